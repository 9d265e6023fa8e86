// Devices that are not presets, measured as benches record them (docs/real-data.md): periodic steady-state
// readings of a coil with a held plunger, through a shunt, an amplifier and an ADC with an offset.
//
// Synthetic devices come from the model itself with a seeded noise and the ADC's rounding, with values far from
// any preset; the real SSBH-0830 readings (../shared/realdata/akita11) are checked against what a direct fit
// of them gives (R 31-34 ohm, L rising with stroke, a ~20 mA offset, R up 3-15 % from the coldest to the
// hottest session).
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>

#include <unistd.h>

#include "../common/run_command.h"
#include "gap/dataset.h"
#include "gap/diagnose.h"
#include "gap/identify.h"
#include "gap/predict.h"
#include "gap/readings_csv.h"
#include "model/params.h"

namespace vb::gap {
namespace {

namespace fs = std::filesystem;

// A coil nobody has a preset for, and the bench it is measured on.
// Its time constant (1.7 ms) is short against the PWM periods, so low duties conduct discontinuously: the
// readings then pin the offset and the diode drop as they do on the real coil.
struct Device {
  double R_ohm = 60.0;          // ts98_coil's R is 28.5: 2.1x away
  double L_H = 0.1;             // ts98_coil's L is 0.33: 3.3x away
  double offset_A = 0.011;
  double diode_V = 0.45;
  double supply_V = 12.0;
  double temp_C = 25.0;
  double alpha_per_K = 0.0;     // R(T) = R (1 + alpha (T - 25))
  double gain = 1.0;            // of the sense chain
};

// The akita11 settings: 100 Hz with on-times 1..9 ms, 200 Hz with 0.5..4.5 ms; readings 100 us and 700/400 us
// after the rising edge.
Dataset Session(const Device& dev, unsigned seed, double noise_A = 1e-4) {
  Dataset ds;
  ds.format = std::string(kFormatValveRuns2);
  ds.model = "ts98_coil";
  ds.device = "synthetic";
  ds.sensor.shunt_ohm = 0.1;
  ds.sensor.shunt_in_switch_path = true;
  ds.sensor.amplifier_gain = 20.0;
  ds.sensor.adc_lsb_A = 1e-3 / (0.1 * 20.0);
  ds.driver.diode_drop_V = dev.diode_V;
  for (double f : {100.0, 200.0}) {
    for (int k = 1; k <= 9; ++k) {
      RunData r;
      r.kind = RunKind::kPeriodic;
      r.pwm_Hz = f;
      r.on_time_s = (f == 100.0 ? 1e-3 : 0.5e-3) * k;
      r.id = std::to_string(static_cast<int>(f)) + "Hz_" + std::to_string(k);
      r.supply_V = dev.supply_V;
      r.ambient_C = dev.temp_C;
      r.stroke_m = 1e-3;
      r.t_s = {1e-4, f == 100.0 ? 7e-4 : 4e-4};
      r.i_A = {0.0, 0.0};
      r.i_sd_A = {noise_A, noise_A};
      r.repeats = {10, 10};
      ds.runs.push_back(r);
    }
  }
  // The truth: the device's own plant, its sense chain; then noise and the ADC's rounding.
  auto plant = *model::Preset("ts98_coil");
  plant.R_ohm = dev.R_ohm * (1.0 + dev.alpha_per_K * (dev.temp_C - 25.0));
  plant.L_H = dev.L_H;
  plant.effects.sensor_offset_A = dev.offset_A;
  plant.effects.sensor_gain = dev.gain;
  auto pred = Predict(ds, plant, PredictOptions{});
  EXPECT_TRUE(pred.ok()) << pred.status().message();
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, noise_A);
  for (std::size_t r = 0; r < ds.runs.size(); ++r)
    for (std::size_t k = 0; k < ds.runs[r].i_A.size(); ++k)
      ds.runs[r].i_A[k] = std::round((pred->i_A[r][k] + noise(rng)) / ds.sensor.adc_lsb_A) * ds.sensor.adc_lsb_A;
  return ds;
}

// The periodic steady state of an RL coil behind a low-side switch with a freewheel diode, in closed form:
// on: i -> V/Ron with tau L/Ron; off: i -> -Vd/R with tau L/R, clamped at 0 (the diode blocks).
double ClosedFormReading(double R, double Rs, double L, double V, double Vd, double f, double ton, double t) {
  const double T = 1.0 / f, Ron = R + Rs, a = V / Ron, b = Vd / R;
  const double e1 = std::exp(-ton * Ron / L), e2 = std::exp(-(T - ton) * R / L);
  // Continuous conduction: i0 = (-b + (a (1 - e1) + b) e2) / (1 - e1 e2); discontinuous: i0 = 0.
  double i0 = (-b + (a * (1.0 - e1) + b) * e2) / (1.0 - e1 * e2);
  if (i0 < 0.0) i0 = 0.0;
  return a + (i0 - a) * std::exp(-t * Ron / L);
}

TEST(PeriodicPrediction, MatchesTheClosedFormSteadyStateInBothConductionModes) {
  Device dev;
  Dataset ds = Session(dev, 1, 0.0);
  auto plant = *model::Preset("ts98_coil");
  plant.R_ohm = dev.R_ohm;
  plant.L_H = dev.L_H;
  auto pred = Predict(ds, plant, PredictOptions{});
  ASSERT_TRUE(pred.ok()) << pred.status().message();
  bool saw_discontinuous = false, saw_continuous = false;
  for (std::size_t r = 0; r < ds.runs.size(); ++r) {
    const RunData& run = ds.runs[r];
    for (std::size_t k = 0; k < run.t_s.size(); ++k) {
      const double want = ClosedFormReading(dev.R_ohm, 0.1, dev.L_H, dev.supply_V, dev.diode_V, run.pwm_Hz,
                                            run.on_time_s, run.t_s[k]);
      EXPECT_NEAR(pred->i_A[r][k], want, 1e-8) << run.id << " reading " << k;
    }
    const double i0 = ClosedFormReading(dev.R_ohm, 0.1, dev.L_H, dev.supply_V, dev.diode_V, run.pwm_Hz,
                                        run.on_time_s, 0.0);
    (i0 > 0.0 ? saw_continuous : saw_discontinuous) = true;
  }
  EXPECT_TRUE(saw_continuous);
  EXPECT_TRUE(saw_discontinuous);
}

TEST(PeriodicPrediction, TheSenseChainOffsetAndGainActOnTheReadings) {
  Device dev;
  Dataset ds = Session(dev, 1, 0.0);
  auto plant = *model::Preset("ts98_coil");
  plant.R_ohm = dev.R_ohm;
  plant.L_H = dev.L_H;
  auto plain = Predict(ds, plant, PredictOptions{});
  plant.effects.sensor_offset_A = 0.02;
  plant.effects.sensor_gain = 0.9;
  ds.sensor.offset_A = 0.005;  // a declared offset adds to the model's
  auto chained = Predict(ds, plant, PredictOptions{});
  ASSERT_TRUE(plain.ok() && chained.ok());
  for (std::size_t r = 0; r < ds.runs.size(); ++r)
    for (std::size_t k = 0; k < ds.runs[r].i_A.size(); ++k)
      EXPECT_NEAR(chained->i_A[r][k], 0.9 * plain->i_A[r][k] + 0.025, 1e-12);
}

TEST(HeldPlunger, InductanceTableInterpolatesAndAStrokeOutsideItIsNamed) {
  auto p = *model::Preset("ts98_coil");
  p.inductance_stroke_m = {0.0, 2e-3, 4e-3};
  p.inductance_L_H = {0.1, 0.2, 0.4};
  ASSERT_TRUE(model::Validate(p).ok());
  auto held = model::AtState(p, {3e-3, NAN});
  ASSERT_TRUE(held.ok());
  EXPECT_NEAR(held->L_H, 0.3, 1e-12);
  EXPECT_FALSE(held->has_moving_part);
  auto out = model::AtState(p, {5e-3, NAN});
  ASSERT_FALSE(out.ok());
  EXPECT_NE(out.status().message().find("stroke_m: 0.005 m is outside the model's inductance table"), std::string::npos)
      << out.status().message();
  p.inductance_L_H = {0.1, 0.2};
  EXPECT_NE(model::Validate(p).message().find("inductance_table"), std::string::npos);
}

TEST(HeldPlunger, TheValveLawGivesLAtTheStrokeAndTheTemperatureScalesR) {
  auto valve = *model::Preset("taghizadeh2009");
  const double x = 0.2e-3;
  auto held = model::AtState(valve, {x, NAN});
  ASSERT_TRUE(held.ok());
  EXPECT_NEAR(held->L_H, model::Plant(valve).L_H(x), 1e-15);
  EXPECT_EQ(held->law, model::InductanceLaw::kConstant);
  ASSERT_TRUE(model::AddEffect(&valve.effects, "resistance_temperature", {{"alpha", 4e-3}, {"T_ref", 20.0}}).ok());
  auto hot = model::AtState(valve, {NAN, 45.0});
  ASSERT_TRUE(hot.ok());
  EXPECT_NEAR(hot->R_ohm, valve.R_ohm * 1.1, 1e-12);
}

TEST(Identify, FindsACoilThreeTimesAwayFromThePresetInOneCall) {
  Device dev;
  const Dataset ds = Session(dev, 7);
  IdentifyOptions o;
  for (const char* spec : {"R=1:1000", "L=0.0001:10", "sensor_offset.offset_A=-0.2:0.2", "driver.diode_drop_V=0:1.5"})
    o.params.push_back(*ParseParamSpec(spec, "--params"));
  auto id = Identify(ds, *model::Preset("ts98_coil"), o);
  ASSERT_TRUE(id.ok()) << id.status().message();
  EXPECT_NEAR(id->fit.params.at("R"), dev.R_ohm, 0.01 * dev.R_ohm);
  EXPECT_NEAR(id->fit.params.at("L"), dev.L_H, 0.02 * dev.L_H);
  EXPECT_NEAR(id->fit.params.at("sensor_offset.offset_A"), dev.offset_A, 1e-3);
  EXPECT_NEAR(id->fit.params.at("driver.diode_drop_V"), dev.diode_V, 0.1);
  for (const auto& v : id->identifiability) {
    EXPECT_TRUE(v.determined) << v.name;
    EXPECT_FALSE(v.at_bound) << v.name;
  }
}

TEST(Identify, SaysWhatTheDataCannotDetermine) {
  // A slow coil (L/R = 9 ms) conducts continuously at every setting: its early readings are two numbers per
  // setting that R, the offset and the diode drop can trade along one valley.
  Device dev;
  dev.R_ohm = 12.0;
  dev.L_H = 0.11;
  const Dataset ds = Session(dev, 3);
  IdentifyOptions o;
  for (const char* spec : {"R=1:1000", "L=0.0001:10", "sensor_offset.offset_A=-0.2:0.2", "driver.diode_drop_V=0:1.5"})
    o.params.push_back(*ParseParamSpec(spec, "--params"));
  auto id = Identify(ds, *model::Preset("ts98_coil"), o);
  ASSERT_TRUE(id.ok()) << id.status().message();
  bool flagged = false;
  for (const auto& v : id->identifiability) flagged = flagged || !v.determined || !v.correlated.empty() || v.at_bound;
  EXPECT_TRUE(flagged) << IdentificationReport(*id);
  const std::string json = IdentificationJson(*id);
  EXPECT_NE(json.find("\"determined\""), std::string::npos);
}

TEST(Identify, ParamSpecErrorsNameTheFlag) {
  EXPECT_EQ(ParseParamSpec("R=5:1", "--params").status().message(),
            "--params: 'R=5:1': the upper bound must exceed the lower one");
  EXPECT_EQ(ParseParamSpec("R=a:1", "--params").status().message(),
            "--params: 'R=a:1': bounds are NAME=LOWER:UPPER with finite numbers");
  EXPECT_EQ(ParseFixed("R", "--fix").status().message(), "--fix: 'R': expected NAME=VALUE with a finite number");
  auto s = ParseParamSpec("L=0.01:2@0.3", "--params");
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->name, "L");
  EXPECT_EQ(s->initial, 0.3);
}

