// Reads ../shared/perfref traces (t_s, i_A, x_m) and event lists.
#pragma once

#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

namespace vb::testing {

struct RefTrace {
  std::vector<double> t_s, i_A, x_m;
};
struct RefEvent {
  double t_s;
  std::string kind;
};

inline std::string PerfrefPath(const std::string& file) { return std::string(VB_SHARED_DIR) + "/perfref/" + file; }

inline RefTrace LoadRefTrace(const std::string& name) {
  RefTrace r;
  std::ifstream in(PerfrefPath("truth_" + name + ".csv"));
  std::string line;
  std::getline(in, line);
  while (std::getline(in, line)) {
    double t, i, x;
    if (std::sscanf(line.c_str(), "%lf,%lf,%lf", &t, &i, &x) == 3) {
      r.t_s.push_back(t);
      r.i_A.push_back(i);
      r.x_m.push_back(x);
    }
  }
  return r;
}

inline std::vector<RefEvent> LoadRefEvents(const std::string& name) {
  std::vector<RefEvent> out;
  std::ifstream in(PerfrefPath("truth_" + name + "_events.csv"));
  std::string line;
  std::getline(in, line);
  while (std::getline(in, line)) {
    double t;
    char kind[32];
    if (std::sscanf(line.c_str(), "%lf,%31[^,]", &t, kind) == 2) out.push_back({t, kind});
  }
  return out;
}

}  // namespace vb::testing
