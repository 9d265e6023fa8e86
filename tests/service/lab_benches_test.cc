// A lab's benches in both directions (service/lab_benches.h): a host's registration of its benches (a typed
// capabilities message in protobuf JSON) read back by another host's admission, including what older builds wrote.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "service/lab_benches.h"

namespace vb::server {
namespace {

runs::BenchSetup HidBench() {
  runs::BenchSetup b;
  b.name = "hid-1";
  b.kind = BenchKind::kHid;
  b.bench_class = "hid";
  b.device = "hid 2e8a:10c0 serial A1";
  b.caps.kind = "hid";
  b.caps.driver = "low_side_flyback";
  b.caps.max_supply_V = 24.0;
  b.caps.min_carrier_Hz = 100.0;
  b.caps.max_carrier_Hz = 20'000.0;
  b.caps.max_sample_rate_Hz = 50'000.0;
  b.caps.max_control_rate_Hz = 10'000.0;
  b.caps.measures_position = true;
  b.caps.max_current_A = 2.5;
  b.caps.device_loops = {"open_loop", "pi"};
  b.caps.max_device_loop_Hz = 40'000.0;
  b.config.mutable_health()->add_supply_v(12.0);
  b.config.mutable_health()->add_supply_pressure_pa(0.0);
  return b;
}

db::HostRecord Host(const std::string& name, const std::string& benches_json) {
  db::HostRecord h;
  h.name = name;
  h.benches_json = benches_json;
  return h;
}

TEST(LabBenches, CapabilitiesTravelAsATypedMessage) {
  const std::string json = BenchesJson({HidBench()});
  const auto parsed = nlohmann::json::parse(json);
  ASSERT_TRUE(parsed.is_array());
  ASSERT_EQ(parsed.size(), 1u);
  // The kind is the enum's, not free text; the description's fields are beside the registration's.
  EXPECT_EQ(parsed[0]["caps"]["kind"], "BENCH_KIND_HID") << json;
  EXPECT_EQ(parsed[0]["kind"], "hid") << json;
  EXPECT_EQ(parsed[0]["bench_class"], "hid") << json;
  EXPECT_EQ(parsed[0]["caps"]["max_supply_V"], 24.0) << json;

  const auto others = OtherHostsBenches({Host("a", json), Host("b", json)}, "a");
  ASSERT_EQ(others.size(), 1u) << "the own host's benches are not another host's";
  const runs::BenchSetup& s = others[0];
  const runs::BenchSetup want = HidBench();
  EXPECT_EQ(s.name, want.name);
  EXPECT_EQ(s.kind, BenchKind::kHid);
  EXPECT_EQ(s.bench_class, "hid");
  EXPECT_EQ(s.device, want.device);
  EXPECT_EQ(s.caps.kind, "hid");
  EXPECT_EQ(s.caps.driver, want.caps.driver);
  EXPECT_EQ(s.caps.max_supply_V, want.caps.max_supply_V);
  EXPECT_EQ(s.caps.min_carrier_Hz, want.caps.min_carrier_Hz);
  EXPECT_EQ(s.caps.max_carrier_Hz, want.caps.max_carrier_Hz);
  EXPECT_EQ(s.caps.max_sample_rate_Hz, want.caps.max_sample_rate_Hz);
  EXPECT_EQ(s.caps.max_control_rate_Hz, want.caps.max_control_rate_Hz);
  EXPECT_EQ(s.caps.measures_position, true);
  EXPECT_EQ(s.caps.max_current_A, want.caps.max_current_A);
  EXPECT_EQ(s.caps.device_loops, want.caps.device_loops);
  EXPECT_EQ(s.caps.max_device_loop_Hz, want.caps.max_device_loop_Hz);
  ASSERT_TRUE(s.config.has_health());
  EXPECT_EQ(s.config.health().supply_v_size(), 1);

  // ListBenches reads the same entry as a description.
  auto info = RegisteredBench(parsed[0].dump());
  ASSERT_TRUE(info.ok()) << info.status().message();
  EXPECT_EQ(info->name(), "hid-1");
  EXPECT_EQ(info->kind(), "hid");
}

// A heartbeat written before the capabilities were a message: "caps" with the kind as text. Still admitted
// against, its kind from the text.
TEST(LabBenches, AnOlderBuildsHeartbeatIsStillRead) {
  const std::string older = R"([{"name": "u3-1", "kind": "u3", "bench_class": "u3", "device": "u3 serial 7",
      "caps": {"kind": "u3", "driver": "low_side_flyback", "max_supply_V": 30, "max_carrier_Hz": 5000,
               "device_loops": ["open_loop"], "max_device_loop_Hz": 1000}}])";
  const auto others = OtherHostsBenches({Host("old", older)}, "new");
  ASSERT_EQ(others.size(), 1u);
  EXPECT_EQ(others[0].kind, BenchKind::kU3);
  EXPECT_EQ(others[0].caps.kind, "u3");
  EXPECT_EQ(others[0].caps.max_supply_V, 30.0);
  EXPECT_EQ(others[0].caps.device_loops, std::vector<std::string>{"open_loop"});
}

TEST(LabBenches, EntriesThatAreNoRegistrationAreSkipped) {
  const std::string json = R"([{"name": "no-caps", "kind": "hid", "bench_class": "hid"},
      {"name": "ghost", "kind": "ghost", "bench_class": "ghost", "caps": {"driver": "x"}},
      {"name": "", "kind": "hid", "bench_class": "hid", "caps": {"kind": "BENCH_KIND_HID"}},
      "not an object",
      {"name": "ok", "kind": "hid", "bench_class": "hid", "caps": {"kind": "BENCH_KIND_HID"}}])";
  const auto others = OtherHostsBenches({Host("x", json), Host("y", "not json")}, "self");
  ASSERT_EQ(others.size(), 1u);
  EXPECT_EQ(others[0].name, "ok");
}

TEST(LabBenches, CapabilitiesRoundTripThroughTheMessage) {
  const hw::Capabilities want = HidBench().caps;
  const auto proto = CapabilitiesToProto(want);
  EXPECT_EQ(proto.kind(), valvebench::v1::BENCH_KIND_HID);
  const hw::Capabilities back = CapabilitiesFromProto(proto);
  EXPECT_EQ(back.kind, want.kind);
  EXPECT_EQ(back.driver, want.driver);
  EXPECT_EQ(back.device_loops, want.device_loops);
  EXPECT_EQ(back.max_current_A, want.max_current_A);
  hw::Capabilities unknown = want;
  unknown.kind = "mystery";
  EXPECT_EQ(CapabilitiesToProto(unknown).kind(), valvebench::v1::BENCH_KIND_UNSPECIFIED);
}

}  // namespace
}  // namespace vb::server