IdentifyOptions ReferenceFit() {
  IdentifyOptions o;
  for (const char* spec : {"R=1:1000", "L=0.0001:10", "sensor_offset.offset_A=-0.2:0.2", "driver.diode_drop_V=0:1.5"})
    o.params.push_back(*ParseParamSpec(spec, "--params"));
  return o;
}

TEST(DiagnoseAgainstAReference, AWarmerWindingIsAResistanceChange) {
  Device cold, hot;
  hot.temp_C = 40.0;
  cold.alpha_per_K = hot.alpha_per_K = 0.0045;  // a little above copper
  const Dataset ref = Session(cold, 11), session = Session(hot, 12);
  DiagnoseOptions opt;
  opt.reference = &ref;
  opt.reference_fit = ReferenceFit();
  auto d = Diagnose(session, *model::Preset("ts98_coil"), opt);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_TRUE(d->verdict == "param:R" || d->verdict == "resistance_temperature") << DiagnosisReport(*d);
  EXPECT_GE(d->ranking.front().closed, 0.8);
  EXPECT_GT(d->noise_floor_A, 0.0);
  for (const auto& row : d->ranking) {
    if (row.name == "resistance_temperature") {
      EXPECT_NEAR(row.params.at("resistance_temperature.alpha"), 0.0045, 0.0008);
    }
  }
}

