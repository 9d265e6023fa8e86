#include "model/driver.h"

#include <cmath>
#include <sstream>

namespace vb::model {

std::string_view DriverKindName(DriverKind kind) {
  switch (kind) {
    case DriverKind::kLowSideFlyback: return "low_side_flyback";
    case DriverKind::kHBridge: return "h_bridge";
    case DriverKind::kInternalElectronics: return "internal_electronics";
  }
  return "low_side_flyback";
}

std::vector<std::string> DriverKindNames() { return {"low_side_flyback", "h_bridge", "internal_electronics"}; }

StatusOr<DriverKind> ParseDriverKind(std::string_view name) {
  if (name.empty() || name == "low_side_flyback") return DriverKind::kLowSideFlyback;
  if (name == "h_bridge") return DriverKind::kHBridge;
  if (name == "internal_electronics") return DriverKind::kInternalElectronics;
  return Status::InvalidArgument("unknown driver '" + std::string(name) +
                                 "' (known: low_side_flyback, h_bridge, internal_electronics)");
}

namespace {
struct DriverParamInfo {
  std::string_view name;
  double DriverParams::*field;
  double min, max;
};
const DriverParamInfo kDriverParams[] = {
    {"diode_drop_V", &DriverParams::diode_drop_V, 0.0, 5.0},
    {"boost_time_s", &DriverParams::boost_time_s, 0.0, 10.0},
    {"hold_current_A", &DriverParams::hold_current_A, 0.0, 100.0},
    {"hold_band_A", &DriverParams::hold_band_A, 1e-6, 10.0},
    {"reverse_V", &DriverParams::reverse_V, 0.0, 1000.0},
    {"reverse_tau_s", &DriverParams::reverse_tau_s, 1e-7, 10.0},
};
}  // namespace

Status SetDriverParam(DriverParams* d, std::string_view name, double value) {
  for (const auto& info : kDriverParams) {
    if (info.name != name) continue;
    if (!std::isfinite(value) || value < info.min || value > info.max) {
      std::ostringstream os;
      os << "driver parameter " << name << " = " << value << " is outside [" << info.min << ", " << info.max << "]";
      return Status::InvalidArgument(os.str());
    }
    d->*(info.field) = value;
    return Status::Ok();
  }
  std::string known;
  for (const auto& info : kDriverParams) known += (known.empty() ? "" : ", ") + std::string(info.name);
  return Status::InvalidArgument("unknown driver parameter '" + std::string(name) + "' (known: " + known + ")");
}

Status Validate(const DriverParams& d) {
  for (const auto& info : kDriverParams) {
    double v = d.*(info.field);
    if (!std::isfinite(v) || v < info.min || v > info.max) {
      std::ostringstream os;
      os << "driver parameter " << info.name << " = " << v << " is outside [" << info.min << ", " << info.max << "]";
      return Status::InvalidArgument(os.str());
    }
  }
  if (d.kind == DriverKind::kInternalElectronics && d.hold_band_A >= 2.0 * d.hold_current_A)
    return Status::InvalidArgument("driver parameter hold_band_A must be less than twice hold_current_A");
  return Status::Ok();
}

double DriveSegment::VoltageAt(double t_s) const {
  if (blocked) return 0.0;
  if (tau_s > 0.0) return v0_V * std::exp(-(t_s - t_origin_s) / tau_s);
  return v0_V;
}

void Driver::Reset() {
  gate_ = 0;
  state_ = State{};
}

bool Driver::SetGate(int gate, double t_s) {
  if (gate == gate_) return false;
  gate_ = gate;
  state_.t_gate_change_s = t_s;
  state_.chopper_started = false;
  if (gate != 0) state_.blocked = false;
  return true;
}

DriveSegment Driver::Next(const DriverParams& p, int gate, double supply_V, double t_s, double i_A, State* st) {
  DriveSegment s;
  const double drop = p.diode_drop_V;
  auto block = [&]() {
    st->blocked = true;
    s.blocked = true;
  };
  switch (p.kind) {
    case DriverKind::kLowSideFlyback:
      if (gate == 1) {
        s.v0_V = supply_V;
        s.from_supply = true;
      } else if (st->blocked || i_A <= 0.0) {
        block();
      } else {
        s.v0_V = -drop;
        s.clamp = +1;
      }
      break;
    case DriverKind::kHBridge:
      if (gate == 1) {
        s.v0_V = supply_V;
        s.from_supply = true;
      } else if (gate == -1) {
        s.v0_V = -supply_V;
        s.from_supply = true;
      } else if (!st->blocked && i_A > 0.0) {
        s.v0_V = -(supply_V + 2.0 * drop);
        s.clamp = +1;
      } else if (!st->blocked && i_A < 0.0) {
        s.v0_V = supply_V + 2.0 * drop;
        s.clamp = -1;
      } else {
        block();
      }
      break;
    case DriverKind::kInternalElectronics: {
      if (gate == 1) {
        const double boost_end = st->t_gate_change_s + p.boost_time_s;
        if (t_s < boost_end - kSameInstant_s) {
          s.v0_V = supply_V;
          s.from_supply = true;
          s.t_end_s = boost_end;
          break;
        }
        const double lo = p.hold_current_A - 0.5 * p.hold_band_A;
        const double hi = p.hold_current_A + 0.5 * p.hold_band_A;
        if (!st->chopper_started) {
          st->chopper_started = true;
          st->chopper_on = i_A < lo;
        }
        if (!st->chopper_on && (st->blocked || i_A <= 0.0)) st->chopper_on = true;
        if (st->chopper_on) {
          st->blocked = false;
          s.v0_V = supply_V;
          s.from_supply = true;
          s.level_A = hi;
          s.level_dir = +1;
        } else {
          s.v0_V = -drop;
          s.clamp = +1;
          s.level_A = lo;
          s.level_dir = -1;
        }
      } else if (st->blocked || i_A <= 0.0) {
        // Reverse voltage from the capacitor, decaying from the gate's falling edge, until the current is 0.
        block();
      } else {
        s.v0_V = -p.reverse_V;
        s.tau_s = p.reverse_tau_s;
        s.t_origin_s = st->t_gate_change_s;
        s.clamp = +1;
      }
      break;
    }
  }
  return s;
}

}  // namespace vb::model
