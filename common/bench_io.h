// The vocabulary shared by controllers and benches: what a bench measures and what it is told to do.
// Controllers (control/) and benches (hw/) both speak it; neither knows the other.
#pragma once

#include <cstdint>
#include <limits>

namespace vb {

inline constexpr double kNotMeasured = std::numeric_limits<double>::quiet_NaN();

// What the bench measured at the start of this tick.
struct Measurement {
  double t_s = 0.0;                      // time since the run started
  double current_A = 0.0;                // coil current
  double position_m = kNotMeasured;      // spool/plunger position; NaN when the bench has no sensor
  double velocity_mps = kNotMeasured;    // spool/plunger velocity; NaN when not available
  double supply_V = 0.0;                 // supply voltage across switch + coil when the gate is on
};

// How the bench drives the switch until the next tick.
struct SwitchCommand {
  enum class Mode : std::uint8_t { kGate, kPwm };
  Mode mode = Mode::kGate;
  // kGate: 1 = supply on the coil; 0 = switch off (freewheel through the driver's decay path);
  //        -1 = reverse supply (H-bridge only: fast decay, current may be driven negative).
  std::int8_t gate = 0;
  // kPwm: the gate is 1 for the first `duty` fraction of each carrier period, then 0. The bench applies a new
  //       duty at the next carrier period start (shadow register), as hardware timers do.
  double duty = 0.0;          // [0, 1]
  double carrier_Hz = 0.0;    // > 0
  // kPwm: true restarts the carrier period now (the new duty applies at once) instead of at the next period
  // start; a change of carrier frequency always restarts it.
  bool restart_carrier = false;

  static constexpr SwitchCommand Gate(int level) {
    SwitchCommand c;
    c.mode = Mode::kGate;
    c.gate = static_cast<std::int8_t>(level);
    return c;
  }
  static constexpr SwitchCommand Pwm(double duty, double carrier_Hz) {
    SwitchCommand c;
    c.mode = Mode::kPwm;
    c.duty = duty;
    c.carrier_Hz = carrier_Hz;
    return c;
  }
};

}  // namespace vb