TEST(DiagnoseAgainstAReference, AShiftedSenseOffsetIsNamedAsSuch) {
  Device before, after;
  after.offset_A = before.offset_A + 0.006;
  const Dataset ref = Session(before, 21), session = Session(after, 22);
  DiagnoseOptions opt;
  opt.reference = &ref;
  opt.reference_fit = ReferenceFit();
  auto d = Diagnose(session, *model::Preset("ts98_coil"), opt);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_EQ(d->verdict, "sensor_offset") << DiagnosisReport(*d);
}

TEST(DiagnoseAgainstAReference, TheSameDeviceTwiceIsNone) {
  Device dev;
  const Dataset ref = Session(dev, 31), session = Session(dev, 32);
  DiagnoseOptions opt;
  opt.reference = &ref;
  opt.reference_fit = ReferenceFit();
  auto d = Diagnose(session, *model::Preset("ts98_coil"), opt);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_EQ(d->verdict, "none") << DiagnosisReport(*d);
}

TEST(DiagnoseOneDataset, FitColdHoldOutHotCarriesRWithCoppersCoefficient) {
  // One dataset: the cold session's runs to fit, the hot session's held out, the model identified on the cold
  // ones. Only a temperature law can say anything about runs at a temperature it was never fitted at.
  Device cold, hot;
  cold.alpha_per_K = hot.alpha_per_K = 3.93e-3;
  hot.temp_C = 45.0;
  Dataset ds = Session(cold, 41), hot_runs = Session(hot, 42);
  for (auto& r : ds.runs) r.split = Split::kFit;
  for (auto r : hot_runs.runs) {
    r.id = "hot_" + r.id;
    r.split = Split::kHoldout;
    ds.runs.push_back(r);
  }
  auto plant = *model::Preset("ts98_coil");
  plant.R_ohm = cold.R_ohm;
  plant.L_H = cold.L_H;
  plant.effects.sensor_offset_A = cold.offset_A;
  ds.driver.diode_drop_V = cold.diode_V;
  auto d = Diagnose(ds, plant);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_EQ(d->verdict, "resistance_temperature") << DiagnosisReport(*d);
  EXPECT_GE(d->ranking.front().closed, 0.9);
}

