// The one number format for text ({fmt}):
//   FormatNumber: messages and names — up to 10 significant digits, no trailing zeros ("48", "0.1", "200000",
//     "2.5e-05"). Enough to quote any value a person typed, while round-off in computed ones
//     (0.05000000000000004 s) stays out of the text. Run keys' case names use it, so baselines keep matching.
//   FormatExact: the shortest text that reads back to the same double (store messages about stored values).
//   FormatUtc: a Unix time as "2026-11-25 13:52:48 UTC" (reports, stored notes, retention listings).
// Tables for people choose their column widths and precision with fmt format specs at the call.
#pragma once

#include <fmt/chrono.h>
#include <fmt/format.h>

#include <ctime>
#include <string>

namespace vb {

inline std::string FormatNumber(double v) { return fmt::format("{:.10g}", v); }
inline std::string FormatExact(double v) { return fmt::format("{}", v); }
inline std::string FormatUtc(double unix_s) {
  return fmt::format("{:%Y-%m-%d %H:%M:%S} UTC", fmt::gmtime(static_cast<std::time_t>(unix_s)));
}

}  // namespace vb
