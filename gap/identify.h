// Parameter identification (seed 000 section 4) on its own: a bounded fit of chosen parameters to measured
// runs of any kind (fit runs only), with 1-sigma uncertainties, an identifiability report and the fit quality
// on the holdout runs. The same machinery as the attribution's candidates (gap/attribution.h), with several
// parameters free at once, user bounds, start values and fixed values, and a global search before the local
// fit so that a device far from the starting model is found in one call (docs/real-data.md).
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "common/status.h"
#include "gap/attribution.h"
#include "gap/dataset.h"
#include "model/params.h"

namespace vb::gap {

// One parameter to fit: a nominal parameter ("R", "L", "mu_r"), an effect's ("sensor_offset.offset_A",
// "eddy_currents.R_p"; the effect is switched on) or the bench driver's ("driver.diode_drop_V").
// NaN bounds or start: defaults (nominal x [0.5, 1.5] for nominal parameters, the effect's own range).
struct ParamSpec {
  std::string name;
  double lower = kNaN, upper = kNaN, initial = kNaN;
};

// Parses "NAME", "NAME=LO:HI", "NAME@START" or "NAME=LO:HI@START" (the --params syntax); errors name `flag`.
StatusOr<ParamSpec> ParseParamSpec(const std::string& text, const std::string& flag);
// Parses "NAME=VALUE" (--fix).
StatusOr<std::pair<std::string, double>> ParseFixed(const std::string& text, const std::string& flag);

struct IdentifyOptions {
  std::vector<ParamSpec> params;
  std::vector<std::pair<std::string, double>> fixed;  // set before the fit and kept
  // Global search before the local fit: kAuto runs it when some box spans more than 3.5x (or crosses 0) (a device from
  // scratch); the default boxes (nominal x [0.5, 1.5]) are for a local re-fit.
  enum class Global { kAuto, kOn, kOff };
  Global global = Global::kAuto;
  // A watchdog, not a budget: the work is bounded by evaluation counts (attribution.max_evaluations, raised to 200
  // per parameter, and global_evaluations_per_param), so results do not depend on the machine's load; this wall
  // time only stops a fit that would otherwise run away (it binds on a machine 100x slower than these need).
  double budget_s = 600.0;
  int global_evaluations_per_param = 150;
  AttributionOptions attribution;
  // Progress lines of a from-scratch identification (gap/moving_valve.h), when no parameter is named.
  std::function<void(const std::string&)> scratch_progress;
  // The evaluation budget of a from-scratch identification (MovingIdentifyOptions::max_evaluations).
  int scratch_max_evaluations = 20000;
  // Its work budget in solver steps (MovingIdentifyOptions::max_ode_steps; -1: that option's default, 0: none).
  std::int64_t scratch_max_ode_steps = -1;
};

// What the data says about each fitted parameter.
struct ParamVerdict {
  std::string name;
  bool at_bound = false;          // ended within 0.5 % of the box at a bound: widen it or fix the parameter
  bool determined = true;         // false: the data does not pin it (singular or a 1-sigma wider than half the box)
  std::vector<std::pair<std::string, double>> correlated;  // |correlation| > 0.95 with these
};

struct Identification {
  std::string model;
  double noise_floor_A = 0.0;
  std::string split_note;
  std::vector<FreeParam> free;     // the bounds searched
  std::vector<std::pair<std::string, double>> fixed;
  std::map<std::string, double> nominal;  // the start values
  CandidateResult fit;             // fitted values, uncertainty, fit and holdout RMSE before/after
  Candidate candidate;             // the effects switched on and the parameters, to rebuild the fitted model
  std::vector<ParamVerdict> identifiability;
  bool global = false;
};

StatusOr<Identification> Identify(const Dataset& ds, const model::PlantParams& nominal, const IdentifyOptions& options);

// names: parameters with default bounds and starts; unknown or repeated names are InvalidArgument.
StatusOr<Identification> Identify(const Dataset& ds, const model::PlantParams& nominal,
                                  const std::vector<std::string>& names, const AttributionOptions& options = {});

// The plant and driver with the identified values (for --out and for a diagnosis against a reference).
StatusOr<model::PlantParams> IdentifiedPlant(const model::PlantParams& nominal, const Identification& id);
StatusOr<model::DriverParams> IdentifiedDriver(const model::DriverParams& driver, const Identification& id);

std::string IdentificationJson(const Identification& id);
std::string IdentificationReport(const Identification& id);

}  // namespace vb::gap