TEST(DetectionLimits, SayTheSmallestEffectTheseRunsWouldShow) {
  // The same device at another temperature, with nothing changed: "none", with limits. A resistance that
  // follows the temperature faster than the limit is then found; one well below it is not.
  Device dev, warm_same = dev;
  warm_same.temp_C = dev.temp_C + 15.0;  // 15 K warmer, and a resistance that does not follow it
  const Dataset ref = Session(dev, 51), same = Session(warm_same, 52);
  DiagnoseOptions opt;
  opt.reference = &ref;
  opt.reference_fit = ReferenceFit();
  auto d = Diagnose(same, *model::Preset("ts98_coil"), opt);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_EQ(d->verdict, "none");
  double alpha_limit = NAN;
  for (const auto& l : d->detection_limits)
    if (l.effect == "resistance_temperature") {
      EXPECT_TRUE(l.detectable);
      alpha_limit = l.params.at("resistance_temperature.alpha");
    }
  ASSERT_TRUE(std::isfinite(alpha_limit)) << DiagnosisReport(*d);
  // Below and above the limit, 15 K warmer.
  for (const double factor : {0.3, 3.0}) {
    Device hot = dev;
    hot.temp_C = dev.temp_C + 15.0;
    hot.alpha_per_K = factor * alpha_limit;
    const Dataset warm = Session(hot, 53);
    auto dw = Diagnose(warm, *model::Preset("ts98_coil"), opt);
    ASSERT_TRUE(dw.ok());
    if (factor < 1.0) {
      EXPECT_EQ(dw->verdict, "none") << factor << "\n" << DiagnosisReport(*dw);
    } else {
      EXPECT_TRUE(dw->verdict == "param:R" || dw->verdict == "resistance_temperature") << DiagnosisReport(*dw);
    }
  }
}

