#include "common/units.h"

#include <fmt/format.h>

#include <cmath>
#include <cstdlib>

namespace vb {

namespace {

// The unit's first factor: its symbol, its power and the rest ("m^2/m" -> "m", 2, "/m").
struct FirstFactor {
  std::string base;
  double power = 1;
  std::string rest;
};

FirstFactor Split(std::string_view unit) {
  FirstFactor f;
  std::size_t end = unit.find_first_of(" /*");
  if (end == std::string_view::npos) end = unit.size();
  std::string_view head = unit.substr(0, end);
  f.rest = std::string(unit.substr(end));
  const std::size_t caret = head.find('^');
  if (caret != std::string_view::npos) {
    f.power = std::atof(std::string(head.substr(caret + 1)).c_str());
    f.rest = std::string(head.substr(caret)) + f.rest;
    head = head.substr(0, caret);
  }
  f.base = std::string(head);
  return f;
}

bool Unprefixed(std::string_view unit) {
  if (unit.empty() || unit == "1" || unit == "%" || unit == "turns" || unit == "count" || unit == "K")
    return true;
  const char c = unit.front();
  return (c >= '0' && c <= '9') || c == '.';
}

}  // namespace

const std::vector<UnitPrefix>& UnitPrefixes() {
  static const std::vector<UnitPrefix> kTable = {{"G", 1e-9}, {"M", 1e-6}, {"k", 1e-3}, {"", 1},
                                                 {"m", 1e3},  {"µ", 1e6},  {"n", 1e9},  {"p", 1e12}};
  return kTable;
}

UnitChoice ChooseUnit(double max_abs, std::string_view unit) {
  if (Unprefixed(unit)) return {std::string(unit), 1.0};
  FirstFactor f = Split(unit);
  double to_base = 1.0;  // SI value * to_base = value in the unprefixed first factor
  if (f.base == "kg") {
    f.base = "g";
    to_base = std::pow(1e3, f.power);
  }
  const auto& table = UnitPrefixes();
  const UnitPrefix* pick = &table[3];  // no prefix
  if (max_abs > 0 && std::isfinite(max_abs)) {
    pick = &table.back();
    for (const auto& p : table)
      if (max_abs * to_base * std::pow(p.scale, f.power) >= 1.0 - 1e-12) {
        pick = &p;
        break;
      }
  } else if (to_base != 1.0) {
    pick = &table[2];  // 0 kg stays "kg"
  }
  return {std::string(pick->symbol) + f.base + f.rest, to_base * std::pow(pick->scale, f.power)};
}

std::string FormatQuantity(double v, std::string_view unit) {
  if (!std::isfinite(v)) return "-";
  const UnitChoice c = ChooseUnit(std::abs(v), unit);
  const std::string suffix = c.unit.empty() || c.unit == "1" ? "" : " " + c.unit;
  if (v == 0.0) return "0" + suffix;
  const double x = v * c.scale;
  // Whole numbers in full (a count, "40000 Hz" has no prefix to take... "40 kHz" does), otherwise 4 significant
  // digits without trailing zeros ("953.3", "27.73"): web/static/format.js value() writes the same.
  if (x == std::round(x) && std::abs(x) < 1e9) return fmt::format("{:.0f}", x) + suffix;
  return fmt::format("{:.4g}", x) + suffix;
}

}  // namespace vb
