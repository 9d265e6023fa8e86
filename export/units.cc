// Units of channels and metrics: names carry their SI unit as a suffix; the few that cannot take the
// controlled variable's unit. Mirrors python/valvebench/units.py (tests compare the two).
#include <array>
#include <string_view>
#include <utility>

#include "export/run_file.h"

namespace vb::exportfile {
namespace {

bool EndsWith(std::string_view s, std::string_view suffix) {
  return s.size() > suffix.size() && s.substr(s.size() - suffix.size()) == suffix;
}

std::string ControlledUnit(const std::string& controller) {
  if (controller == "cascade_pi_position" || controller == "sliding_mode_position") return "m";
  if (controller.empty() || controller == "open_loop_pwm" || controller == "dither_pwm") return "";
  return "A";
}

}  // namespace

std::string ChannelUnit(const std::string& channel, const std::string& controller) {
  static const std::array<std::pair<std::string_view, std::string_view>, 11> kNamed = {{{"t_s", "s"},
                                                                                        {"gate", "1"},
                                                                                        {"v_coil_V", "V"},
                                                                                        {"i_A", "A"},
                                                                                        {"x_m", "m"},
                                                                                        {"v_mps", "m/s"},
                                                                                        {"x_avg_m", "m"},
                                                                                        {"flow_kg_per_s", "kg/s"},
                                                                                        {"v2_int_V2s", "V^2 s"},
                                                                                        {"energy_int_J", "J"},
                                                                                        {"switch_count", "1"}}};
  for (const auto& [name, unit] : kNamed)
    if (channel == name) return std::string(unit);
  if (channel == "ref") return ControlledUnit(controller);
  static const std::array<std::pair<std::string_view, std::string_view>, 12> kSuffix = {{{"_kg_per_s", "kg/s"},
                                                                                         {"_mps", "m/s"},
                                                                                         {"_V2s", "V^2 s"},
                                                                                         {"_pct", "%"},
                                                                                         {"_Pa", "Pa"},
                                                                                         {"_Hz", "Hz"},
                                                                                         {"_J", "J"},
                                                                                         {"_W", "W"},
                                                                                         {"_V", "V"},
                                                                                         {"_A", "A"},
                                                                                         {"_m", "m"},
                                                                                         {"_s", "s"}}};
  for (const auto& [suffix, unit] : kSuffix)
    if (EndsWith(channel, suffix)) return std::string(unit);
  return "";
}

std::string MetricUnit(const std::string& metric, const std::string& controller) {
  // Laws without a reference have no tracking metrics; A is the unit they would have (the current).
  const std::string controlled = ControlledUnit(controller);
  const std::string y = controlled.empty() ? std::string("A") : controlled;
  if (metric == "rmse" || metric == "max_abs_error") return y;
  if (metric == "iae") return y + " s";
  if (metric == "overshoot" || metric == "switches") return "1";
  if (metric == "effort_l2") return "V s^0.5";
  if (metric == "effort_rms") return "V";
  return ChannelUnit(metric, controller);
}

}  // namespace vb::exportfile
