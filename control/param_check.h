// Parameter checks shared by the laws' Validate(): one wording for every "field: problem, got value" message.
#pragma once

#include <string>
#include <string_view>

#include "common/format.h"
#include "common/status.h"

namespace vb::control {

// InvalidArgument "<prefix><field>: must be > 0, got <v>" unless v is finite and > 0.
Status CheckPositive(std::string_view prefix, std::string_view field, double v);
// InvalidArgument "<prefix><field>: must be >= 0, got <v>" unless v is finite and >= 0.
Status CheckNonNegative(std::string_view prefix, std::string_view field, double v);

}  // namespace vb::control