TEST(DiagnoseCandidates, NothingMechanicalWhereNothingMovesAndNoSampledLagOnReadings) {
  Device dev;
  const Dataset ds = Session(dev, 5);
  const auto cands = DefaultCandidates(*model::Preset("ts98_coil"), ds, {});
  std::vector<std::string> names;
  for (const auto& c : cands) names.push_back(c.name);
  for (const char* absent : {"coulomb_friction", "end_stop_bounce", "sensor_lag", "param:k", "param:m", "param:mu_r"})
    EXPECT_EQ(std::count(names.begin(), names.end(), absent), 0) << absent;
  for (const char* present : {"param:R", "param:L", "sensor_offset", "sensor_gain", "supply_resistance"})
    EXPECT_EQ(std::count(names.begin(), names.end(), present), 1) << present;
}

// ---- the real SSBH-0830 readings --------------------------------------------------------------------------

const fs::path kAkita = fs::path(VB_SHARED_DIR) / "realdata" / "akita11" / "ssbh0830.csv";

TEST(RealData, Ssbh0830FromScratchAndHotAgainstCold) {
  if (!fs::exists(kAkita)) GTEST_SKIP() << kAkita << " not present";
  const fs::path out = fs::temp_directory_path() / ("vb_akita_" + std::to_string(::getpid()));
  auto sessions = ConvertReadingsCsv(kAkita.string(), out.string());
  ASSERT_TRUE(sessions.ok()) << sessions.status().message();
  EXPECT_EQ(sessions->size(), 48u);
  auto dir = [&](double stroke_mm, double temp_C) {
    for (const auto& s : *sessions)
      if (std::abs(s.stroke_m - stroke_mm * 1e-3) < 1e-9 && s.temp_C == temp_C) return s.directory;
    return std::string();
  };
  double last_L = 0.0;
  for (double stroke : {0.0, 2.5, 5.5}) {
    auto cold = LoadDataset(dir(stroke, 26.0), model::PresetNames());
    auto hot = LoadDataset(dir(stroke, 40.0), model::PresetNames());
    ASSERT_TRUE(cold.ok() && hot.ok());
    auto id_cold = Identify(*cold, *model::Preset("ts98_coil"), ReferenceFit());
    auto id_hot = Identify(*hot, *model::Preset("ts98_coil"), ReferenceFit());
    ASSERT_TRUE(id_cold.ok() && id_hot.ok());
    const double R = id_cold->fit.params.at("R"), L = id_cold->fit.params.at("L");
    const double offset = id_cold->fit.params.at("sensor_offset.offset_A");
    EXPECT_GT(R, 0.9 * 31.0) << stroke;  // within 10 % of a direct fit's 31-34 ohm
    EXPECT_LT(R, 1.1 * 34.0) << stroke;
    EXPECT_GT(L, last_L) << "L rises with stroke";
    last_L = L;
    EXPECT_NEAR(offset, 0.019, 0.004) << stroke;
    const double ratio = id_hot->fit.params.at("R") / R;
    EXPECT_GT(ratio, 1.03) << stroke;
    EXPECT_LT(ratio, 1.15) << stroke;
    DiagnoseOptions opt;
    opt.reference = &cold.value();
    opt.reference_fit = ReferenceFit();
    auto d = Diagnose(*hot, *model::Preset("ts98_coil"), opt);
    ASSERT_TRUE(d.ok()) << d.status().message();
    EXPECT_TRUE(d->verdict == "param:R" || d->verdict == "resistance_temperature")
        << stroke << "\n" << DiagnosisReport(*d);
    EXPECT_GE(d->ranking.front().closed, 0.8) << stroke;
  }
  fs::remove_all(out);
}

