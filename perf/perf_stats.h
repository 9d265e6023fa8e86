// What the perf programs that measure rates print beside them: a Wilson interval, the process's CPU time and the
// machine's load (perf_identify, perf_changes).
#pragma once

#include <algorithm>
#include <cmath>
#include <ctime>
#include <fstream>
#include <string>
#include <utility>

namespace vb::perf {

// Wilson score interval for k successes in n trials at 95 % (z = 1.96): valid at small n and near 0 or 1,
// where the normal approximation is not.
inline std::pair<double, double> Wilson(int k, int n) {
  if (n == 0) return {0.0, 1.0};
  const double z = 1.96, p = static_cast<double>(k) / n, z2 = z * z / n;
  const double c = (p + z2 / 2.0) / (1.0 + z2);
  const double h = z * std::sqrt(p * (1.0 - p) / n + z * z / (4.0 * n * n)) / (1.0 + z2);
  return {std::max(0.0, c - h), std::min(1.0, c + h)};
}

// Process CPU time over all threads.
inline double CpuSeconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

// /proc/loadavg's three averages, "unknown" where there is none.
inline std::string LoadAverage() {
  std::ifstream f("/proc/loadavg");
  std::string a, b, c;
  f >> a >> b >> c;
  return a.empty() ? "unknown" : a + " " + b + " " + c;
}

}  // namespace vb::perf
