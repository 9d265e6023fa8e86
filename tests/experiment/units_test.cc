// One formatter with units (common/units.h, issue 37): every parameter of the model's tables and every metric
// is written with its unit and a correct SI prefix, compound units included (a prefix on m^2 squares).
#include "common/units.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <string>

#include "experiment/compare.h"
#include "experiment/metrics.h"
#include "model/effects.h"
#include "model/params.h"

namespace vb {
namespace {

// Reads "81.13 mm^2" back into SI `unit` independently of ChooseUnit: the number, then the prefix that makes
// the printed unit the SI one (or the gram form of the kilogram), raised to the first factor's power.
double ReadBack(const std::string& text, const std::string& unit, std::string* why) {
  char* end = nullptr;
  const double x = std::strtod(text.c_str(), &end);
  std::string printed = *end == ' ' ? std::string(end + 1) : std::string(end);
  if (unit.empty() || unit == "1") {
    if (!printed.empty()) *why = "a dimensionless value printed a unit: " + text;
    return x;
  }
  // The SI unit's first factor and its power.
  std::size_t cut = unit.find_first_of(" /*");
  std::string head = unit.substr(0, cut == std::string::npos ? unit.size() : cut);
  double power = 1;
  if (auto caret = head.find('^'); caret != std::string::npos) {
    power = std::atof(head.substr(caret + 1).c_str());
    head = head.substr(0, caret);
  }
  const std::string tail = unit.substr(head.size());
  std::string si_base = head;
  double base_factor = 1;
  if (head == "kg") {
    si_base = "g";
    base_factor = 1e-3;  // 1 g = 1e-3 kg
  }
  const std::pair<const char*, double> prefixes[] = {{"G", 1e9}, {"M", 1e6}, {"k", 1e3}, {"m", 1e-3},
                                                     {"µ", 1e-6}, {"n", 1e-9}, {"p", 1e-12}, {"", 1}};
  for (const auto& [sym, f] : prefixes) {
    if (printed == std::string(sym) + si_base + tail) return x * std::pow(f, power) * std::pow(base_factor, power);
  }
  if (printed == unit) return x;  // an unprefixed unit (%, turns)
  *why = "'" + printed + "' is not a prefixed '" + unit + "'";
  return std::nan("");
}

void ExpectWrittenRight(double v, const std::string& unit, const std::string& what) {
  const std::string text = FormatQuantity(v, unit);
  std::string why;
  const double back = ReadBack(text, unit, &why);
  EXPECT_TRUE(why.empty()) << what << ": " << why;
  EXPECT_NEAR(back, v, 6e-4 * std::abs(v)) << what << " = " << v << " " << unit << " written " << text;
  // The mantissa in [1, 1000) whenever the unit takes a prefix and the value is not 0 ([1, 1e6) for a squared
  // first factor: its prefix steps are 1e6).
  const double mantissa = std::abs(std::strtod(text.c_str(), nullptr));
  const bool prefixable = !(unit.empty() || unit == "1" || unit == "%" || unit == "turns" || unit == "K" ||
                            (unit[0] >= '0' && unit[0] <= '9'));  // "1/K": a reciprocal takes no prefix
  const double top = unit.rfind("^2", unit.find_first_of(" /*")) != std::string::npos ? 1e6 : 1e3;
  if (prefixable && v != 0 && std::abs(v) > 1e-12 && std::abs(v) < 1e9) {
    EXPECT_TRUE(mantissa >= 1 && mantissa < top + 0.5) << what << " written " << text;
  }
}

TEST(Units, TheIssuesFigures) {
  EXPECT_EQ(FormatQuantity(81.13e-6, "m^2"), "81.13 mm^2");  // was "81.13 um^2": the prefix applied linearly
  EXPECT_EQ(FormatQuantity(0.02773, "kg"), "27.73 g");        // was "27.73 mkg"
  EXPECT_EQ(FormatQuantity(7.514e-4, "kg/s"), "751.4 mg/s");  // was "751.4 ukg/s"
  EXPECT_EQ(FormatQuantity(9.533e-4, "A"), "953.3 µA");
  EXPECT_EQ(FormatQuantity(8.67476e-05, "W"), "86.75 µW");    // was "8.67476e-05 W" in `show`
  EXPECT_EQ(FormatQuantity(3.669, "V s^0.5"), "3.669 V s^0.5");
  EXPECT_EQ(FormatQuantity(2e-3, "N s/m"), "2 mN s/m");
  EXPECT_EQ(FormatQuantity(0.8e-4, "m^2"), "80 mm^2");
  EXPECT_EQ(FormatQuantity(1.2e-4, "m^2"), "120 mm^2");
  EXPECT_EQ(FormatQuantity(2.0e-2, "m^2/m"), "20000 mm^2/m");  // a prefix step on m^2 is 1e6
  EXPECT_EQ(FormatQuantity(0.0, "kg"), "0 kg");
  EXPECT_EQ(FormatQuantity(1234, "1"), "1234");
  EXPECT_EQ(FormatQuantity(std::nan(""), "A"), "-");
}

TEST(Units, EveryModelParameterWithItsUnit) {
  for (const auto& preset : model::PresetNames()) {
    auto p = model::Preset(preset);
    ASSERT_TRUE(p.ok());
    for (const auto& info : model::ParamTable()) {
      EXPECT_FALSE(std::string(info.unit).empty()) << info.name;
      const double v = (*p).*(info.field);
      ExpectWrittenRight(v, std::string(info.unit), preset + "." + std::string(info.name));
      // And across the parameter's whole range.
      for (double x : {info.min, info.max, std::sqrt(std::abs(info.min * info.max))})
        ExpectWrittenRight(x, std::string(info.unit), std::string(info.name) + " (range)");
    }
  }
  for (const auto& effect : model::EffectCatalog())
    for (const auto& param : effect.params) {
      EXPECT_FALSE(std::string(param.unit).empty()) << effect.name << "." << param.name;
      for (double x : {param.min, param.max, 0.5 * (param.min + param.max)})
        ExpectWrittenRight(x, std::string(param.unit), std::string(effect.name) + "." + std::string(param.name));
    }
}

TEST(Units, EveryMetricWithItsUnit) {
  for (const char* law : {"pi_current", "cascade_pi_position", "open_loop_pwm"}) {
    for (const auto& [name, unused] : experiment::MetricList(experiment::Metrics{})) {
      const std::string unit = experiment::SiUnit(name, law);
      EXPECT_FALSE(unit.empty()) << name << " has no unit";
      for (double v : {9.533e-4, 0.02773, 3.5, 40000.0, 8.67476e-05})
        ExpectWrittenRight(v, unit, std::string(law) + " " + name);
      // The CSV header says the unit too, unless the name carries it or it has none.
      const std::string column = experiment::MetricColumnName(name, law);
      if (unit != "1") {
        EXPECT_NE(column.find('_'), std::string::npos) << name;
      }
    }
  }
  EXPECT_EQ(experiment::MetricColumnName("rmse", "pi_current"), "rmse_A");
  EXPECT_EQ(experiment::MetricColumnName("rmse", "sliding_mode_position"), "rmse_m");
  EXPECT_EQ(experiment::MetricColumnName("iae", "pi_current"), "iae_A_s");
  EXPECT_EQ(experiment::MetricColumnName("effort_l2", "pi_current"), "effort_l2_V_sqrt_s");
  EXPECT_EQ(experiment::MetricColumnName("mean_flow_kg_per_s", "open_loop_pwm"), "mean_flow_kg_per_s");
  EXPECT_EQ(experiment::MetricColumnName("switches", "pi_current"), "switches");
  EXPECT_EQ(experiment::SiUnit("mean_flow_kg_per_s", "open_loop_pwm"), "kg/s");
}

}  // namespace
}  // namespace vb