// ---- the readings importer --------------------------------------------------------------------------------

TEST(ReadingsCsv, ErrorsNameTheLineAndTheColumn) {
  const fs::path dir = fs::temp_directory_path() / ("vb_readings_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string header =
      "device,supply_V,amp_feedback_ohm,temp_C,stroke_mm,pwm_Hz,on_time_s,sample,t_after_edge_s,v_mV_mean,v_mV_sd,repeats\n";
  auto convert = [&](const std::string& body) {
    std::ofstream(dir / "r.csv") << body;
    return ConvertReadingsCsv((dir / "r.csv").string(), (dir / "out").string());
  };
  EXPECT_EQ(convert("device,supply_V\nX,5\n").status().message(),
            "r.csv:1: missing column amp_feedback_ohm (header 'device,supply_V')");
  EXPECT_EQ(convert(header + "X,5,19400,26,0,100,0.001,v0,0.0001,abc,0,10\n").status().message(),
            "r.csv:2: column v_mV_mean: 'abc' is not a finite number");
  EXPECT_EQ(convert(header + "X,5,19400,26,0,100,0.02,v0,0.0001,91,0,10\n").status().message(),
            "r.csv:2: column on_time_s: 0.02 s is outside (0, period]");
  EXPECT_EQ(convert(header + "X,5,19400,26,0,100,0.001,v0,0.0001,91,0,2.5\n").status().message(),
            "r.csv:2: column repeats: 2.5 is not a whole number >= 1");
  // Found by fuzz/readings_csv_fuzz.cc: a device name that is not UTF-8 made nlohmann::json::dump throw
  // (std::terminate: `benchctl convert` aborted).
  EXPECT_EQ(convert(header + "X\xC0,5,19400,26,0,100,0.001,v0,0.0001,91,0,10\n").status().message(),
            "r.csv:2: column device: not valid UTF-8");
  // Found by the same target's round trip: 583 mV through a 0.2 ohm shunt at gain 1 is 2915 A, which the
  // converter wrote and LoadDataset then refused (|i_A| <= 1000 A).
  EXPECT_EQ(convert(header + "X,5,0,26,0,100,0.001,v0,0.0001,583000,0,10\n").status().message(),
            "r.csv:2: column v_mV_mean: 583000 mV is 2915 A through the shunt and amplifier, outside [-1000, 1000] A");
  // Found by the fuzzing helper: two devices whose names differ only in characters a directory cannot carry
  // wrote one session over the other.
  EXPECT_EQ(convert(header + "a b,5,19400,26,0,100,0.001,v0,0.0001,91,0,10\na_b,5,19400,26,0,100,0.001,v0,0.0001,91,0,10\n")
                .status()
                .message(),
            "r.csv: column device: 'a b' and 'a_b' both become the directory a_b_s0mm_26C (characters other than "
            "letters, digits, - and _ become _): rename one");
  // One device at two supplies: two sessions, two directories.
  auto two = convert(header + "X,5,19400,26,0,100,0.001,v0,0.0001,91,0,10\nX,12,19400,26,0,100,0.001,v0,0.0001,91,0,10\n");
  ASSERT_TRUE(two.ok()) << two.status().message();
  ASSERT_EQ(two->size(), 2u);
  EXPECT_NE(two->at(0).directory, two->at(1).directory);
  auto ok = convert(header + "X,5,19400,26,0,100,0.001,v0,0.0001,91,0,10\nX,5,19400,26,0,100,0.001,v1,0.0007,205.8,0.4216,10\n");
  ASSERT_TRUE(ok.ok()) << ok.status().message();
  ASSERT_EQ(ok->size(), 1u);
  auto ds = LoadDataset(ok->front().directory, model::PresetNames());
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  ASSERT_EQ(ds->runs.size(), 1u);
  EXPECT_EQ(ds->runs[0].kind, RunKind::kPeriodic);
  EXPECT_NEAR(ds->runs[0].i_A[1], 0.2058 / (0.2 * 20.4), 1e-12);  // mV -> A through shunt and gain
  EXPECT_NEAR(ds->sensor.adc_lsb_A, 1e-3 / (0.2 * 20.4), 1e-15);
  fs::remove_all(dir);
}

// ---- the workflow script on a solenoid it has never seen ----------------------------------------------------

// Writes a readings CSV of the akita11 layout for a synthetic solenoid at three strokes and two temperatures.
void WriteReadingsCsv(const fs::path& path) {
  std::ofstream o(path);
  o << "device,supply_V,amp_feedback_ohm,temp_C,stroke_mm,pwm_Hz,on_time_s,sample,t_after_edge_s,v_mV_mean,v_mV_sd,"
       "repeats\n";
  const double gain = 1.0 + 9000.0 / 1000.0, shunt = 0.2;
  unsigned seed = 100;
  for (double stroke_mm : {0.0, 1.0, 2.0})
    for (double temp_C : {20.0, 45.0}) {
      Device dev;
      dev.R_ohm = 45.0;
      dev.L_H = 0.05 + 0.03 * stroke_mm;
      dev.offset_A = -0.008;
      dev.diode_V = 0.6;
      dev.supply_V = 9.0;
      dev.temp_C = temp_C;
      dev.alpha_per_K = 0.004;
      Dataset ds = Session(dev, ++seed);
      for (const auto& r : ds.runs)
        for (std::size_t k = 0; k < r.t_s.size(); ++k)
          o << "COIL-7," << dev.supply_V << ",9000," << temp_C << "," << stroke_mm << "," << r.pwm_Hz << ","
            << r.on_time_s << ",v" << k << "," << r.t_s[k] << "," << std::round(r.i_A[k] * 1e3 * shunt * gain * 10) / 10
            << ",0.3,10\n";
    }
}

TEST(RealDataWorkflow, RunShOnAnotherSolenoidWritesTheSummary) {
  const fs::path dir = fs::temp_directory_path() / ("vb_workflow_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  WriteReadingsCsv(dir / "coil7.csv");
  const std::string script = std::string(VB_SOURCE_DIR) + "/examples/realdata/akita11/run.sh";
  auto r = testing::RunCommand("BENCHCTL=" + std::string(VB_BENCHCTL) + " bash " + script + " " +
                               (dir / "coil7.csv").string() + " " + (dir / "out").string());
  ASSERT_EQ(r.exit_code, 0) << r.out;
  std::ifstream in(dir / "out" / "summary.json");
  const auto j = nlohmann::json::parse(in);
  EXPECT_EQ(j["device"], "COIL-7");
  ASSERT_EQ(j["strokes"].size(), 3u);
  double last_L = 0.0;
  for (const auto& s : j["strokes"]) {
    const double cold = s["R_cold_ohm"], hot = s["R_hot_ohm"], L = s["L_cold_H"], stroke = s["stroke_mm"];
    EXPECT_NEAR(cold, 45.0 * (1 + 0.004 * (20 - 25)), 0.02 * 45.0) << stroke;
    EXPECT_NEAR(hot / cold, (1 + 0.004 * 20) / (1 + 0.004 * -5), 0.02) << stroke;
    EXPECT_NEAR(L, 0.05 + 0.03 * stroke, 0.05 * L) << stroke;
    EXPECT_GT(L, last_L);
    last_L = L;
    EXPECT_NEAR(static_cast<double>(s["offset_A"]), -0.008, 0.0015) << stroke;
    const std::string verdict = s["verdict"];
    EXPECT_TRUE(verdict == "param:R" || verdict == "resistance_temperature") << verdict;
    EXPECT_GE(static_cast<double>(s["closed"]), 0.8);
  }
  EXPECT_LT(static_cast<double>(j["seconds"]), 60.0);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace vb::gap
