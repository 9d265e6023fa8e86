#include "control/param_check.h"

#include <cmath>

namespace vb::control {

Status CheckPositive(std::string_view prefix, std::string_view field, double v) {
  if (std::isfinite(v) && v > 0.0) return Status::Ok();
  return Status::InvalidArgument(std::string(prefix) + std::string(field) + ": must be > 0, got " + FormatNumber(v));
}

Status CheckNonNegative(std::string_view prefix, std::string_view field, double v) {
  if (std::isfinite(v) && v >= 0.0) return Status::Ok();
  return Status::InvalidArgument(std::string(prefix) + std::string(field) + ": must be >= 0, got " +
                                 FormatNumber(v));
}

}  // namespace vb::control
