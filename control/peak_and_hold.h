// Peak-and-hold coil drive (Taghizadeh, Ghaffari, Najafi, C. R. Mecanique 2009 = seed 000, section 4; the same
// scheme as peak-and-hold injector drivers): full supply until the coil current reaches the switching current
// that moves the spool, then a much lower holding current that keeps it at its end stop, and a reverse voltage at
// release so the current, and with it the force, collapses fast. See docs/position-controllers.md.
//
// Phases (state.mode), evaluated every tick from the measured current and the reference's on/off command:
//   kOff     command off, coil released                           -> gate 0
//   kPeak    command on, i < switching_current_A and
//            Reference.t_since_on_s < peak_time_max_s            -> gate 1 (full supply)
//   kHold    hysteresis chopper around holding_current_A:
//            gate 1 when i < holding - band/2, gate 0 when i > holding + band/2, else keep the last gate
//   kReverse command off with reverse_on_release (H-bridge): gate -1 while i > release_current_A, then kOff
// Transitions: kOff/kReverse -> kPeak when command_on is true; kPeak -> kHold when i >= switching_current_A or
// t_since_on_s >= peak_time_max_s (checked on the same tick, so the first hold command is already hysteresis);
// kPeak/kHold -> kReverse (or kOff without reverse_on_release) when command_on is false.
//
// The hold is a hysteresis chopper rather than a fixed-duty PWM: it regulates the current itself (the seed's valve
// does it with an internal PWM and a PI), so the holding current does not move with supply voltage, coil
// temperature (R) or spool position (L), and it needs no knowledge of R. Its switching frequency follows from the
// band and the coil: about 0.85 kHz for the seed's valve (L ~ 0.12 H, R = 13 ohm, 24 V, band 0.05 A) on a
// low-side driver, ~1.9 kHz on an H-bridge, whose off state (gate 0) is fast decay at -(V + 2 V_d).
// reverse_on_release needs a driver that accepts gate -1 (H-bridge); the Runner must not enable it on a
// low-side bench. On the emulator's H-bridge gate 0 already decays fast, so there the reverse phase mostly states
// the intent of the seed's capacitor; it matters on bridges whose off state freewheels.
// The law needs the coil current only (NeedsPosition() is false); a non-finite current gives gate 0 for that
// tick with the state untouched.
#pragma once

#include <string_view>

#include "common/status.h"
#include "control/controller.h"

namespace vb::control {

class PeakAndHold final : public Controller {
 public:
  // Defaults for the taghizadeh2009 valve (24 V, R = 13 ohm): the current has to pass ~0.6 A to move the spool
  // (the local peak of Fig. 4 at 0.64 A), the internal drive holds 0.5 A.
  struct Params {
    double tick_period_s = 20e-6;      // control period; short against the coil's L/R (~9 ms) so the chopper's
                                       // overshoot per tick stays small (~3 mA at 24 V)
    double switching_current_A = 0.9;  // peak phase ends when the current reaches it (well above the ~0.6 A
                                       // needed to move the spool, so the spool is at its stop when it ends)
    double peak_time_max_s = 0.02;     // peak phase ends at the latest this long after command_on (a weak supply
                                       // that never reaches the switching current still gets to hold)
    double holding_current_A = 0.5;    // hold phase current (the seed's 0.5 A)
    double band_A = 0.05;         // full width of the hysteresis band around holding_current_A
    bool reverse_on_release = false;   // the bench has an H-bridge: apply -supply at release (fast decay)
    double release_current_A = 0.02;   // reverse voltage stops once the current is below this (then gate 0)
  };

  // state.mode values (the phase):
  static constexpr int kOff = 0;
  static constexpr int kPeak = 1;
  static constexpr int kHold = 2;
  static constexpr int kReverse = 3;
  // state.x slots (units in brackets):
  static constexpr int kChopperGate = 0;  // last hold-chopper output, 0 or 1 [-]
  static constexpr int kPeakEndTime = 1;  // Reference.t_since_on_s when the last peak phase ended [s] (telemetry)

  static Status Validate(const Params& p);
  static StatusOr<PeakAndHold> Create(const Params& p);
  // p must be valid (Validate); an invalid p is a programming error and aborts.
  explicit PeakAndHold(const Params& p);

  std::string_view name() const override { return "peak_and_hold"; }
  double period_s() const override { return p_.tick_period_s; }
  SwitchCommand Step(const Measurement& m, const Reference& r, ControllerState* state) const override;
  bool NeedsPosition() const { return false; }
  const Params& params() const { return p_; }

 private:
  Params p_;
};

}  // namespace vb::control
