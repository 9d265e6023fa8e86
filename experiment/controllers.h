// Builds the controller a spec names, with the spec's parameters over the documented defaults. This is the
// one place that knows every law; the Runner only sees control::Controller.
#pragma once

#include <memory>
#include <vector>

#include "common/status.h"
#include "control/controller.h"
#include "experiment/metrics.h"
#include "model/driver.h"
#include "model/params.h"
#include "valvebench/v1/spec.pb.h"

namespace vb::experiment {

struct BuiltController {
  std::unique_ptr<control::Controller> controller;
  ControlledVariable controlled = ControlledVariable::kNone;
  double pwm_period_s = 0.0;            // the valve PWM period, for the moving average of x (0 = none)
  std::vector<double> breakpoints_s;    // instants the law must be called at (segment starts)
};

// plant/driver/supply_V: the bench the spec selects, for defaults that depend on it (the dither planner's
// coil, the laws' nominal R and L) -- data handed to the law, never the model itself.
StatusOr<BuiltController> BuildController(const valvebench::v1::ExperimentSpec& spec,
                                          const model::PlantParams& plant, const model::DriverParams& driver,
                                          double supply_V);

}  // namespace vb::experiment
