#include "gap/identify.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <set>
#include <sstream>

#include "gap/diagnose.h"

namespace vb::gap {

StatusOr<Identification> Identify(const Dataset& ds, const model::PlantParams& nominal,
                                  const std::vector<std::string>& names, const AttributionOptions& options) {
  if (names.empty()) return Status::InvalidArgument("--params: name at least one parameter (e.g. R,mu_r,b,x_t)");
  Identification id;
  id.model = ds.model;
  Candidate c{"identify", {}, {}};
  std::set<std::string> seen;
  for (const auto& n : names) {
    if (!seen.insert(n).second) return Status::InvalidArgument("--params: '" + n + "' is given twice");
    auto v = model::GetParam(nominal, n);
    if (!v.ok()) return v.status().WithContext("--params");
    const double lo = std::min(0.5 * *v, 1.5 * *v), hi = std::max(0.5 * *v, 1.5 * *v);
    if (!(hi > lo)) return Status::InvalidArgument("--params: '" + n + "' is 0 in the nominal model; cannot scale it");
    c.params.push_back({n, lo, hi, *v, false});
    id.nominal[n] = *v;
  }
  id.free = c.params;
  // The split and the noise floor, as the diagnosis makes them.
  DiagnoseOptions where_only;
  where_only.attribute = false;
  auto d = Diagnose(ds, nominal, where_only);
  if (!d.ok()) return d.status();
  id.noise_floor_A = d->noise_floor_A;
  id.split_note = d->split_note;
  std::vector<bool> mask;
  for (const auto& r : d->runs) mask.push_back(r.split != "holdout");
  AttributionOptions opt = options;
  opt.max_evaluations = std::max(opt.max_evaluations, 60 * static_cast<int>(names.size()));
  auto res = Attribute(ds, mask, nominal, {c}, d->noise_floor_A, opt);
  if (!res.ok()) return res.status();
  id.fit = res->front();
  if (!id.fit.status.ok()) return id.fit.status;
  return id;
}

std::string IdentificationJson(const Identification& id) {
  nlohmann::ordered_json j;
  j["model"] = id.model;
  j["noise_floor_A"] = id.noise_floor_A;
  nlohmann::ordered_json params = nlohmann::ordered_json::object();
  for (const auto& f : id.free)
    params[f.name] = {{"nominal", id.nominal.at(f.name)},
                      {"value", id.fit.params.at(f.name)},
                      {"sigma", id.fit.uncertainty.count(f.name) ? id.fit.uncertainty.at(f.name) : 0.0},
                      {"lower", f.lower},
                      {"upper", f.upper}};
  j["params"] = params;
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
  char buf[256];
  std::snprintf(buf, sizeof buf, "model %s; noise floor %.2f mA; %d model evaluations\n", id.model.c_str(),
                id.noise_floor_A * 1e3, id.fit.evaluations);
  os << buf;
  if (!id.split_note.empty()) os << id.split_note << "\n";
  os << "  param      nominal        fitted     1-sigma   (bounds)\n";
  for (const auto& f : id.free) {
    const double sigma = id.fit.uncertainty.count(f.name) ? id.fit.uncertainty.at(f.name) : 0.0;
    std::snprintf(buf, sizeof buf, "  %-8s %10.5g  %12.6g  %10.3g   [%g, %g]%s\n", f.name.c_str(), id.nominal.at(f.name),
                  id.fit.params.at(f.name), sigma, f.lower, f.upper,
                  id.fit.params.at(f.name) <= f.lower * 1.0001 || id.fit.params.at(f.name) >= f.upper * 0.9999
                      ? "  AT A BOUND"
                      : "");
    os << buf;
  }
  std::snprintf(buf, sizeof buf, "fit runs %.2f mA RMS; holdout %.2f -> %.2f mA RMS (%.0f %% of the gap above noise)\n",
                id.fit.fit_rmse_A * 1e3, id.fit.holdout_rmse_before_A * 1e3, id.fit.holdout_rmse_after_A * 1e3,
                100.0 * id.fit.closed);
  os << buf;
  return os.str();
}

}  // namespace vb::gap
