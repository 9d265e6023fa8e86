// The one number format for text ({fmt}):
//   FormatNumber: messages and names — up to 10 significant digits, no trailing zeros ("48", "0.1", "200000",
//     "2.5e-05"). Enough to quote any value a person typed, while round-off in computed ones
//     (0.05000000000000004 s) stays out of the text. Run keys' case names use it, so baselines keep matching.
//   FormatExact: the shortest text that reads back to the same double (store messages about stored values).
// Tables for people choose their column widths and precision with fmt format specs at the call.
#pragma once

#include <fmt/format.h>

#include <string>

namespace vb {

inline std::string FormatNumber(double v) { return fmt::format("{:.10g}", v); }
inline std::string FormatExact(double v) { return fmt::format("{}", v); }

}  // namespace vb
