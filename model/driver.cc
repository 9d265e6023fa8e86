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

}  // namespace vb::model
