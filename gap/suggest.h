// The next experiment (docs/gap.md, "The next experiment"): when the diagnosis cannot tell its leading
// candidates apart, which runs would. Every design of a grid of runnable open-loop runs (supply and pressure
// within what the session already used, a step or PWM at a carrier frequency and duty, a hold time, a release
// tail) is simulated with each contender's fitted model; a design's worth is the smallest RMS difference
// between any two contenders' predicted currents, in units of the session's noise floor. The best few designs
// that differ from each other are suggested, as an experiment spec `benchctl run` executes.
#pragma once

#include <string>
#include <vector>

#include "common/status.h"
#include "gap/dataset.h"
#include "gap/diagnose.h"
#include "model/params.h"

namespace vb::gap {

// One suggested run: from rest (rest_s with the gate off first, so that slow states such as the coil's
// temperature start where the models start them), then the gate as a step (pwm_Hz 0) or PWM for hold_s, then
// off for tail_s.
struct Design {
  double supply_V = 24.0;
  double supply_pressure_Pa = 0.0;
  double pwm_Hz = 0.0;  // 0: a step (gate on for hold_s)
  double duty = 1.0;
  double hold_s = 0.05;
  double tail_s = 0.03;
  double rest_s = 0.0;
};

struct SuggestedRun {
  Design design;
  // The smallest predicted RMS difference between two contenders over the run, over the noise floor, and the
  // pair it belongs to (the hardest to separate on this run).
  double separation_sigma = 0.0;
  std::string closest_pair;
};

struct Suggestion {
  std::vector<std::string> contenders;  // the candidates to separate (ranking names)
  std::vector<SuggestedRun> runs;       // best first
  double current_separation_sigma = 0.0;  // the same figure on the session's own runs (RMS over all of them)
  double sample_rate_Hz = 0.0;
  std::string note;                     // why there is no suggestion, or what to do with it
};

struct SuggestOptions {
  int max_runs = 3;
  int max_contenders = 3;
};

// The contenders are the verdict and what it is confusable with; with an unknown verdict, the best rows that
// may be the verdict. No suggestion (a note saying why) when there is only one, or the data are not waveforms.
StatusOr<Suggestion> SuggestNextRuns(const Dataset& ds, const model::PlantParams& nominal, const Diagnosis& d,
                                     const SuggestOptions& options = {});

// The gate of a design sampled at sample_period_s (what the bench will record as `gate`).
std::vector<std::int8_t> DesignGate(const Design& design, double sample_period_s);

// The suggestion as an experiment spec (protobuf JSON, proto/valvebench/v1/spec.proto): one variant per run,
// open-loop PWM segments, the dataset's sample rate; model_preset is the bench model's preset.
std::string SuggestionSpecJson(const Suggestion& s, const std::string& name, const std::string& model_preset);

// The suggestion as JSON: contenders, current_separation_sigma, runs (design and separation_sigma), note.
std::string SuggestionJson(const Suggestion& s);

// For people: the contenders, each run's design and its predicted separation.
std::string SuggestionReport(const Suggestion& s);

}  // namespace vb::gap
