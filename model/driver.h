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

}  // namespace vb::model
