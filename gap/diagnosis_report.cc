// The diagnosis for people (DiagnosisReport) and as the JSON contract (DiagnosisJson): docs/gap.md, "JSON".
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

#include "common/format.h"
#include "gap/text_wrap.h"
#include "gap/diagnose.h"

namespace vb::gap {

namespace {

nlohmann::ordered_json RowJson(const CandidateResult& r) {
  nlohmann::ordered_json row;
  row["effect"] = r.name;
  nlohmann::ordered_json params = nlohmann::ordered_json::object(), unc = nlohmann::ordered_json::object();
  for (const auto& [k, v] : r.params) params[k] = v;
  for (const auto& [k, v] : r.uncertainty) unc[k] = v;
  row["params"] = params;
  row["uncertainty"] = unc;
  row["fit_rmse_A"] = r.fit_rmse_A;
  row["holdout_rmse_before_A"] = r.holdout_rmse_before_A;
  row["holdout_rmse_after_A"] = r.holdout_rmse_after_A;
  row["closed"] = r.closed;
  row["signature_match"] = r.signature_match;
  row["score"] = std::isfinite(r.score) ? nlohmann::ordered_json(r.score) : nlohmann::ordered_json(nullptr);
  row["evaluations"] = r.evaluations;
  if (!r.status.ok()) row["error"] = r.status.message();
  if (!r.disqualified.empty()) row["disqualified"] = r.disqualified;
  return row;
}

nlohmann::ordered_json NumOrNull(double v) { return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(nullptr); }

}  // namespace

std::string DiagnosisJson(const Diagnosis& d) {
  nlohmann::ordered_json j;
  j["model"] = d.model;
  if (!d.device.empty()) j["device"] = d.device;
  j["noise_floor_A"] = d.noise_floor_A;
  j["measurement_noise_A"] = d.measurement_noise_A;
  j["form_floor_A"] = d.form_floor_A;
  if (d.has_reference) {
    nlohmann::ordered_json params = nlohmann::ordered_json::object();
    for (const auto& [k, v] : d.reference.params) params[k] = v;
    j["reference"] = {{"directory", d.reference.directory},
                      {"temperature_C", NumOrNull(d.reference.temperature_C)},
                      {"fit_rmse_A", d.reference.fit_rmse_A},
                      {"params", params}};
    j["reference"]["noise_floor_A"] = d.reference.noise_floor_A;
    j["reference"]["identified"] = d.reference.identified();
    if (d.reference.from_scratch) {
      j["reference"]["from_scratch"] = true;
      j["reference"]["notes"] = d.reference.notes;
    }
  }
  j["gap"] = {{"fit_rmse_A", d.fit_rmse_A}, {"holdout_rmse_A", d.holdout_rmse_A}, {"significant", d.significant}};
  nlohmann::ordered_json where = nlohmann::ordered_json::array();
  for (const auto& w : d.where)
    where.push_back({{"phase", std::string(PhaseName(w.phase))}, {"share", w.share}, {"rmse_A", w.rmse_A},
                     {"samples", w.samples}});
  j["where"] = where;
  nlohmann::ordered_json runs = nlohmann::ordered_json::array();
  for (const auto& r : d.runs) runs.push_back({{"id", r.id}, {"split", SplitName(r.split)}, {"rmse_A", r.rmse_A}});
  j["runs"] = runs;
  nlohmann::ordered_json lms = nlohmann::ordered_json::array();
  for (const auto& l : d.landmarks) {
    auto pair = [](const double v[2]) {
      return nlohmann::ordered_json{{"measured", NumOrNull(v[0])}, {"nominal", NumOrNull(v[1])}};
    };
    lms.push_back({{"run", l.run}, {"dip_time_s", pair(l.dip_t_s)}, {"dip_depth_A", pair(l.dip_depth_A)},
                   {"hold_current_A", pair(l.hold_current_A)}, {"decay_time_s", pair(l.decay_time_s)}});
  }
  j["landmarks"] = lms;
  nlohmann::ordered_json trends = nlohmann::ordered_json::object();
  for (const auto& [k, v] : d.trends) trends[k] = v;
  j["trends"] = trends;
  nlohmann::ordered_json ranking = nlohmann::ordered_json::array();
  for (const auto& r : d.ranking) ranking.push_back(RowJson(r));
  j["ranking"] = ranking;
  if (d.parametric >= 0) j["parametric"] = RowJson(d.ranking[static_cast<std::size_t>(d.parametric)]);
  j["verdict"] = d.verdict;
  j["verdict_kind"] = VerdictKindName(d.verdict_kind);
  j["verdict_reason"] = d.verdict_reason;
  if (d.verdict_kind == VerdictKind::kUndetermined) {
    j["smallest_visible_A"] = NumOrNull(d.smallest_visible_A);
    j["to_record"] = d.reference.to_record;
    if (!d.untrusted_name.empty()) j["untrusted_name"] = d.untrusted_name;
  }
  if (!d.nuisance.empty()) {
    nlohmann::ordered_json drift = nlohmann::ordered_json::array();
    for (const auto& n : d.nuisance)
      drift.push_back({{"param", n.param}, {"value", n.value}, {"nominal", n.nominal}, {"factor", n.value / n.nominal},
                       {"gap_A", n.gap_A}, {"effects_gap_A", n.effects_gap_A}});
    j["nuisance"] = drift;
    j["verdict_alone_holdout_rmse_A"] = d.verdict_alone_holdout_A;
  }
  if (!d.members.empty()) {
    nlohmann::ordered_json members = nlohmann::ordered_json::array();
    for (const auto& m : d.members)
      members.push_back({{"cause", m.name}, {"holdout_rmse_after_A", m.holdout_rmse_after_A}, {"closed", m.closed},
                         {"gap_A", m.gap_A}});
    j["members"] = members;
  }
  if (!d.additions.empty()) {  // the evidence for each addition the rule judged (docs/gap.md)
    nlohmann::ordered_json steps = nlohmann::ordered_json::array();
    for (const auto& a : d.additions)
      steps.push_back({{"from", a.from}, {"to", a.to}, {"holdout_rmse_before_A", a.before_A},
                       {"holdout_rmse_after_A", a.after_A}, {"effective_samples", a.effective_samples},
                       {"evidence", a.evidence}, {"params_before", a.params_before}, {"params_after", a.params_after},
                       {"parsimony_samples", a.parsimony_samples}, {"f_statistic", a.f_statistic},
                       {"p_value", a.p_value}, {"level", a.level}, {"parsimonious", a.parsimonious},
                       {"taken", a.taken}});
    j["additions"] = steps;
  }
  if (!d.form_error.empty()) j["form_error"] = d.form_error;
  nlohmann::ordered_json limits = nlohmann::ordered_json::array();
  for (const auto& l : d.detection_limits) {
    nlohmann::ordered_json params = nlohmann::ordered_json::object();
    for (const auto& [k, v] : l.params) params[k] = v;
    limits.push_back({{"effect", l.effect}, {"detectable", l.detectable}, {"below_range", l.below_range}, {"params", params},
                      {"residual_at_limit_A", l.residual_at_limit_A}});
  }
  j["detection_limits"] = limits;
  if (!d.ranking.empty()) {
    j["confusable"] = d.confusable;
    j["margin_A"] = d.margin_A;
    const CandidateResult& best = d.ranking.front();
    nlohmann::ordered_json phases = nlohmann::ordered_json::array();
    for (int p = 0; p < kPhaseCount; ++p) {
      if (d.phase_holdout_before_A[p] == 0.0) continue;
      phases.push_back({{"phase", std::string(PhaseName(static_cast<Phase>(p)))},
                        {"holdout_rmse_before_A", d.phase_holdout_before_A[p]},
                        {"holdout_rmse_after_A", best.phase_holdout_after_A[p]}});
    }
    j["how_far"] = {{"candidate", best.name}, {"holdout_rmse_before_A", best.holdout_rmse_before_A},
                    {"holdout_rmse_after_A", best.holdout_rmse_after_A}, {"closed", best.closed},
                    {"phases", phases}};
  }
  if (!d.split_note.empty()) j["split_note"] = d.split_note;
  if (!d.warnings.empty()) j["warnings"] = d.warnings;
  nlohmann::ordered_json ovs = nlohmann::ordered_json::array();
  for (const auto& o : d.overlays)
    ovs.push_back({{"run", o.run}, {"split", SplitName(o.split)}, {"t_s", o.t_s}, {"measured_A", o.measured_A},
                   {"nominal_A", o.nominal_A}, {"fitted_A", o.fitted_A}});
  j["overlays"] = ovs;
  return j.dump(2);
}

std::string DiagnosisReport(const Diagnosis& d) {
  std::ostringstream os;
  char buf[320];
  if (d.has_reference) {
    std::snprintf(buf, sizeof buf, "model %s%s%s; floor %.3f mA: the reference session's own fit error (measurement "
                  "noise %.3f mA)\n", d.model.c_str(), d.device.empty() ? "" : ", device ", d.device.c_str(),
                  d.noise_floor_A * 1e3, d.measurement_noise_A * 1e3);
    os << buf;
    os << "reference " << d.reference.directory;
    if (std::isfinite(d.reference.temperature_C)) os << " at " << FormatNumber(d.reference.temperature_C) << " C";
    os << (d.reference.from_scratch ? ", identified there from scratch:" : ", identified there:");
    for (const auto& [k, v] : d.reference.params) {
      std::snprintf(buf, sizeof buf, " %s=%.5g", k.c_str(), v);
      os << buf;
    }
    os << "\n";
    for (const auto& n : d.reference.notes) os << "  reference: " << n << "\n";
  } else {
    std::snprintf(buf, sizeof buf, "model %s%s%s; noise floor %.3f mA (from the data and the declared sense chain)\n",
                  d.model.c_str(), d.device.empty() ? "" : ", device ", d.device.c_str(), d.noise_floor_A * 1e3);
    os << buf;
  }
  const bool any_holdout =
      std::any_of(d.runs.begin(), d.runs.end(), [](const RunGap& r) { return r.split == Split::kHoldout; });
  char holdout[48] = "no holdout run";
  if (any_holdout) std::snprintf(holdout, sizeof holdout, "holdout %.2f mA RMS", d.holdout_rmse_A * 1e3);
  std::snprintf(buf, sizeof buf, "gap: fit runs %.2f mA RMS, %s: %s (threshold %.1fx the floor)\n",
                d.fit_rmse_A * 1e3, holdout, d.significant ? "SIGNIFICANT" : "not significant", kSignificance);
  os << buf;
  if (!d.split_note.empty()) os << d.split_note << "\n";
  if (d.form_floor_A > d.noise_floor_A) {
    std::snprintf(buf, sizeof buf, "model form floor %.3f mA: the model fits the fit runs as well as any candidate; closure is "
                  "measured above it\n", d.form_floor_A * 1e3);
    os << buf;
  }
  os << "where (share of residual energy, RMSE):\n";
  for (const auto& w : d.where) {
    std::snprintf(buf, sizeof buf, "  %-8s %5.1f %%  %7.2f mA  (%zu samples)\n", std::string(PhaseName(w.phase)).c_str(),
                  100.0 * w.share, w.rmse_A * 1e3, w.samples);
    os << buf;
  }
  if (!d.trends.empty()) {
    os << "trends (correlation of a run's residual RMS with):";
    for (const auto& [k, v] : d.trends) {
      std::snprintf(buf, sizeof buf, " %s %+.2f", k.c_str(), v);
      os << buf;
    }
    os << "\n";
  }
  if (!d.landmarks.empty()) {
    os << "landmarks, measured vs nominal (first gate-on of each run):\n";
    auto ms = [](double v) { return std::isfinite(v) ? v * 1e3 : NAN; };
    for (const auto& l : d.landmarks) {
      std::snprintf(buf, sizeof buf,
                    "  %-16s dip %6.2f/%6.2f ms depth %6.1f/%6.1f mA  hold %6.1f/%6.1f mA  decay %6.2f/%6.2f ms\n",
                    l.run.c_str(), ms(l.dip_t_s[0]), ms(l.dip_t_s[1]), ms(l.dip_depth_A[0]), ms(l.dip_depth_A[1]),
                    ms(l.hold_current_A[0]), ms(l.hold_current_A[1]), ms(l.decay_time_s[0]), ms(l.decay_time_s[1]));
      os << buf;
    }
  }
  if (!d.ranking.empty()) {
    os << "which (fitted on the fit runs, scored on the holdout runs):\n";
    // One row per candidate within 120 columns; its fitted values (and why it may not be the verdict) follow,
    // wrapped, on indented lines.
    os << "  rank  candidate                                     holdout before -> after [mA]  closed  signature\n";
    for (std::size_t k = 0; k < d.ranking.size(); ++k) {
      const auto& r = d.ranking[k];
      os << fmt::format("  {:>4}  {:<44}  {:>7.2f} -> {:>7.2f}       {:>4.0f} %  {:>9.2f}\n", k + 1, r.name,
                        r.holdout_rmse_before_A * 1e3, r.holdout_rmse_after_A * 1e3, 100.0 * r.closed,
                        r.signature_match);
      std::vector<std::string> words;
      if (!r.status.ok()) {
        words.push_back("failed: " + r.status.message());
      } else {
        for (const auto& [name, v] : r.params) {
          auto u = r.uncertainty.find(name);
          words.push_back(u != r.uncertainty.end() ? fmt::format("{}={:.4g}+-{:.2g}", name, v, u->second)
                                                   : fmt::format("{}={:.4g}", name, v));
        }
      }
      os << Wrap(words, 8);
      if (!r.disqualified.empty()) os << Wrap({"not the verdict: " + r.disqualified}, 8);
    }
    if (d.parametric >= 0) {
      const auto& p = d.ranking[static_cast<std::size_t>(d.parametric)];
      std::snprintf(buf, sizeof buf, "parameter-only re-fit: best %s closes %.0f %% (holdout %.2f mA)\n",
                    p.name.c_str(), 100.0 * p.closed, p.holdout_rmse_after_A * 1e3);
      os << buf;
    }
    const auto& best = d.ranking.front();
    os << "how far (" << best.name << ", holdout RMSE per phase, before -> after):\n";
    for (int p = 0; p < kPhaseCount; ++p) {
      if (d.phase_holdout_before_A[p] == 0.0) continue;
      std::snprintf(buf, sizeof buf, "  %-8s %7.2f -> %7.2f mA\n", std::string(PhaseName(static_cast<Phase>(p))).c_str(),
                    d.phase_holdout_before_A[p] * 1e3, best.phase_holdout_after_A[p] * 1e3);
      os << buf;
    }
    if (!d.confusable.empty()) {
      os << "confusable with the verdict (the data cannot separate them):";
      for (const auto& c : d.confusable) os << " " << c;
      os << "\n";
    }
  }
  if (!d.detection_limits.empty()) {
    os << "detection limits (the smallest of each effect these runs would show at " << kSignificance
       << "x the floor):\n";
    for (const auto& l : d.detection_limits) {
      std::string what;
      for (const auto& [k, v] : l.params) {
        const auto u = l.units.find(k);
        what += (what.empty() ? "" : ", ") + k + " " + fmt::format("{:.3g}", v) +
                (u != l.units.end() && !u->second.empty() && u->second != "1" ? " " + u->second : "");
      }
      os << "  " << l.effect << ": "
         << (!l.detectable    ? "not detectable even at " + what + " (the range's end)"
             : l.below_range ? "shown even at " + what + " (the range's weakest)"
                             : what)
         << "\n";
    }
  }
  os << Wrap({"verdict: " + d.verdict + (d.verdict_reason.empty() ? "" : " (" + d.verdict_reason + ")")}, 2, 120, 0);
  if (!d.members.empty()) {
    std::string each;
    for (const auto& m : d.members)
      each += fmt::format("{}{} {:.0f} % (holdout {:.2f} mA; its own gap {:.2f} mA)", each.empty() ? "" : ", ", m.name,
                          100.0 * m.closed, m.holdout_rmse_after_A * 1e3, m.gap_A * 1e3);
    os << Wrap({fmt::format("each cause on its own closes: {}; together {:.0f} % (holdout {:.2f} mA)", each,
                            100.0 * d.ranking.front().closed, d.ranking.front().holdout_rmse_after_A * 1e3)},
               2, 120, 0);
  }
  for (const auto& n : d.nuisance)
    os << Wrap({fmt::format("nuisance drift beside it: {} = {:.4g} ({:+.1f} % from nominal); the verdict alone leaves "
                            "{:.2f} mA on the holdout runs, with the drift {:.2f} mA (the drift's own gap {:.2f} mA, "
                            "the effects' {:.2f} mA)",
                            n.param, n.value, 100.0 * (n.value / n.nominal - 1.0), d.verdict_alone_holdout_A * 1e3,
                            d.ranking.front().holdout_rmse_after_A * 1e3, n.gap_A * 1e3, n.effects_gap_A * 1e3)},
               2, 120, 0);
  for (const auto& a : d.additions)
    os << Wrap({fmt::format("addition {} -> {}: holdout {:.2f} -> {:.2f} mA, {:.0f} independent samples, evidence {:.1f}; "
                            "parsimony {} -> {} parameters, F {:.2f} on {:.0f} independent samples, p {:.2g} "
                            "against {:.2g}: {}",
                            a.from, a.to, a.before_A * 1e3, a.after_A * 1e3, a.effective_samples, a.evidence,
                            a.params_before, a.params_after, a.f_statistic, a.parsimony_samples, a.p_value, a.level,
                            a.taken ? "taken" : a.parsimonious ? "not taken" : "not taken (not parsimonious)")},
               2, 120, 0);
  for (const auto& w : d.warnings) os << Wrap({"warning: " + w}, 2, 120, 0);
  return os.str();
}

}  // namespace vb::gap
