// The controller interface: a discrete-time law called at its own rate with the latest measurement and
// reference, returning a switch command that the bench's PWM peripheral realises until the next tick.
//
// A law is `const` code; everything that changes between ticks lives in a small, copyable ControllerState
// (after Drake's System/Context split), so reset, replay and the sim-to-real comparison are copies of data.
// A controller sees measurements only, never the plant model, so the same law runs on the emulator and on a
// USB bench. Model-based laws carry the nominal plant values they need as their own parameters (data).
//
// Real-time contract for Step(): no allocation, no locks, no I/O, no exceptions.
#pragma once

#include <array>
#include <cstdint>
#include <string_view>

#include "common/bench_io.h"

namespace vb::control {

// The bench vocabulary (common/bench_io.h), visible here as part of the controller interface.
using ::vb::kNotMeasured;
using ::vb::Measurement;
using ::vb::SwitchCommand;

// What the experiment wants at this tick.
struct Reference {
  double value = 0.0;       // reference of the controlled variable: A for current laws, m for position laws
  double rate = 0.0;        // its time derivative (A/s or m/s); 0 where the profile has none
  bool command_on = true;   // the valve's on/off command: false asks the law to release (de-energise) the coil
  double t_since_on_s = 0.0;  // time since command_on last went true (peak-and-hold and profile timing)
};

// The mutable part of a controller: plain data, no heap. Each law documents what its slots hold.
struct ControllerState {
  std::array<double, 8> x{};  // continuous state: integrators, previous error, filtered values, ...
  std::int32_t mode = 0;      // discrete state: hysteresis output, peak/hold phase, ...
};

class Controller {
 public:
  virtual ~Controller() = default;
  // Stable identifier used in specs, metrics and comparisons, e.g. "pi_current".
  virtual std::string_view name() const = 0;
  // The law is called every period_s seconds (its sampling period).
  virtual double period_s() const = 0;
  // State at the start of a run.
  virtual ControllerState InitialState() const { return {}; }
  // One tick: read m and r, update *state, return the command for the next period.
  virtual SwitchCommand Step(const Measurement& m, const Reference& r, ControllerState* state) const = 0;
  // The ControllerState::x slot that holds, after Step, the law's own control input u as its paper defines it
  // (the position laws: the force demand, seed 002 eqs. 7 and 22), or -1. The Runner integrates it into
  // seed 002's effort ||u||_2 (docs/metrics.md); reading one double keeps Step's real-time contract.
  virtual int input_slot() const { return -1; }
};

// Turns a voltage demand into a PWM command on a bench whose switch puts supply_V or ~0 V on the coil:
// duty = clamp(v / supply_V, 0, 1). Laws that compute a coil voltage (PI, predictive, fuzzy, SMC) use it.
inline SwitchCommand VoltageToPwm(double v_coil_V, double supply_V, double carrier_Hz) {
  double duty = supply_V > 0.0 ? v_coil_V / supply_V : 0.0;
  duty = duty < 0.0 ? 0.0 : (duty > 1.0 ? 1.0 : duty);
  return SwitchCommand::Pwm(duty, carrier_Hz);
}

}  // namespace vb::control
