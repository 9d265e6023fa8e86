#include "gap/identify.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <set>
#include <sstream>

#include "common/format.h"
#include "gap/diagnose.h"

namespace vb::gap {

namespace {

bool ParseNumber(std::string_view s, double* v) {
  auto [ptr, ec] = std::from_chars(s.data(), s.data() + s.size(), *v);
  return !s.empty() && ec == std::errc() && ptr == s.data() + s.size() && std::isfinite(*v);
}

// The effect a parameter name belongs to ("sensor_offset.offset_A" -> "sensor_offset"); "" for nominal and
// driver parameters.
std::string EffectOf(const std::string& name) {
  if (name.rfind("driver.", 0) == 0) return "";
  const auto dot = name.find('.');
  return dot == std::string::npos ? "" : name.substr(0, dot);
}

const model::EffectParamInfo* EffectParam(const std::string& name) {
  const std::string effect = EffectOf(name);
  for (const auto& e : model::EffectCatalog()) {
    if (e.name != effect) continue;
    for (const auto& p : e.params)
      if (effect + "." + std::string(p.name) == name) return &p;
  }
  return nullptr;
}

// The start value and default bounds of a parameter.
// *no_default (when given) says the parameter has no default box because it is 0 in the model: then bounds the
// user gives make the parameter fine (the caller tests this flag, not the message).
Status Defaults(const Dataset& ds, const model::PlantParams& nominal, const std::string& name, double* start,
                double* lo, double* hi, bool* no_default = nullptr) {
  if (name.rfind("driver.", 0) == 0) {
    model::DriverParams d = ds.driver;
    const std::string field = name.substr(7);
    if (field != "diode_drop_V")
      return Status::InvalidArgument("'" + name + "': of the driver only diode_drop_V can be identified");
    *start = d.diode_drop_V;
    *lo = 0.0;
    *hi = 2.0;
    return Status::Ok();
  }
  const std::string effect = EffectOf(name);
  if (effect.empty()) {
    auto v = model::GetParam(nominal, name);
    if (!v.ok()) return v.status();
    *start = *v;
    *lo = std::min(0.5 * *v, 1.5 * *v);
    *hi = std::max(0.5 * *v, 1.5 * *v);
    if (!(*hi > *lo)) {
      if (no_default != nullptr) *no_default = true;
      return Status::InvalidArgument("'" + name + "' is 0 in the model; give its bounds (NAME=LO:HI)");
    }
    return Status::Ok();
  }
  const model::EffectParamInfo* info = EffectParam(name);
  if (info == nullptr) return Status::InvalidArgument("'" + name + "': unknown parameter (an effect's is EFFECT.PARAM)");
  model::Effects fx = nominal.effects;
  VB_RETURN_IF_ERROR(model::AddEffect(&fx, effect, {}));
  *start = fx.*(info->field);
  *lo = info->min;
  *hi = info->max;
  if (name == "sensor_offset.offset_A") {
    double peak = 0.0;
    for (const auto& r : ds.runs)
      for (double i : r.i_A) peak = std::max(peak, std::abs(i));
    const double span = std::max(0.3 * peak, 1e-3);
    *lo = *start - span;
    *hi = *start + span;
  } else if (name == "sensor_gain.gain") {
    *lo = 0.5 * *start;
    *hi = 2.0 * *start;
  }
  return Status::Ok();
}

}  // namespace

StatusOr<ParamSpec> ParseParamSpec(const std::string& text, const std::string& flag) {
  ParamSpec p;
  std::string rest = text;
  const auto at = rest.find('@');
  if (at != std::string::npos) {
    if (!ParseNumber(std::string_view(rest).substr(at + 1), &p.initial))
      return Status::InvalidArgument(flag + ": '" + text + "': the start value after @ is not a finite number");
    rest.resize(at);
  }
  const auto eq = rest.find('=');
  if (eq != std::string::npos) {
    const std::string range = rest.substr(eq + 1);
    const auto colon = range.find(':');
    if (colon == std::string::npos || !ParseNumber(std::string_view(range).substr(0, colon), &p.lower) ||
        !ParseNumber(std::string_view(range).substr(colon + 1), &p.upper))
      return Status::InvalidArgument(flag + ": '" + text + "': bounds are NAME=LOWER:UPPER with finite numbers");
    if (!(p.upper > p.lower))
      return Status::InvalidArgument(flag + ": '" + text + "': the upper bound must exceed the lower one");
    rest.resize(eq);
  }
  if (rest.empty()) return Status::InvalidArgument(flag + ": '" + text + "': no parameter name");
  p.name = rest;
  return p;
}

StatusOr<std::pair<std::string, double>> ParseFixed(const std::string& text, const std::string& flag) {
  const auto eq = text.find('=');
  double v = 0.0;
  if (eq == std::string::npos || eq == 0 || !ParseNumber(std::string_view(text).substr(eq + 1), &v))
    return Status::InvalidArgument(flag + ": '" + text + "': expected NAME=VALUE with a finite number");
  return std::make_pair(text.substr(0, eq), v);
}

StatusOr<Identification> Identify(const Dataset& ds, const model::PlantParams& nominal, const IdentifyOptions& options) {
  if (options.params.empty())
    return Status::InvalidArgument("--params: name at least one parameter (e.g. R,L or R=5:100,L=0.01:2); without "
                                   "--params only a moving valve's switch-on runs (a gate that rises once, "
                                   "docs/real-data.md) are identified from scratch");
  Identification id;
  id.model = ds.model;

  id.fixed = options.fixed;
  Candidate c{"identify", {}, {}, options.fixed};
  auto add_effect = [&](const std::string& name) {
    const std::string e = EffectOf(name);
    if (!e.empty() && std::find(c.effects.begin(), c.effects.end(), e) == c.effects.end()) c.effects.push_back(e);
  };
  std::set<std::string> seen;
  for (const auto& [name, v] : options.fixed) {
    if (!seen.insert(name).second) return Status::InvalidArgument("--fix: '" + name + "' is given twice");
    double start = 0, lo = 0, hi = 0;
    VB_RETURN_IF_ERROR(Defaults(ds, nominal, name, &start, &lo, &hi).WithContext("--fix"));
    add_effect(name);
  }
  for (const auto& spec : options.params) {
    if (!seen.insert(spec.name).second)
      return Status::InvalidArgument("--params: '" + spec.name + "' is given twice (or also fixed)");
    double start = 0, lo = 0, hi = 0;
    const bool user_bounds = std::isfinite(spec.lower);
    bool no_default = false;
    auto st = Defaults(ds, nominal, spec.name, &start, &lo, &hi, &no_default);
    if (!st.ok() && !(user_bounds && no_default))
      return st.WithContext("--params");
    if (user_bounds) {
      lo = spec.lower;
      hi = spec.upper;
    }
    if (std::isfinite(spec.initial)) start = spec.initial;
    if (!std::isfinite(start) || start < lo || start > hi) start = std::clamp(std::isfinite(start) ? start : lo, lo, hi);
    if (user_bounds && std::isfinite(spec.initial) && (spec.initial < lo || spec.initial > hi))
      return Status::InvalidArgument("--params: '" + spec.name + "': the start value is outside its bounds");
    const bool log_scale = lo > 0.0 && hi / lo > 20.0;
    c.params.push_back({spec.name, lo, hi, start, log_scale});
    id.nominal[spec.name] = start;
    add_effect(spec.name);
  }
  id.free = c.params;
  bool wide = false;
  for (const auto& f : c.params) wide = wide || (f.lower > 0.0 ? f.upper / f.lower > 3.5 : true);
  id.global = options.global == IdentifyOptions::Global::kOn || (options.global == IdentifyOptions::Global::kAuto && wide);
  // The split and the noise floor, as the diagnosis makes them.
  DiagnoseOptions where_only;
  where_only.attribute = false;
  auto d = Diagnose(ds, nominal, where_only);
  if (!d.ok()) return d.status();
  id.noise_floor_A = d->noise_floor_A;
  id.split_note = d->split_note;
  std::vector<bool> mask;
  for (const auto& r : d->runs) mask.push_back(r.split != Split::kHoldout);
  AttributionOptions opt = options.attribution;
  const int k = static_cast<int>(c.params.size());
  // Identification wants the optimum itself, not a ranking: a tight local fit (each evaluation of a coil
  // in periodic steady state costs microseconds; waveform sessions cost more and keep their own budget).
  opt.max_evaluations = std::max(opt.max_evaluations, 200 * k);
  opt.xtol_rel = std::min(opt.xtol_rel, 1e-6);
  opt.global_evaluations = id.global ? options.global_evaluations_per_param * k : 0;
  opt.candidate_budget_s = options.budget_s;
  auto res = Attribute(ds, mask, nominal, {c}, d->noise_floor_A, opt);
  if (!res.ok()) return res.status();
  id.fit = res->front();
  id.candidate = c;
  if (!id.fit.status.ok()) return id.fit.status;
  // Identifiability: bounds reached, parameters the data does not pin, strong correlations.
  for (std::size_t j = 0; j < c.params.size(); ++j) {
    const FreeParam& f = c.params[j];
    ParamVerdict v;
    v.name = f.name;
    const double x = id.fit.params.at(f.name);
    const double u = Normalised(f, x);
    v.at_bound = u < 0.005 || u > 0.995;
    const auto sig = id.fit.uncertainty.find(f.name);
    v.determined = sig != id.fit.uncertainty.end() && sig->second < 0.5 * (f.upper - f.lower);
    if (!id.fit.correlation.empty())
      for (std::size_t q = 0; q < c.params.size(); ++q)
        if (q != j && std::abs(id.fit.correlation[j][q]) > 0.95)
          v.correlated.emplace_back(c.params[q].name, id.fit.correlation[j][q]);
    id.identifiability.push_back(v);
  }
  return id;
}

StatusOr<Identification> Identify(const Dataset& ds, const model::PlantParams& nominal,
                                  const std::vector<std::string>& names, const AttributionOptions& options) {
  IdentifyOptions o;
  for (const auto& n : names) o.params.push_back({n});
  o.global = IdentifyOptions::Global::kOff;
  o.attribution = options;
  return Identify(ds, nominal, o);
}

StatusOr<model::PlantParams> IdentifiedPlant(const model::PlantParams& nominal, const Identification& id) {
  return FittedPlant(nominal, id.candidate, id.fit);
}

StatusOr<model::DriverParams> IdentifiedDriver(const model::DriverParams& driver, const Identification& id) {
  return FittedDriver(driver, id.candidate, id.fit);
}

std::string IdentificationJson(const Identification& id) {
  nlohmann::ordered_json j;
  j["model"] = id.model;
  j["noise_floor_A"] = id.noise_floor_A;
  j["global_search"] = id.global;
  nlohmann::ordered_json params = nlohmann::ordered_json::object();
  for (std::size_t k = 0; k < id.free.size(); ++k) {
    const FreeParam& f = id.free[k];
    const ParamVerdict& v = id.identifiability[k];
    const auto sig = id.fit.uncertainty.find(f.name);
    nlohmann::ordered_json corr = nlohmann::ordered_json::object();
    for (const auto& [other, r] : v.correlated) corr[other] = r;
    params[f.name] = {{"start", id.nominal.at(f.name)},
                      {"value", id.fit.params.at(f.name)},
                      {"sigma", sig != id.fit.uncertainty.end() && v.determined ? nlohmann::ordered_json(sig->second)
                                                                                : nlohmann::ordered_json(nullptr)},
                      {"determined", v.determined},
                      {"at_bound", v.at_bound},
                      {"correlated", corr},
                      {"lower", f.lower},
                      {"upper", f.upper}};
  }
  j["params"] = params;
  nlohmann::ordered_json fixed = nlohmann::ordered_json::object();
  for (const auto& [name, v] : id.fixed) fixed[name] = v;
  j["fixed"] = fixed;
  j["fit_rmse_A"] = id.fit.fit_rmse_A;
  j["holdout_rmse_before_A"] = id.fit.holdout_rmse_before_A;
  j["holdout_rmse_after_A"] = id.fit.holdout_rmse_after_A;
  j["closed"] = id.fit.closed;
  j["evaluations"] = id.fit.evaluations;
  if (!id.split_note.empty()) j["split_note"] = id.split_note;
  return j.dump(2);
}

std::string IdentificationReport(const Identification& id) {
  std::ostringstream os;
  char buf[320];
  std::snprintf(buf, sizeof buf, "model %s; noise floor %.3f mA; %d model evaluations%s\n", id.model.c_str(),
                id.noise_floor_A * 1e3, id.fit.evaluations, id.global ? " (global search, then local)" : "");
  os << buf;
  if (!id.split_note.empty()) os << id.split_note << "\n";
  for (const auto& [name, v] : id.fixed) os << "  fixed " << name << " = " << FormatNumber(v) << "\n";
  os << "  param                         start        fitted       1-sigma   bounds\n";
  for (std::size_t k = 0; k < id.free.size(); ++k) {
    const FreeParam& f = id.free[k];
    const ParamVerdict& v = id.identifiability[k];
    const auto sig = id.fit.uncertainty.find(f.name);
    char sigma[32];
    if (v.determined && sig != id.fit.uncertainty.end())
      std::snprintf(sigma, sizeof sigma, "%10.3g", sig->second);
    else
      std::snprintf(sigma, sizeof sigma, "%10s", "undeterm.");
    std::snprintf(buf, sizeof buf, "  %-26s %10.5g  %12.6g  %s   [%g, %g]\n", f.name.c_str(), id.nominal.at(f.name),
                  id.fit.params.at(f.name), sigma, f.lower, f.upper);
    os << buf;
  }
  std::snprintf(buf, sizeof buf, "fit runs %.3f mA RMS; holdout %.3f -> %.3f mA RMS (%.0f %% of the gap above noise)\n",
                id.fit.fit_rmse_A * 1e3, id.fit.holdout_rmse_before_A * 1e3, id.fit.holdout_rmse_after_A * 1e3,
                100.0 * id.fit.closed);
  os << buf;
  bool any = false;
  for (const auto& v : id.identifiability) {
    if (!v.at_bound && v.determined && v.correlated.empty()) continue;
    if (!any) os << "identifiability:\n";
    any = true;
    if (v.at_bound) os << "  " << v.name << " ended at a bound: widen its bounds or fix it (--fix)\n";
    if (!v.determined) os << "  " << v.name << " is not determined by these runs\n";
    for (const auto& [other, r] : v.correlated) {
      std::snprintf(buf, sizeof buf, "  %s and %s are correlated (%+.3f): the data trades one for the other\n",
                    v.name.c_str(), other.c_str(), r);
      os << buf;
    }
  }
  if (!any) os << "identifiability: every parameter determined, none at a bound, no correlation above 0.95\n";
  return os.str();
}

}  // namespace vb::gap
