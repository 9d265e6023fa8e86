// The nightly health check of a bench (config "health"; issue 38, docs/track.md "On the server"): before each
// night's suite, one switch-on run per supply and pressure on the bench, from rest (the gate low for 0.1 ms, then
// high to the end), and one hold (the same switch-on, then PWM, then the gate low for the drop-out; gap/hold.h),
// stored as any run. `benchctl health BENCH` tracks a bench's checks night by night (the same
// gap::TrackSessions as `benchctl track`). Each run is tagged "health", "health:<bench>", "night",
// "night:<date>" and the night's number (runs::NightNumberTag), pinned to its bench, and queued ahead of the
// suite (priority kHealthPriority).
#pragma once

#include <string>
#include <vector>

#include "common/status.h"
#include "experiment/spec.h"
#include "runs/bench_setup.h"

namespace vb::server {

constexpr int kHealthPriority = 100;
constexpr double kHealthPreTrigger_s = 1e-4;   // the gate rises here (a recorded rest before it: the offset)
constexpr double kHealthDefaultDuration_s = 0.0101;
constexpr double kHealthDefaultRate_Hz = 1e5;
// The hold (docs/track.md "The hold"): half the supply's current, where the ripple (V d (1 - d) / (f L)) is
// largest; 1 kHz, so that a coil of 1 H at 12 V still ripples by 3 mA, above a scope's noise, with 100 samples
// a period at 100 kHz; 0.1 s, so that a coil of 50 ms time constant has settled within a time constant by the
// window's start (the second half; what remains is taken out through L).
constexpr double kHealthDefaultHoldDuty = 0.5;
constexpr double kHealthDefaultHoldFrequency_Hz = 1e3;
constexpr double kHealthDefaultHold_s = 0.1;
// The hold's gate stays low this long first: the baseline a scope's offset is taken from (gap/hold.h; 500
// samples at 100 kHz).
constexpr double kHealthHoldBaseline_s = 5e-3;
// After the hold the gate stays low this long: the drop-out (gap/hold.h MeasureDropOut). The current decays
// through the flyback diode with the held coil's L/R and the plunger lets go on the way down; 50 ms is a
// coil of 50 ms time constant falling to a third of its hold current (and 50 periods at 1 kHz).
constexpr double kHealthDefaultDropOut_s = 0.05;

// Checks the bench's "health" block (when it has one) against its capabilities; the message names the field.
Status ValidateHealthCheck(const valvebench::v1::BenchConfig& bench, const hw::Capabilities& caps,
                           const std::string& field);

// Checks the bench's "drift" entries (emulated benches only) and fills setup->drift.
Status DriftFromConfig(const valvebench::v1::BenchConfig& bench, const std::string& field, runs::BenchSetup* setup);

// The night's health runs for one bench (empty when it has no "health" block).
std::vector<experiment::ExperimentSpec> HealthCheckSpecs(const runs::BenchSetup& bench, const std::string& date,
                                                          int night_number);

}  // namespace vb::server
