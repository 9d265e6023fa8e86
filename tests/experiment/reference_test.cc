#include <gtest/gtest.h>

#include <cmath>

#include "experiment/reference.h"

namespace vb::experiment {
namespace {

using valvebench::v1::ReferenceSpec;
using valvebench::v1::ValveCommand;

ReferenceProfile Make(const ReferenceSpec& r, const ValveCommand& c = {}) {
  auto p = ReferenceProfile::FromSpec(r, c);
  EXPECT_TRUE(p.ok()) << p.status().message();
  return p.ok() ? *p : ReferenceProfile{};
}

TEST(Reference, StepsRampSine) {
  ReferenceSpec steps;
  auto* s0 = steps.mutable_steps()->add_steps();
  s0->set_start_s(0.0);
  s0->set_value(0.2);
  auto* s1 = steps.mutable_steps()->add_steps();
  s1->set_start_s(0.01);
  s1->set_value(0.5);
  const ReferenceProfile st = Make(steps);
  EXPECT_DOUBLE_EQ(st.At(0.005).value, 0.2);
  EXPECT_DOUBLE_EQ(st.At(0.01).value, 0.5) << "a step holds from its start";
  EXPECT_EQ(st.Breakpoints(1.0), (std::vector<double>{0.0, 0.01}));

  ReferenceSpec ramp;
  ramp.mutable_ramp()->set_start_value(0.0);
  ramp.mutable_ramp()->set_end_value(1.0);
  ramp.mutable_ramp()->set_start_s(0.1);
  ramp.mutable_ramp()->set_end_s(0.2);
  const ReferenceProfile rp = Make(ramp);
  EXPECT_DOUBLE_EQ(rp.At(0.05).value, 0.0);
  EXPECT_NEAR(rp.At(0.15).value, 0.5, 1e-12);
  EXPECT_NEAR(rp.At(0.15).rate, 10.0, 1e-12);
  EXPECT_DOUBLE_EQ(rp.At(0.3).value, 1.0);

  ReferenceSpec sine;
  sine.mutable_sine()->set_offset(1.0);
  sine.mutable_sine()->set_amplitude(0.5);
  sine.mutable_sine()->set_frequency_hz(10.0);
  const ReferenceProfile sn = Make(sine);
  EXPECT_NEAR(sn.At(0.025).value, 1.5, 1e-12);
  EXPECT_NEAR(sn.At(0.0).rate, 0.5 * 2 * M_PI * 10.0, 1e-9);
}

TEST(Reference, OnOffProfileFollowsTheValveCommand) {
  ReferenceSpec r;
  r.mutable_on_off_profile()->set_switching_value(0.9);
  r.mutable_on_off_profile()->set_switching_time_s(0.005);
  r.mutable_on_off_profile()->set_holding_value(0.5);
  ValveCommand c;
  c.set_frequency_hz(20.0);  // 50 ms period
  c.set_duty(0.4);           // on for 20 ms
  const ReferenceProfile p = Make(r, c);
  EXPECT_DOUBLE_EQ(p.At(0.052).value, 0.9);
  EXPECT_TRUE(p.At(0.052).command_on);
  EXPECT_NEAR(p.At(0.052).t_since_on_s, 0.002, 1e-12);
  EXPECT_DOUBLE_EQ(p.At(0.06).value, 0.5);
  EXPECT_FALSE(p.At(0.075).command_on);
  EXPECT_DOUBLE_EQ(p.At(0.075).value, 0.0);
  const auto bp = p.Breakpoints(0.1);
  const std::vector<double> want = {0.0, 0.005, 0.02, 0.05, 0.055, 0.07};
  ASSERT_EQ(bp.size(), want.size());
  for (size_t k = 0; k < want.size(); ++k) EXPECT_NEAR(bp[k], want[k], 1e-12) << k;
}

TEST(Reference, BadShapesNameTheField) {
  ReferenceSpec ramp;
  ramp.mutable_ramp()->set_start_s(0.2);
  ramp.mutable_ramp()->set_end_s(0.1);
  auto p = ReferenceProfile::FromSpec(ramp, {});
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.status().message().find("reference.ramp.end_s"), std::string::npos);
  ValveCommand c;
  c.set_frequency_hz(10);
  c.set_duty(1.5);
  p = ReferenceProfile::FromSpec(ReferenceSpec{}, c);
  ASSERT_FALSE(p.ok());
  EXPECT_NE(p.status().message().find("valve_command.duty"), std::string::npos);
}

}  // namespace
}  // namespace vb::experiment
