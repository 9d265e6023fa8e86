// Drivers: how the switch command (gate) becomes a coil voltage.
//
// kLowSideFlyback (default; the nominal contract): gate 1 -> v_coil = supply_V; gate 0 -> v_coil = -diode_drop_V
//   while i > 0 (the current freewheels through the diode); once i reaches 0 it stays 0 (v_coil = 0) until
//   the gate is 1 again.
// kHBridge: gate 1 -> +supply_V; gate -1 -> -supply_V (current may reverse); gate 0 -> all switches off, the
//   current returns to the supply through the body diodes: v_coil = -(supply_V + 2 diode_drop_V) sgn(i)
//   until i reaches 0 (fast decay).
// kInternalElectronics (seed 000 section 4): the valve's own electronics between a low-side gate and the coil.
//   On a rising gate: full supply for boost_time_s (the switching current opens the valve), then a chopper
//   regulates the current to hold_current_A within +/- hold_band_A/2 (the paper uses PI + PWM; a hysteretic
//   chopper holds the same mean current with exactly located switching events). On a falling gate: the
//   capacitor charged during opening reverses the coil voltage, v_coil = -reverse_V exp(-t/reverse_tau_s)
//   (the paper's "low-pass filter with initial value"), until i reaches 0.
#pragma once

#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "common/status.h"

namespace vb::model {

enum class DriverKind { kLowSideFlyback, kHBridge, kInternalElectronics };

struct DriverParams {
  DriverKind kind = DriverKind::kLowSideFlyback;
  double diode_drop_V = 0.7;       // forward drop of the flyback / body diodes
  double boost_time_s = 5.0e-3;    // internal electronics: full supply after a rising gate
  double hold_current_A = 0.5;     // internal electronics: holding current (seed 000: about 0.5 A)
  double hold_band_A = 0.02;       // internal electronics: chopper hysteresis band
  double reverse_V = 24.0;         // internal electronics: initial reverse voltage on release
  double reverse_tau_s = 1.0e-3;   // internal electronics: decay time constant of the reverse voltage
};

std::string_view DriverKindName(DriverKind kind);
StatusOr<DriverKind> ParseDriverKind(std::string_view name);
std::vector<std::string> DriverKindNames();
// Gate levels the driver accepts: {0, 1}, or {-1, 0, 1} for the H-bridge.
inline bool AcceptsGate(DriverKind kind, int gate) {
  return gate == 0 || gate == 1 || (gate == -1 && kind == DriverKind::kHBridge);
}

Status SetDriverParam(DriverParams* d, std::string_view name, double value);
Status Validate(const DriverParams& d);

// Two instants closer than this are the same instant (sample grid vs. edges computed in floating point).
inline constexpr double kSameInstant_s = 1e-12;

// What the driver puts on the coil until its next event: a piece of the simulation (model/simulator.h) runs
// on one segment.
struct DriveSegment {
  double v0_V = 0.0;       // coil voltage at t_origin_s
  double tau_s = 0.0;      // > 0: v = v0 exp(-(t - t_origin)/tau) (internal electronics' reverse); 0: constant
  double t_origin_s = 0.0;
  double t_end_s = std::numeric_limits<double>::infinity();  // a time event of the driver (boost end)
  int clamp = 0;           // +1: conduction ends when i falls to 0; -1: when i rises to 0
  bool blocked = false;    // i is held at 0 (diode blocks), v_coil = 0
  double level_A = 0.0;    // driver threshold event on i (the chopper) ...
  int level_dir = 0;       // ... crossed upward (+1) or downward (-1); 0 = none
  bool from_supply = false;  // the supply drives the coil (its source resistance is in series)

  // The driver's voltage at t (the open-circuit source; the coil's terminal voltage is in model/coil.h).
  double VoltageAt(double t_s) const;
};

// The driver's state machine: gate -> coil voltage, as described at the top of this file. It knows the gate,
// whether a diode blocks the current, and the internal electronics' boost and chopper; the simulator tells it
// the time, the coil current and the events it located (current zero, chopper level).
class Driver {
 public:
  explicit Driver(const DriverParams& params) : p_(params) {}

  const DriverParams& params() const { return p_; }
  // Gate 0, current blocked, no boost or chopper running.
  void Reset();
  // A new gate level at t_s (the caller guarantees AcceptsGate). Returns false if the level did not change.
  bool SetGate(int gate, double t_s);
  int gate() const { return gate_; }
  bool blocked() const { return state_.blocked; }
  // The coil current was set from outside (> 0): the diode conducts again.
  void Unblock() { state_.blocked = false; }
  // Events the simulator located on the segment: the terminal current reached zero (clamp), or the chopper's
  // level was crossed (level_dir).
  void OnCurrentZero() { state_.blocked = true; }
  void OnLevelCrossed() { state_.chopper_on = !state_.chopper_on; }

  // The segment in force at t_s for the coil current i_A (the simulator passes its magnetising current),
  // advancing the state machine: a current that is no longer positive in a freewheel path becomes blocked,
  // the chopper starts after the boost. When the segment is blocked the caller holds the current at 0 (unless
  // an eddy branch carries it).
  DriveSegment Segment(double supply_V, double t_s, double i_A) { return Next(p_, gate_, supply_V, t_s, i_A, &state_); }
  // The same segment without changing the state (for const readers).
  DriveSegment PeekSegment(double supply_V, double t_s, double i_A) const {
    State copy = state_;
    return Next(p_, gate_, supply_V, t_s, i_A, &copy);
  }

 private:
  struct State {
    bool blocked = true;
    double t_gate_change_s = 0.0;
    bool chopper_started = false;
    bool chopper_on = false;
  };
  static DriveSegment Next(const DriverParams& p, int gate, double supply_V, double t_s, double i_A, State* s);

  DriverParams p_;
  int gate_ = 0;
  State state_;
};

}  // namespace vb::model
