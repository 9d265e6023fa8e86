#include "control/peak_and_hold.h"
#include "control/param_check.h"

#include <cmath>
#include <cstdlib>
#include <string>

namespace vb::control {
Status PeakAndHold::Validate(const Params& p) {
  VB_RETURN_IF_ERROR(CheckPositive("", "tick_period_s", p.tick_period_s));
  VB_RETURN_IF_ERROR(CheckPositive("", "switching_current_A", p.switching_current_A));
  VB_RETURN_IF_ERROR(CheckPositive("", "peak_time_max_s", p.peak_time_max_s));
  VB_RETURN_IF_ERROR(CheckPositive("", "holding_current_A", p.holding_current_A));
  VB_RETURN_IF_ERROR(CheckPositive("", "band_A", p.band_A));
  if (!(p.switching_current_A > p.holding_current_A)) {
    return Status::InvalidArgument("switching_current_A: must be > holding_current_A (" +
                                   std::to_string(p.holding_current_A) + "), got " +
                                   std::to_string(p.switching_current_A));
  }
  if (!(0.5 * p.band_A < p.holding_current_A)) {
    return Status::InvalidArgument("band_A: half the band must be < holding_current_A (" +
                                   std::to_string(p.holding_current_A) + "), got " + std::to_string(p.band_A));
  }
  if (!(std::isfinite(p.release_current_A) && p.release_current_A >= 0.0 &&
        p.release_current_A < p.holding_current_A)) {
    return Status::InvalidArgument("release_current_A: must be >= 0 and < holding_current_A (" +
                                   std::to_string(p.holding_current_A) + "), got " +
                                   std::to_string(p.release_current_A));
  }
  return Status::Ok();
}

StatusOr<PeakAndHold> PeakAndHold::Create(const Params& p) {
  VB_RETURN_IF_ERROR(Validate(p));
  return PeakAndHold(p);
}

PeakAndHold::PeakAndHold(const Params& p) : p_(p) {
  if (!Validate(p_).ok()) std::abort();  // invariant: callers validate first (Create does)
}

SwitchCommand PeakAndHold::Step(const Measurement& m, const Reference& r, ControllerState* state) const {
  ControllerState& st = *state;
  const double i = m.current_A;
  if (!std::isfinite(i)) return SwitchCommand::Gate(0);  // a transient fault: switch off, state untouched
  int phase = st.mode;

  if (!r.command_on) {
    st.x[kChopperGate] = 0.0;
    if (phase == kPeak || phase == kHold) phase = p_.reverse_on_release ? kReverse : kOff;
    if (phase == kReverse && !(i > p_.release_current_A)) phase = kOff;
    if (phase != kReverse) phase = kOff;
    st.mode = phase;
    return SwitchCommand::Gate(phase == kReverse ? -1 : 0);
  }

  if (phase != kPeak && phase != kHold) phase = kPeak;  // command_on turned true (or the run starts on)
  if (phase == kPeak) {
    if (i < p_.switching_current_A && r.t_since_on_s < p_.peak_time_max_s) {
      st.mode = kPeak;
      return SwitchCommand::Gate(1);
    }
    phase = kHold;
    st.x[kPeakEndTime] = r.t_since_on_s;
    st.x[kChopperGate] = 0.0;
  }

  // Hold: hysteresis chopper.
  const double half_band = 0.5 * p_.band_A;
  if (i < p_.holding_current_A - half_band) {
    st.x[kChopperGate] = 1.0;
  } else if (i > p_.holding_current_A + half_band) {
    st.x[kChopperGate] = 0.0;
  }
  st.mode = kHold;
  return SwitchCommand::Gate(st.x[kChopperGate] > 0.5 ? 1 : 0);
}

}  // namespace vb::control
