// Replay of a measured run through a model: the recorded gate command (a sample's gate holds until the next
// sample, as valve-runs/1 defines it) drives the event-exact simulator from rest, and the model's current,
// position and phase come out on the run's own sample grid. The residual is measured - simulated.
#pragma once

#include <cstdint>
#include <string_view>
#include <vector>

#include "common/status.h"
#include "model/simulator.h"

namespace vb::gap {

// Where the model's valve is, from its state: the diagnosis localises the gap by these phases.
enum class Phase : std::uint8_t {
  kRise,     // energised, spool still at rest on the lower stop
  kOpening,  // spool moving towards x_max
  kOpen,     // energised, held at x_max
  kRelease,  // de-energised, still held at x_max
  kClosing,  // spool moving towards the lower stop
  kClosed,   // de-energised, at rest on the lower stop
};
inline constexpr int kPhaseCount = 6;
std::string_view PhaseName(Phase p);

struct ReplayInput {
  double supply_V = 24.0;
  double supply_pressure_Pa = 0.0;
  double sample_period_s = 2e-5;
  std::vector<std::int8_t> gate;     // one per sample, 0 or 1
  double initial_i_A = 0.0;          // the coil current at t = 0 (a run that does not start from rest)
};

struct Replay {
  std::vector<double> i_A, x_m, v_mps;  // i_A: what the sensor reports (sensor_lag applies)
  std::vector<Phase> phase;
  double final_dT_K = 0.0;    // coil temperature rise at the end (coil_heating)
  double final_im_A = 0.0;    // core magnetisation state at the end (residual_magnetism)
  std::uint64_t ode_steps = 0;  // the solver's accepted and rejected steps: the replay's work (its CPU time)
};

// The status of a simulation the watchdog stopped (model::SolverOptions): Aborted, with when and why.
Status SimulationFailed(const model::Simulator& sim);

// Simulates the input from rest with the given plant and driver.
StatusOr<Replay> ReplayRun(const model::PlantParams& plant, const model::DriverParams& driver,
                           const ReplayInput& input, const model::SolverOptions& solver = {});

// A whole bench session: every run in manifest (time) order, carrying the slow states from run to run: the
// coil's temperature rise cools during the idle time between runs (coil_heating's thermal time constant),
// the core's magnetisation persists (residual_magnetism). Only gate commands and conditions are used, never
// measured currents.
struct SessionRun {
  double supply_V, supply_pressure_Pa, sample_period_s, t_start_s;
  const std::vector<std::int8_t>* gate;
};
StatusOr<std::vector<Replay>> ReplaySession(const model::PlantParams& plant, const model::DriverParams& driver,
                                            const std::vector<SessionRun>& runs,
                                            const model::SolverOptions& solver = {});

}  // namespace vb::gap
