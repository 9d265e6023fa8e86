// Detection limits (docs/gap.md, "Detection limits"): for each catalogued effect, the smallest magnitude this
// dataset could have shown. A verdict of "none" then means "nothing above these limits", and a weak effect
// that was missed can be told from one the runs could never see.
//
// For an effect at magnitude s in [0, 1] (its parameters moved together, in the fit's normalised coordinates,
// from where the effect vanishes towards the far end of their range), the change it makes to every predicted
// value, d(s), is compared with the floor after removing what a change of R alone would absorb (the diagnosis
// fits R with every effect that has R free): r(s) = RMS(d - proj_dR d). The limit is the smallest s with
// r(s) >= sqrt(kSignificance^2 - 1) x floor, the residual that would make the gap significant on its own,
// found by bisection (r grows with s for every catalogued effect).
#pragma once

#include <map>
#include <string>
#include <vector>

#include "common/status.h"
#include "gap/attribution.h"
#include "gap/dataset.h"
#include "model/params.h"

namespace vb::gap {

struct DetectionLimit {
  std::string effect;
  std::map<std::string, double> params;  // the effect's parameters at the limit
  std::map<std::string, std::string> units;
  bool detectable = false;               // false: not even at the end of its range
  bool below_range = false;              // shown even at the weakest end of its range (the box does not reach
                                         // "none": Frohlich's knee at 20 T, heating at R_th 0.05 K/W)
  double residual_at_limit_A = 0.0;      // r at the limit (or at the range's end when not detectable)
};

// candidates: structural candidates (those with a parameter whose `absent` is set); others are skipped.
StatusOr<std::vector<DetectionLimit>> DetectionLimits(const Dataset& ds, const model::PlantParams& nominal,
                                                      const std::vector<Candidate>& candidates, double floor_A,
                                                      const AttributionOptions& options);

}  // namespace vb::gap
