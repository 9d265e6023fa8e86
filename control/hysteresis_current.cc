#include "control/hysteresis_current.h"
#include "control/param_check.h"

#include <cmath>
#include <cstdio>
#include <string>

namespace vb::control {
Status HysteresisCurrent::Validate(const Params& p) {
  VB_RETURN_IF_ERROR(CheckPositive("hysteresis.", "band_A", p.band_A));
  VB_RETURN_IF_ERROR(CheckPositive("hysteresis.", "sample_period_s", p.sample_period_s));
  return Status::Ok();
}

StatusOr<HysteresisCurrent> HysteresisCurrent::Create(const Params& p) {
  Status s = Validate(p);
  if (!s.ok()) return s;
  return HysteresisCurrent(p);
}

SwitchCommand HysteresisCurrent::Step(const Measurement& m, const Reference& r, ControllerState* state) const {
  if (!r.command_on) {
    *state = InitialState();
    return SwitchCommand::Gate(0);
  }
  const double i = m.current_A;
  if (!std::isfinite(i) || !std::isfinite(r.value)) return SwitchCommand::Gate(0);

  const double half = 0.5 * p_.band_A;
  const double on_threshold = r.value - half;   // switch on at or below
  const double off_threshold = r.value + half;  // switch off at or above
  if (i <= on_threshold) {
    state->mode = 1;
  } else if (i >= off_threshold) {
    state->mode = 0;
  }  // else: inside the band, keep the previous output
  return SwitchCommand::Gate(state->mode != 0 ? 1 : 0);
}

}  // namespace vb::control
