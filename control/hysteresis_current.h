// Hysteresis (relay, bang-bang) coil-current controller.
//
// Implements Najjari, Fotuhi, Vaezipour (2021), section 3.1, eq. (2): a relay with hysteresis band H centred on
// the desired current i_d, evaluated every sample_period_s seconds on the measured current i:
//
//     gate = 1          if i <= i_d - H/2
//     gate = 0          if i >= i_d + H/2
//     gate unchanged    if i_d - H/2 < i < i_d + H/2
//
// Decision on the paper: eq. (2) as printed reads "1 if i_a <= i_d + H/2; 0 if i_a >= i_d - H/2; no change if
// |i_a| < H/2". Taken literally the two switching conditions overlap on [i_d - H/2, i_d + H/2] and the "no
// change" condition compares the current itself (not the error) with H/2, so it is not a relay at all. We
// implement the evident intent, the textbook current-hysteresis relay above (band H centred on i_d, i.e. the
// "no change" condition is |i_a - i_d| < H/2). See docs/current-controllers.md.
//
// Output: SwitchCommand::Gate(1) (supply on the coil) or Gate(0) (switch off, the coil freewheels through the
// driver's flyback diode). When Reference::command_on is false the law releases: Gate(0) and the relay resets.
// A non-finite current measurement is treated as a fault: Gate(0), state unchanged.
//
// ControllerState slots:
//   mode  relay output held between ticks: 0 = gate off, 1 = gate on.
//   x[]   unused (left at 0).
#pragma once

#include <string_view>

#include "common/status.h"
#include "control/controller.h"

namespace vb::control {

struct HysteresisCurrentParams {
  // Hysteresis band H [A]: the relay switches on at i_d - H/2 and off at i_d + H/2. 20 mA (4 % of the 0.5 A
  // hold level) gives a ~2 kHz switching frequency on taghizadeh2009 at 0.5 A (L ~ 0.12 H, 24 V, 0.7 V diode).
  double band_A = 0.02;
  // Sampling period [s] at which the relay is evaluated. 10 us (100 kHz) adds at most ~1.5 mA of overshoot
  // beyond each threshold (di/dt <= (24 V - R i)/L ~ 150 A/s on taghizadeh2009).
  double sample_period_s = 10e-6;
};

class HysteresisCurrent final : public Controller {
 public:
  using Params = HysteresisCurrentParams;

  // Names the offending field, e.g. "hysteresis.band_A: must be > 0, got -0.1".
  static Status Validate(const Params& p);
  // Validates, then constructs.
  static StatusOr<HysteresisCurrent> Create(const Params& p);

  // Precondition: Validate(p).ok() (use Create() to check).
  explicit HysteresisCurrent(const Params& p = Params()) : p_(p) {}

  std::string_view name() const override { return "hysteresis_current"; }
  double period_s() const override { return p_.sample_period_s; }
  ControllerState InitialState() const override { return {}; }
  SwitchCommand Step(const Measurement& m, const Reference& r, ControllerState* state) const override;

  const Params& params() const { return p_; }

 private:
  Params p_;
};

}  // namespace vb::control
