// A bench as configured, and the bench a run executes on, opened from that configuration: an EmulatedBench
// (the configured plant, or the spec's own plant for the local emulator), or a hardware bench (HidBench over
// hidapi, U3Bench over libusb) opened for the run, so an unplugged and replugged device is found again by
// the next run. Execute() wraps it in the safety interlocks.
#pragma once

#include <atomic>
#include <memory>
#include <string>
#include <vector>

#include "common/bench_kind.h"
#include "experiment/spec.h"
#include "hw/bench.h"
#include "hw/emulated_bench.h"
#include "hw/safety.h"
#include "valvebench/v1/config.pb.h"

namespace vb::runs {

// An emulated valve changing night by night (config "drift"; issue 38): the parameter (model/params.h name) is
// multiplied by DriftFactor on night n, the lab's n-th night.
struct ValveDrift {
  std::string parameter;
  double step = 0.0;       // relative step at from_night
  double per_night = 0.0;  // relative change per night after from_night
  int from_night = 1;
  double base = 0.0;       // the value the factor multiplies (0: the model's own)
};

// 1 + step + per_night (night - from_night) on nights >= from_night; 1 before (and on night 0: no night yet).
double DriftFactor(const ValveDrift& d, int night);
// The plant of night `night`: each drift's parameter (a plant parameter, or an effect's "effect.param") set to
// its base (the model's own unless given) times DriftFactor, from its from_night on; unchanged before.
Status ApplyDrift(const std::vector<ValveDrift>& drift, int night, model::PlantParams* plant);

// The night a run belongs to: its tag "night-number:N" (the nights scheduler tags every run of a night), else 0.
int NightNumberOf(const valvebench::v1::ExperimentSpec& spec);

// The tag the nights scheduler gives every run of the lab's n-th night.
std::string NightNumberTag(int night);

struct BenchSetup {
  std::string name;
  BenchKind kind = BenchKind::kEmulated;
  std::string bench_class;      // what runs are matched on: "emulated:<preset>", "hid", "u3"
  std::string preset;
  valvebench::v1::ModelSpec model;
  hw::EmulatedBenchOptions emulated;
  valvebench::v1::BenchConfig config;  // as configured (hardware: which device)
  hw::Capabilities caps;        // what submissions are checked against
  hw::SafetyLimits safety;      // the interlocks every run on this bench goes through
  bool interlocks = true;       // false: runs execute on the bare bench (the local emulator; docs/decisions.md)
  std::string device;           // hardware: "hid 2e8a:10c0 serial X", "u3 serial N"
  // The local emulator (benchctl run --local): the plant and driver are the spec's own, so every spec fits
  // it; admission matches it to any spec without class, name or capability checks.
  bool plant_from_spec = false;
  // An emulated bench paced to the wall clock (config "pace": "realtime"): every run on it is realtime, as on
  // hardware (docs/lab.md).
  bool paced = false;
  // Emulated: the valve's drift night by night, and white noise on the recorded current (config "drift",
  // "current_noise_A"). A run of a night applies that night's drift; a run outside the nights applies the last
  // night this process's workers ran on the bench (night_seen, shared by the setup's copies; 0 until the first).
  std::vector<ValveDrift> drift;
  double current_noise_A = 0.0;
  std::shared_ptr<std::atomic<int>> night_seen = std::make_shared<std::atomic<int>>(0);
};

// The local emulator bench of `benchctl run --local`: class "local", the spec's own plant, no interlocks.
BenchSetup LocalEmulatorSetup();

// Unavailable naming the device when it cannot be opened (not attached, no permission, no USB bus).
StatusOr<std::unique_ptr<hw::Bench>> OpenBench(const BenchSetup& setup, const experiment::Experiment& e);

}  // namespace vb::runs
