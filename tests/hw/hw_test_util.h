// Shared helpers of the hardware-bench tests: specs, runs, and the checks every fault test repeats.
#pragma once

#include <gtest/gtest.h>

#include <string>

#include "experiment/runner.h"
#include "experiment/spec.h"
#include "hw/emulated_bench.h"

namespace vb::hw::testing {

// Open-loop PWM on taghizadeh2009 at 24 V; the carrier (375 Hz) and duty (0.5) are ones every bench here
// realises exactly (the U3 included: 12 MHz / 125 / 256 in 8-bit PWM mode).
inline std::string OpenLoopJson(double duration_s, double rate_Hz, double carrier_Hz = 375.0, double duty = 0.5) {
  return R"({"name":"hw","bench":{"model":{"preset":"taghizadeh2009"}},"conditions":{"supply_V":24},)"
         R"("controller":{"open_loop_pwm":{"segments":[{"start_s":0,"frequency_Hz":)" +
         std::to_string(carrier_Hz) + R"(,"duty":)" + std::to_string(duty) + R"(}]}},"duration_s":)" +
         std::to_string(duration_s) + R"(,"recording":{"rate_Hz":)" + std::to_string(rate_Hz) + "}}";
}

inline experiment::Experiment BuildOrDie(const std::string& json) {
  auto spec = experiment::ParseSpecJson(json);
  EXPECT_TRUE(spec.ok()) << spec.status().message();
  auto e = experiment::BuildExperiment(*spec);
  EXPECT_TRUE(e.ok()) << e.status().message();
  return std::move(e.value());
}

struct Ran {
  experiment::RunSummary summary;
  experiment::Trace trace;
};

inline Ran RunOn(const experiment::Experiment& e, Bench& bench) {
  Ran r;
  r.summary = experiment::Runner::Run(e, bench, &r.trace);
  return r;
}

// The valve model every device emulator here has behind it: the one the spec asks for.
inline EmulatedBenchOptions ValveFor(const experiment::Experiment& e) { return experiment::EmulatedBenchFor(e); }

}  // namespace vb::hw::testing
