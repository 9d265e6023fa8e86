// Attribution: which unmodelled effect explains the gap (issue 5, "Which" and "How far").
//
// Every candidate is fitted on the fit runs only, by a bounded derivative-free optimiser (NLopt BOBYQA) in
// normalised coordinates (log-scaled where a parameter spans decades), replaying the whole session so slow
// states carry over (holdout runs' gate commands drive those states; their measured currents never enter
// the objective). Candidates: each nominal parameter alone (param:NAME: the parametric part of the gap), and
// each catalogued effect with the coil resistance free too, so no effect wins merely by absorbing an R
// offset. A candidate's worth is its error on the holdout runs, with a small complexity penalty.
#pragma once

#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <functional>
#include <map>
#include <string>
#include <string_view>
#include <vector>

#include "common/status.h"
#include "gap/dataset.h"
#include "gap/replay.h"
#include "model/params.h"
#include "model/simulator.h"

namespace vb::gap {

struct FreeParam {
  std::string name;     // a nominal parameter ("R"), an effect's ("eddy_currents.R_p") or the driver's
                        // ("driver.diode_drop_V")
  double lower = 0.0, upper = 0.0, initial = 0.0;
  bool log_scale = false;
  // The value at which the effect vanishes (an effect's own parameter); NaN for nominal parameters. A
  // candidate whose effect parameters all end there has found no effect in the data and cannot win.
  double absent = std::numeric_limits<double>::quiet_NaN();
  // > 1: a discrete choice among `levels` values evenly spaced over [lower, upper] (a form, e.g. the saturation's
  // knee: magnetic_saturation.tanh 0, 1, 2), fitted by fitting the others at each level and keeping the level
  // whose fit runs end lowest; it counts as one parameter and has no uncertainty. At most one per candidate.
  int levels = 0;
};

// A parameter's value at normalised coordinate u in [0, 1] of its box (log-scaled where log_scale), and back.
double ValueAt(const FreeParam& f, double u);
double Normalised(const FreeParam& f, double v);

// What a candidate (and so a verdict) names: one catalogued effect ("eddy_currents"; the moving valve's
// "supply_pressure" and "stuck" too), one nominal parameter re-fitted alone ("param:R"), or several causes
// together ("a+b"). Declared by whoever builds the candidate: the code reads the kind, never the name's text.
enum class CauseKind { kEffect, kParameter, kCombination };
const char* CauseKindName(CauseKind kind);  // "effect", "parameter", "combination"
StatusOr<CauseKind> ParseCauseKind(std::string_view name);

// Why a candidate may not be the verdict (CandidateResult::disqualified says it in words for people).
enum class Disqualification {
  kNone,
  kEffectVanished,    // its effect's parameters ended where the effect vanishes
  kSaturatedFit,      // as many free parameters as fit values: it can match anything
  kRAloneDoesAsWell,  // R alone (param:R) does as well on the holdout runs
  kMemberVanished,    // a combination with a member fitted where it vanishes
  kNotDecisive,       // a combination that does not remove enough of what a smaller model leaves
};
// "", "effect_vanished", "saturated_fit", "r_alone_does_as_well", "member_vanished", "not_decisive".
const char* DisqualificationName(Disqualification why);
StatusOr<Disqualification> ParseDisqualification(std::string_view name);

struct Candidate {
  std::string name;                  // the output name: "eddy_currents", "param:R", "a+b" (for people)
  std::vector<std::string> effects;  // effects switched on
  std::vector<FreeParam> params;
  std::vector<std::pair<std::string, double>> fixed = {};  // set before the free ones (e.g. a reference temperature)
  // Nominal parameters that are causes in their own right in a combination ("eddy_currents+param:k" has {"k"});
  // a single param:NAME candidate needs none (its name says it). R freed beside an effect is not one.
  std::vector<std::string> param_members = {};
  CauseKind kind = CauseKind::kEffect;
};

// The candidate that re-fits one nominal parameter alone: "param:NAME", kind kParameter.
Candidate ParamCandidate(const std::string& param, FreeParam free);

// The causes a candidate names, in order: its effects, then "param:NAME" for each parametric member (a single
// param:NAME candidate is its own member).
std::vector<std::string> Members(const Candidate& c);

struct CandidateResult {
  std::string name;
  CauseKind kind = CauseKind::kEffect;  // the candidate's
  std::map<std::string, double> params;       // fitted values
  std::map<std::string, double> uncertainty;  // 1-sigma (Gauss-Newton at the optimum; optimistic with
                                              // correlated residuals)
  double fit_rmse_A = 0.0;
  double holdout_rmse_before_A = 0.0;
  double holdout_rmse_after_A = 0.0;
  double closed = 0.0;        // (before - after) / (before - noise floor), in [0, 1]
  // The holdout residual as evidence (docs/gap.md, "Several causes"): how many samples it has, and its integrated
  // autocorrelation time in samples (1 for white noise; the length of the structure a model leaves, when it
  // leaves some). holdout_samples / holdout_autocorrelation_time is its number of independent samples.
  std::size_t holdout_samples = 0;
  double holdout_autocorrelation_time = 1.0;
  double score = 0.0;         // holdout RMSE x (1 + complexity_penalty x parameters): lower is better
  // Holdout RMSE after the fit in each phase of the nominal model (phases where the holdout runs have samples).
  std::array<double, kPhaseCount> phase_holdout_after_A{};
  // How the fitted effect changes the model, phase by phase: the share of the energy of (fitted - nominal)
  // in each nominal phase, over every run (the effect's model-derived signature).
  std::array<double, kPhaseCount> signature{};
  double signature_match = 0.0;  // Bhattacharyya coefficient of that signature and the residual's, in [0, 1]
  // Correlations of the fitted parameters (from the same covariance), in the candidate's parameter order;
  // empty when the covariance could not be formed (then no parameter is determined by the data).
  std::vector<std::vector<double>> correlation;
  int evaluations = 0;
  Status status;              // a candidate whose replay failed is ranked last with its reason
  // Why the candidate may not be the verdict, "" if it may: its effect ended at its absent value, it has as
  // many free parameters as the fit has values, or (gap/diagnose.h) R alone does as well.
  std::string disqualified;
  Disqualification disqualification = Disqualification::kNone;  // the same, as a value to test
};

// Sets both the reason and its words.
void Disqualify(CandidateResult* row, Disqualification why, std::string words);

struct AttributionOptions {
  int max_evaluations = 150;          // per candidate
  double xtol_rel = 1e-3;             // on the normalised parameters
  int threads = 2;                    // candidates fitted concurrently
  double complexity_penalty = 0.01;   // per free parameter, relative to the holdout RMSE
  // A global search over the whole box before the local fit (NLopt's controlled random search with local
  // mutation, seeded): for identification far from the starting values. 0: local fit only.
  int global_evaluations = 0;
  unsigned seed = 1;
  // Bounded fits: a candidate whose fit has not finished after candidate_budget_s of wall time, or when the
  // deadline (the whole diagnosis's) passes, is reported as failed with the reason; the others go on.
  double candidate_budget_s = 30.0;
  std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max();
  model::SolverOptions solver = FastSolver();
  // Called after each candidate's fit (from the fitting threads, one call at a time): its name, how many are done
  // and how many there are in this round.
  std::function<void(const std::string& name, int done, int total)> progress;
  static model::SolverOptions FastSolver() {
    model::SolverOptions s;
    s.rel_tol = 1e-7;                 // plenty at a 2 mA noise floor, and 2-3x fewer steps
    s.abs_tol = 1e-9;
    return s;
  }
};

// The catalog as candidates, around a nominal plant.
std::vector<Candidate> DefaultCandidates(const model::PlantParams& nominal);
// The candidates this dataset can tell apart: no mechanical candidate where nothing moves (a plain coil, a
// held plunger), the law's own parameters, sensor_lag only on waveforms (it acts on a sampled chain), the
// sense chain's offset and gain, and resistance_temperature where the runs' temperatures differ from the
// model's reference temperature or from each other.
// reference_C: the temperature of a reference session the nominal was fitted on (NaN: none).
std::vector<Candidate> DefaultCandidates(const model::PlantParams& nominal, const Dataset& ds,
                                         const std::vector<bool>& fit_mask, double reference_C = NAN);

// Applies the driver parameters of a candidate ("driver.NAME") to a copy of the dataset's driver.
StatusOr<model::DriverParams> ApplyCandidateDriver(const model::DriverParams& driver, const Candidate& c,
                                                   const std::vector<double>& values);

// Applies a candidate's effects and parameter values to a copy of the nominal plant.
StatusOr<model::PlantParams> ApplyCandidate(const model::PlantParams& nominal, const Candidate& c,
                                            const std::vector<double>& values);

// The nominal model's replay of every run, which the fitted candidates are compared with.
struct NominalReference {
  std::vector<std::vector<double>> i_A;     // per run
  std::vector<std::vector<Phase>> phase;    // per run
  std::array<double, kPhaseCount> residual_share{};  // share of (measured - nominal)^2 by phase, all runs
};
StatusOr<NominalReference> ReplayNominal(const Dataset& ds, const model::PlantParams& nominal,
                                         const model::SolverOptions& solver);

// Fits every candidate; results sorted by score, best first. fit_mask[r]: run r may be used to fit; the
// measured currents of the other runs never reach the objective.
StatusOr<std::vector<CandidateResult>> Attribute(const Dataset& ds, const std::vector<bool>& fit_mask,
                                                 const model::PlantParams& nominal,
                                                 const std::vector<Candidate>& candidates, double noise_floor_A,
                                                 const AttributionOptions& options = {});

// The integrated autocorrelation time of a residual (in samples; 1 for white noise), pooled over several series
// (the holdout runs): tau = 1 + 2 sum_k rho_k, the sum cut by Geyer's initial positive sequence. n / tau is the
// number of independent samples a correlated residual is worth as evidence.
double IntegratedAutocorrelationTime(const std::vector<std::vector<double>>& series);

// Two candidates as one (each one's parameters free, shared ones once; a parametric single becomes a
// parametric member), for when no single cause closes the gap.
Candidate PairCandidate(const Candidate& a, const Candidate& b);

// Ranking order: candidates that may be the verdict first, then by score.
void SortRanking(std::vector<CandidateResult>* rows);

// The dataset's driver with a candidate's fitted driver parameters.
StatusOr<model::DriverParams> FittedDriver(const model::DriverParams& driver, const Candidate& c,
                                           const CandidateResult& r);

// The session replayed with a candidate's fitted values (for overlays and the improved model).
StatusOr<model::PlantParams> FittedPlant(const model::PlantParams& nominal, const Candidate& c,
                                         const CandidateResult& r);

}  // namespace vb::gap
