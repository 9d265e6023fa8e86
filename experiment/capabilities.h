// Capabilities decide what runs, at submission and not at run time: whether a bench with these capabilities
// can run an experiment (supply voltage, recording rate, control-loop rate, PWM carriers, a position
// measurement, the driver topology). FailedPrecondition naming the spec field and both numbers.
#pragma once

#include "common/status.h"
#include "experiment/spec.h"
#include "hw/bench.h"

namespace vb::experiment {

Status CheckCapabilities(const Experiment& e, const hw::Capabilities& caps);

}  // namespace vb::experiment
