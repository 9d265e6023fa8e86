// References and the valve on/off command, as pure functions of run time (no state, no allocation in At()).
#pragma once

#include <vector>

#include "common/status.h"
#include "control/controller.h"
#include "valvebench/v1/spec.pb.h"

namespace vb::experiment {

class ReferenceProfile {
 public:
  ReferenceProfile() = default;
  static StatusOr<ReferenceProfile> FromSpec(const valvebench::v1::ReferenceSpec& ref,
                                             const valvebench::v1::ValveCommand& command);
  // Reference value and rate, the valve command and the time since it last turned on.
  control::Reference At(double t_s) const;
  // Instants in [0, duration_s) where the reference or the command jumps (the runner ticks there too).
  std::vector<double> Breakpoints(double duration_s) const;
  bool has_reference() const { return kind_ != Kind::kNone; }
  // Period of the valve command (0 = always on).
  double command_period_s() const { return cmd_period_s_; }

 private:
  enum class Kind { kNone, kConstant, kSteps, kRamp, kSine, kOnOff };
  bool CommandOn(double t_s, double* t_since_on_s) const;
  Kind kind_ = Kind::kNone;
  double a_ = 0, b_ = 0, c_ = 0, d_ = 0;  // shape parameters (see FromSpec)
  std::vector<double> step_t_s_, step_value_;
  double cmd_period_s_ = 0.0, cmd_duty_ = 1.0;
};

}  // namespace vb::experiment
