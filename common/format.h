// Numbers in messages: up to 10 significant digits, no trailing zeros ("48", "0.1", "200000", "2.5e-05"). Enough
// to quote any value a person typed, while round-off in computed ones (0.05000000000000004 s) stays out of
// the text. (The store's own %.17g and the tables' %.6g serve other ends.)
#pragma once

#include <cstdio>
#include <string>

namespace vb {

inline std::string FormatNumber(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.10g", v);
  return buf;
}

}  // namespace vb
