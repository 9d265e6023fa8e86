// Parameter identification (seed 000 section 4) on its own: a bounded fit of chosen nominal parameters to
// measured current traces (fit runs only), with 1-sigma uncertainties and the fit quality on the holdout runs.
// The same machinery as the attribution's parametric candidates (gap/attribution.h), with several parameters
// free at once.
#pragma once

#include <string>
#include <vector>

#include "common/status.h"
#include "gap/attribution.h"
#include "gap/dataset.h"
#include "model/params.h"

namespace vb::gap {

struct Identification {
  std::string model;
  double noise_floor_A = 0.0;
  std::string split_note;
  std::vector<FreeParam> free;     // the bounds searched (nominal x [0.5, 1.5] unless given)
  std::map<std::string, double> nominal;
  CandidateResult fit;             // fitted values, uncertainty, fit and holdout RMSE before/after
};

// names: nominal parameter symbols ("R", "mu_r", ...). Unknown or repeated names are InvalidArgument
// naming them.
StatusOr<Identification> Identify(const Dataset& ds, const model::PlantParams& nominal,
                                  const std::vector<std::string>& names, const AttributionOptions& options = {});

std::string IdentificationJson(const Identification& id);
std::string IdentificationReport(const Identification& id);

}  // namespace vb::gap
