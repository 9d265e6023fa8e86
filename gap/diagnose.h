// The sim-to-real gap diagnosis (issue 5). This first stage answers "is there a gap, and where":
//   1. replay every run's recorded gate through the nominal model; residual = measured - simulated;
//   2. the noise floor from the data itself: white-noise sigma from second differences,
//      sqrt(mean(d2^2) / 6), which the smooth coil current barely contributes to at 50 kHz;
//   3. the gap is significant when the fit runs' residual RMS exceeds kSignificance x the noise floor;
//   4. where: each model phase's share of the residual energy and its RMSE, per split.
// Attribution (fitting each catalogued effect) builds on this; until it runs, a significant gap is "unknown".
#pragma once

#include <array>
#include <string>
#include <vector>

#include "common/status.h"
#include "gap/dataset.h"
#include "gap/replay.h"
#include "model/params.h"

namespace vb::gap {

inline constexpr double kSignificance = 1.5;  // residual RMS / noise floor above which the gap is real

struct PhaseStat {
  Phase phase;
  double share = 0.0;   // fraction of the residual energy
  double rmse_A = 0.0;
  std::size_t samples = 0;
};

struct RunGap {
  std::string id;
  std::string split;    // "fit" or "holdout" (made up when the manifest has none)
  double rmse_A = 0.0;
};

struct Diagnosis {
  std::string model;
  std::string split_note;          // how the split was made when the manifest gave none
  double noise_floor_A = 0.0;
  double fit_rmse_A = 0.0;
  double holdout_rmse_A = 0.0;
  bool significant = false;
  std::vector<PhaseStat> where;    // over all runs, sorted by share
  std::vector<RunGap> runs;
  std::string verdict;             // "none", or "unknown" until attribution runs
  std::vector<std::string> warnings;
};

StatusOr<Diagnosis> Diagnose(const Dataset& dataset, const model::PlantParams& nominal);

// The diagnosis as JSON (the output contract) and as a report for people.
std::string DiagnosisJson(const Diagnosis& d);
std::string DiagnosisReport(const Diagnosis& d);

}  // namespace vb::gap
