// The improved model a diagnosis leads to (docs/gap.md): the model the diagnosis started from (with a reference
// session: as identified there) plus the verdict's fitted values, as a ModelSpec that --model and an emulated
// bench load. One builder for `benchctl diagnose --model-out` and the server's DiagnoseRuns
// (improved_model_json).
#pragma once

#include <map>
#include <string>
#include <vector>

#include "common/status.h"
#include "gap/diagnose.h"
#include "model/driver.h"
#include "valvebench/v1/spec.pb.h"

namespace vb::gap {

// Writes identified values into a model spec: nominal ones ("R") as params, effect ones
// ("eddy_currents.R_p") into their effect (added when missing, as are `effects`), driver ones ("driver.X")
// into identified_driver (then based on driver_base).
valvebench::v1::ModelSpec WithValues(valvebench::v1::ModelSpec spec, const std::vector<std::string>& effects,
                                     const std::map<std::string, double>& values,
                                     const model::DriverParams& driver_base, const std::string& description);

// The improved model of a diagnosis. nominal: the spec the diagnosis started from (a preset's name or a loaded
// model file); driver: the dataset's driver; fitted_by names the tool and data in the description ("benchctl
// diagnose on DIR"). FailedPrecondition when the verdict is unknown (no candidate explains the gap); a verdict
// of "none" gives the nominal model (as identified on the reference, if any).
StatusOr<valvebench::v1::ModelSpec> ImprovedModel(const Diagnosis& d, const valvebench::v1::ModelSpec& nominal,
                                                  const model::DriverParams& driver, const std::string& fitted_by);

// A ModelSpec as the files --model-out writes: indented protobuf JSON with the proto's field names.
std::string ModelSpecJson(const valvebench::v1::ModelSpec& spec);

}  // namespace vb::gap
