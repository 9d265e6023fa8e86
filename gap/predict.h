// What a model predicts for every measured value of a dataset, whatever the run kind (docs/gap.md, "Runs of
// every kind"). The one path from a model to numbers comparable with the measurement: the diagnosis, the
// attribution and identification all go through Predict.
//
//   waveform  replayed from rest (or from its first measured current when it says it does not start at rest)
//             with the recorded gate; slow states (coil heating, core magnetisation) carry from run to run by
//             t_start_s, as on the bench (gap/replay.h);
//   samples   simulated from rest with the recorded gate edges, read at each sample's instant;
//   periodic  the PWM (frequency, on-time) held until the current is periodic: the steady state is found by
//             shooting on the current at the rising edge (a secant step on P(i0) - i0, P one period of the
//             event-exact simulator), then read at each delay after the edge.
// Each run sees the device in its own state (model::AtState: a held stroke, a winding temperature) and the
// dataset's sense chain: a shunt in the switch path adds to the supply resistance; a declared offset is added
// to every reading. The model file itself stays the device's: the bench's chain belongs to the dataset.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "common/status.h"
#include "gap/dataset.h"
#include "gap/replay.h"
#include "model/params.h"
#include "model/simulator.h"

namespace vb::gap {

struct Predicted {
  std::vector<std::vector<double>> i_A;     // per run: one per measured value (empty for runs not asked for)
  std::vector<std::vector<Phase>> phase;    // per run: the model's phase at each value
  std::uint64_t ode_steps = 0;              // the solver's steps over every run simulated: the work (CPU time)
};

struct PredictOptions {
  model::SolverOptions solver;
  int max_periods = 400;                    // periodic runs: periods simulated at most before giving up
  double periodic_tol_A = 1e-9;             // periodic runs: |P(i0) - i0| that counts as steady (plus 1e-7 |i0|)
  const model::DriverParams* driver = nullptr;  // the bench's driver; nullptr: the dataset's
};

// Predicts the runs with need[r] (all when need is empty). Runs not needed are skipped unless a later needed
// run depends on their slow states. Errors name the run.
StatusOr<Predicted> Predict(const Dataset& ds, const model::PlantParams& plant, const PredictOptions& options,
                            const std::vector<bool>& need = {});

// The plant one run sees: the device in the run's state (held stroke, temperature) with the dataset's sense
// chain (shunt in the switch path). The declared offset is not in it: Predict adds it to the readings.
StatusOr<model::PlantParams> PlantForRun(const Dataset& ds, const RunData& run, const model::PlantParams& plant);

// True when the dataset has waveform runs (sampled chains such as sensor_lag act on them only).
bool HasWaveforms(const Dataset& ds);
// True when any run could show the spool moving: a waveform or samples run without a held stroke on a plant
// with a moving part.
bool CanShowMotion(const Dataset& ds, const model::PlantParams& plant);

}  // namespace vb::gap
