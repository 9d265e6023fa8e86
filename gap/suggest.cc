#include "gap/suggest.h"

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>

#include "gap/attribution.h"
#include "gap/predict.h"

namespace vb::gap {

namespace {


// The slowest thermal time constant among the contenders' fitted values (0 without coil heating): a run that
// rests five of them first starts from the cold coil the models start from.
double SlowestThermal_s(const Diagnosis& d, const std::vector<std::size_t>& rows) {
  double tau = 0.0;
  for (std::size_t k : rows) {
    const auto& p = d.ranking[k].params;
    auto rth = p.find("coil_heating.R_th"), cth = p.find("coil_heating.C_th");
    if (rth != p.end() && cth != p.end()) tau = std::max(tau, rth->second * cth->second);
  }
  return tau;
}

// The grid of runnable designs: the session's extreme supplies and pressures (nothing the valve has not seen),
// a step, and PWM at three carriers and three duties, each held briefly and long.
std::vector<Design> Grid(const Dataset& ds) {
  std::set<double> supplies, pressures;
  for (const auto& r : ds.runs) {
    supplies.insert(r.supply_V);
    pressures.insert(r.supply_pressure_Pa);
  }
  std::vector<double> vs = {*supplies.begin()}, ps = {*pressures.begin()};
  if (*supplies.rbegin() != *supplies.begin()) vs.push_back(*supplies.rbegin());
  if (*pressures.rbegin() != *pressures.begin()) ps.push_back(*pressures.rbegin());
  std::vector<std::pair<double, double>> gates = {{0.0, 1.0}};
  for (double f : {50.0, 200.0, 1000.0})
    for (double duty : {0.2, 0.5, 0.8}) gates.emplace_back(f, duty);
  std::vector<Design> out;
  for (double v : vs)
    for (double p : ps)
      for (const auto& [f, duty] : gates)
        for (double hold : {0.05, 0.3}) {
          Design d;
          d.supply_V = v;
          d.supply_pressure_Pa = p;
          d.pwm_Hz = f;
          d.duty = duty;
          d.hold_s = hold;
          out.push_back(d);
        }
  return out;
}

bool Similar(const Design& a, const Design& b) {
  return a.pwm_Hz == b.pwm_Hz && a.duty == b.duty && a.hold_s == b.hold_s;
}

}  // namespace

std::vector<std::int8_t> DesignGate(const Design& design, double dt) {
  const double total = design.rest_s + design.hold_s + design.tail_s;
  const auto n = static_cast<std::size_t>(std::llround(total / dt)) + 1;
  std::vector<std::int8_t> g(n, 0);
  for (std::size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * dt - design.rest_s;
    if (t < 0.0 || t >= design.hold_s) continue;
    if (design.pwm_Hz <= 0.0) {
      g[k] = 1;
    } else {
      // Gate high for the first `duty` of each period, as an open-loop PWM segment drives it.
      const double phase = t * design.pwm_Hz - std::floor(t * design.pwm_Hz + 1e-9);
      g[k] = phase < design.duty - 1e-9 ? 1 : 0;
    }
  }
  return g;
}

StatusOr<Suggestion> SuggestNextRuns(const Dataset& ds, const model::PlantParams& nominal, const Diagnosis& d,
                                     const SuggestOptions& options) {
  Suggestion s;
  if (d.has_reference) {
    // The contenders were fitted around the device as identified on the reference, which this call does not have.
    s.note = "no suggestion: not made against a reference session yet (diagnose without --reference to get one)";
    return s;
  }
  // The contenders: the verdict and what it is confusable with; with no verdict, the best rows that may be it.
  std::vector<std::size_t> rows;
  auto row_of = [&](const std::string& name) -> int {
    for (std::size_t k = 0; k < d.ranking.size(); ++k)
      if (d.ranking[k].name == name) return static_cast<int>(k);
    return -1;
  };
  if (d.chosen >= 0) {
    rows.push_back(static_cast<std::size_t>(d.chosen));
    for (const auto& c : d.confusable)
      if (int k = row_of(c); k >= 0 && rows.size() < static_cast<std::size_t>(options.max_contenders))
        rows.push_back(static_cast<std::size_t>(k));
  } else if (d.significant) {
    for (std::size_t k = 0; k < d.ranking.size() && rows.size() < static_cast<std::size_t>(options.max_contenders); ++k)
      if (d.ranking[k].status.ok() && d.ranking[k].disqualified.empty()) rows.push_back(k);
  }
  for (std::size_t k : rows) s.contenders.push_back(d.ranking[k].name);
  if (rows.size() < 2) {
    s.note = d.significant ? "nothing to separate: no candidate is confusable with the verdict"
                           : "nothing to separate: the gap is within the noise floor";
    return s;
  }
  double dt = 0.0;
  for (const auto& r : ds.runs)
    if (r.kind == RunKind::kWaveform && r.sample_period_s > 0.0) dt = r.sample_period_s;
  if (!(dt > 0.0)) {
    s.note = "no suggestion: the suggested runs are waveforms, and this session has none to take the sample rate from";
    return s;
  }
  s.sample_rate_Hz = std::round(1.0 / dt * 1e6) / 1e6;  // 50000, not 50000.00000000001
  // Each contender's fitted device.
  struct Fitted {
    model::PlantParams plant;
    model::DriverParams driver;
  };
  std::vector<Fitted> fitted;
  for (std::size_t k : rows) {
    const Candidate* c = nullptr;
    for (const auto& cand : d.candidates)
      if (cand.name == d.ranking[k].name) c = &cand;
    if (c == nullptr) return Status::Internal("suggest: no candidate behind " + d.ranking[k].name);
    auto plant = FittedPlant(nominal, *c, d.ranking[k]);
    if (!plant.ok()) return plant.status();
    auto driver = FittedDriver(ds.driver, *c, d.ranking[k]);
    if (!driver.ok()) return driver.status();
    fitted.push_back({*plant, *driver});
  }
  const double floor = std::max(d.noise_floor_A, 1e-12);
  const double rest_s = std::min(60.0, 5.0 * SlowestThermal_s(d, rows));
  // The same separation on the session's own runs, for comparison.
  {
    std::vector<std::vector<std::vector<double>>> preds;
    for (const auto& f : fitted) {
      PredictOptions popt;
      popt.driver = &f.driver;
      auto p = Predict(ds, f.plant, popt);
      if (!p.ok()) return p.status();
      preds.push_back(std::move(p->i_A));
    }
    double worst = INFINITY;
    for (std::size_t a = 0; a < preds.size(); ++a)
      for (std::size_t b = a + 1; b < preds.size(); ++b) {
        double e2 = 0.0;
        std::size_t n = 0;
        for (std::size_t r = 0; r < preds[a].size(); ++r)
          for (std::size_t k = 0; k < preds[a][r].size(); ++k) {
            const double e = preds[a][r][k] - preds[b][r][k];
            e2 += e * e;
            ++n;
          }
        worst = std::min(worst, n > 0 ? std::sqrt(e2 / static_cast<double>(n)) / floor : 0.0);
      }
    s.current_separation_sigma = std::isfinite(worst) ? worst : 0.0;
  }
  // Every design, simulated with every contender from rest.
  std::vector<SuggestedRun> scored;
  for (Design design : Grid(ds)) {
    Dataset one;
    one.format = ds.format;
    one.model = ds.model;
    one.sensor = ds.sensor;
    one.driver = ds.driver;
    RunData r;
    r.id = "design";
    r.supply_V = design.supply_V;
    r.supply_pressure_Pa = design.supply_pressure_Pa;
    r.t_start_s = 0.0;
    r.sample_period_s = dt;
    r.gate = DesignGate(design, dt);
    r.t_s.resize(r.gate.size());
    for (std::size_t k = 0; k < r.t_s.size(); ++k) r.t_s[k] = static_cast<double>(k) * dt;
    r.i_A.assign(r.gate.size(), 0.0);
    one.runs.push_back(std::move(r));
    std::vector<std::vector<double>> preds;
    bool ok = true;
    for (const auto& f : fitted) {
      PredictOptions popt;
      popt.driver = &f.driver;
      auto p = Predict(one, f.plant, popt);
      if (!p.ok()) {
        ok = false;
        break;
      }
      preds.push_back(std::move(p->i_A.front()));
    }
    if (!ok) continue;  // a design a contender cannot simulate is not suggested
    SuggestedRun run;
    run.design = design;
    run.separation_sigma = INFINITY;
    for (std::size_t a = 0; a < preds.size(); ++a)
      for (std::size_t b = a + 1; b < preds.size(); ++b) {
        double e2 = 0.0;
        for (std::size_t k = 0; k < preds[a].size(); ++k) e2 += (preds[a][k] - preds[b][k]) * (preds[a][k] - preds[b][k]);
        const double sep = std::sqrt(e2 / static_cast<double>(preds[a].size())) / floor;
        if (sep < run.separation_sigma) {
          run.separation_sigma = sep;
          run.closest_pair = s.contenders[a] + " / " + s.contenders[b];
        }
      }
    run.design.rest_s = rest_s;
    scored.push_back(run);
  }
  std::stable_sort(scored.begin(), scored.end(),
                   [](const SuggestedRun& a, const SuggestedRun& b) { return a.separation_sigma > b.separation_sigma; });
  for (const auto& run : scored) {
    if (s.runs.size() >= static_cast<std::size_t>(options.max_runs)) break;
    const bool dup = std::any_of(s.runs.begin(), s.runs.end(), [&](const SuggestedRun& x) { return Similar(x.design, run.design); });
    if (!dup) s.runs.push_back(run);
  }
  if (s.runs.empty()) {
    s.note = "no runnable design in the grid could be simulated with every contender";
  } else if (s.runs.front().separation_sigma < kSignificance) {
    s.note = fmt::format("even the best design separates the contenders by only {:.2g} noise sigma: more repeats of "
                         "it, or a measurement of position, are needed", s.runs.front().separation_sigma);
  } else {
    s.note = "run these on the same bench, add them to the session as holdout runs (they test each contender's prediction), and diagnose again";
  }
  return s;
}

std::string SuggestionSpecJson(const Suggestion& s, const std::string& name, const std::string& model_preset) {
  nlohmann::ordered_json spec;
  spec["name"] = name;
  std::string contenders;
  for (const auto& c : s.contenders) contenders += (contenders.empty() ? "" : ", ") + c;
  spec["description"] = "Suggested by benchctl diagnose --suggest to separate " + contenders +
                        ": each run rests with the gate off first, then a step or PWM, then a release tail";
  spec["tags"] = {"suggested", "diagnosis"};
  spec["bench"] = {{"kind", "emulated"}, {"model", {{"preset", model_preset}}}};
  spec["recording"] = {{"rate_Hz", s.sample_rate_Hz}};
  // Each variant sets its own conditions, controller and duration.
  nlohmann::ordered_json variants = nlohmann::ordered_json::array();
  double longest = 0.0;
  for (std::size_t k = 0; k < s.runs.size(); ++k) {
    const Design& d = s.runs[k].design;
    nlohmann::ordered_json segs = nlohmann::ordered_json::array();
    if (d.rest_s > 0.0) segs.push_back({{"start_s", 0.0}, {"frequency_Hz", 0.0}, {"duty", 0.0}});
    segs.push_back({{"start_s", d.rest_s}, {"frequency_Hz", d.pwm_Hz}, {"duty", d.pwm_Hz > 0.0 ? d.duty : 1.0}});
    segs.push_back({{"start_s", d.rest_s + d.hold_s}, {"frequency_Hz", 0.0}, {"duty", 0.0}});
    const std::string vname = d.pwm_Hz > 0.0 ? fmt::format("s{}_pwm{:g}_d{:g}_{:g}V_{:g}ms", k + 1, d.pwm_Hz, d.duty * 100,
                                                           d.supply_V, d.hold_s * 1e3)
                                             : fmt::format("s{}_step_{:g}V_{:g}ms", k + 1, d.supply_V, d.hold_s * 1e3);
    const double duration = d.rest_s + d.hold_s + d.tail_s;
    longest = std::max(longest, duration);
    variants.push_back({{"name", vname},
                        {"description", fmt::format("predicted to separate the contenders by {:.3g} noise sigma "
                                                    "(closest: {})", s.runs[k].separation_sigma, s.runs[k].closest_pair)},
                        {"conditions", {{"supply_V", d.supply_V}, {"supply_pressure_Pa", d.supply_pressure_Pa}}},
                        {"controller", {{"open_loop_pwm", {{"segments", segs}}}}},
                        {"duration_s", duration}});
  }
  spec["duration_s"] = longest;
  spec["variants"] = variants;
  return spec.dump(2) + "\n";
}

std::string SuggestionJson(const Suggestion& s) {
  nlohmann::ordered_json j;
  j["contenders"] = s.contenders;
  j["current_separation_sigma"] = s.current_separation_sigma;
  nlohmann::ordered_json runs = nlohmann::ordered_json::array();
  for (const auto& r : s.runs)
    runs.push_back({{"supply_V", r.design.supply_V}, {"supply_pressure_Pa", r.design.supply_pressure_Pa},
                    {"pwm_Hz", r.design.pwm_Hz}, {"duty", r.design.duty}, {"hold_s", r.design.hold_s},
                    {"tail_s", r.design.tail_s}, {"rest_s", r.design.rest_s},
                    {"separation_sigma", r.separation_sigma}, {"closest_pair", r.closest_pair}});
  j["runs"] = runs;
  j["note"] = s.note;
  return j.dump();
}

std::string SuggestionReport(const Suggestion& s) {
  std::ostringstream os;
  os << "next experiment";
  if (!s.contenders.empty()) {
    os << " (to separate";
    for (const auto& c : s.contenders) os << " " << c;
    os << fmt::format("; the session's own runs separate them by {:.2g} sigma)", s.current_separation_sigma);
  }
  os << ":\n";
  for (std::size_t k = 0; k < s.runs.size(); ++k) {
    const Design& d = s.runs[k].design;
    os << fmt::format("  {}. {:>5.1f} V {:>6.2f} bar  {:<18} hold {:>4.0f} ms, tail {:>3.0f} ms{}  -> {:.1f} sigma "
                      "(closest: {})\n",
                      k + 1, d.supply_V, d.supply_pressure_Pa * 1e-5,
                      d.pwm_Hz > 0.0 ? fmt::format("PWM {:g} Hz, D {:.0f} %", d.pwm_Hz, d.duty * 100) : std::string("step"),
                      d.hold_s * 1e3, d.tail_s * 1e3, d.rest_s > 0.0 ? fmt::format(", after {:.1f} s of rest", d.rest_s) : "",
                      s.runs[k].separation_sigma, s.runs[k].closest_pair);
  }
  if (!s.note.empty()) os << "  " << s.note << "\n";
  return os.str();
}

}  // namespace vb::gap
