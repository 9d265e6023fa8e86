// Quantities for people: the one rule every surface applies (benchctl's tables and single-run output, `show`,
// the web pages through web/static/format.js, which implements the same rule, Python's reprs through the CLI's
// text, CSV headers): an SI value in its SI unit, written with the SI prefix that puts its magnitude in
// [1, 1000) and 4 significant digits ("953.3 µA", "81.13 mm^2", "27.73 g", "751.4 mg/s").
//
// Compound units take the prefix on their first factor, raised to that factor's power: m^2 -> mm^2 is a
// factor 1e6 (not 1e3), "N s/m" -> "mN s/m", "V s^0.5" -> "mV s^0.5". The kilogram is a prefixed gram:
// 0.02773 kg is "27.73 g", 7.514e-4 kg/s is "751.4 mg/s". Units that take no prefix: "" and "1"
// (dimensionless), "%", "turns", "count", "K" (a temperature reads best whole), and a first factor that is a number ("1/s").
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace vb {

struct UnitPrefix {
  const char* symbol;
  double scale;  // value in the base unit * scale = value in the prefixed unit
};
// G, M, k, "", m, µ, n, p: largest first.
const std::vector<UnitPrefix>& UnitPrefixes();

// How values of largest magnitude `max_abs` in SI `unit` are shown: the prefixed unit and the factor from SI.
struct UnitChoice {
  std::string unit;   // "mm^2"; "" for a dimensionless value
  double scale = 1;   // SI value * scale = shown number
};
UnitChoice ChooseUnit(double max_abs, std::string_view unit);

// One value with its unit, 4 significant digits, prefix on its own magnitude: "953.3 µA", "0 A", "-" (NaN).
std::string FormatQuantity(double v, std::string_view unit);

}  // namespace vb
