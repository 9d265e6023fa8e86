#include "control/open_loop_pwm.h"

#include <cmath>
#include <sstream>

namespace vb::control {

Status OpenLoopPwm::Validate(const std::vector<PwmSegment>& segments) {
  if (segments.empty()) return Status::InvalidArgument("segments: at least one segment is needed");
  for (size_t k = 0; k < segments.size(); ++k) {
    const PwmSegment& s = segments[k];
    std::ostringstream field;
    field << "segments[" << k << "]";
    if (k == 0 && s.start_s != 0.0)
      return Status::InvalidArgument(field.str() + ".start_s: the first segment must start at 0");
    if (k > 0 && !(s.start_s > segments[k - 1].start_s))
      return Status::InvalidArgument(field.str() + ".start_s: segments must start in increasing order");
    if (!std::isfinite(s.frequency_Hz) || s.frequency_Hz < 0.0)
      return Status::InvalidArgument(field.str() + ".frequency_Hz: must be >= 0");
    if (!(s.duty >= 0.0 && s.duty <= 1.0))
      return Status::InvalidArgument(field.str() + ".duty: must be in [0, 1]");
    if (s.frequency_Hz == 0.0 && s.duty != 0.0 && s.duty != 1.0)
      return Status::InvalidArgument(field.str() +
                                     ".duty: with frequency_Hz 0 (a constant gate) the duty must be 0 or 1");
  }
  return Status::Ok();
}

SwitchCommand OpenLoopPwm::Step(const Measurement& m, const Reference& /*r*/, ControllerState* state) const {
  int idx = state->mode < 0 ? 0 : state->mode;
  while (idx + 1 < static_cast<int>(segments_.size()) && segments_[idx + 1].start_s <= m.t_s + 1e-12) ++idx;
  const PwmSegment& s = segments_[idx];
  const bool entered = idx != state->mode;
  state->mode = idx;
  if (s.frequency_Hz == 0.0) return SwitchCommand::Gate(s.duty >= 0.5 ? 1 : 0);
  SwitchCommand c = SwitchCommand::Pwm(s.duty, s.frequency_Hz);
  c.restart_carrier = entered;
  return c;
}

}  // namespace vb::control
