#include "gap/track.h"

#include "gap/hold.h"
#include "gap/text_wrap.h"

#include <boost/math/distributions/normal.hpp>
#include <boost/math/distributions/students_t.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <optional>
#include <sstream>

namespace vb::gap {

namespace {

// Siegmund's correction of the decision interval for the overshoot of a normal CUSUM (1.166 = 2 x 0.583).
constexpr double kOvershoot = 1.166;
// A session joins the reference only when it is itself in control, |z| <= 4, and only guard_sessions later
// (TrackOptions): a change that the CUSUM has not yet summed past h must not move the mean and widen the spread it
// is judged by (Hawkins' chart takes every session at once; a step of 3 sigma then hides itself in a third of
// the cases, measured in tests/gap/track_test.cc), and a fit in a neighbouring optimum must not widen it for
// every later session. Why 4 and not 3 (the screen before 2026-11-30): a screen feeds on itself. A short
// reference whose scatter is small by chance makes the next sessions' z large; screened out, they cannot widen
// it, and the chart flags nothing. With a reference of 5 and values normal, a screen at 3 flagged 0.8 % of
// 60-session series at the default target where none flags 0.2 % (the CUSUM's own 0.22 %; guard of one session,
// tests' draws, docs/track.md "What raised the in-control rate"). At 4 an in-control session is left out with
// probability 6e-5; a fit 10 sigma off is still left out once the reference has about 8 sessions.
constexpr double kJoin_z = 4.0;

// Least squares of y on the session index over [from, to]: slope and its standard error. With two points or a
// perfect line the residuals give no spread: the values' own sigmas do (propagated through the slope's weights).
void Slope(const std::vector<TrackedValue>& v, int from, int to, double* slope, double* sigma) {
  std::vector<double> x, y, s;
  for (int j = std::max(from, 0); j <= to && j < static_cast<int>(v.size()); ++j)
    if (std::isfinite(v[j].value)) x.push_back(j), y.push_back(v[j].value), s.push_back(v[j].sigma);
  *slope = NAN, *sigma = NAN;
  const std::size_t n = x.size();
  if (n < 2) return;
  const double mx = std::accumulate(x.begin(), x.end(), 0.0) / static_cast<double>(n);
  const double my = std::accumulate(y.begin(), y.end(), 0.0) / static_cast<double>(n);
  double sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < n; ++i) sxx += (x[i] - mx) * (x[i] - mx), sxy += (x[i] - mx) * (y[i] - my);
  *slope = sxy / sxx;
  double rss = 0, own = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double e = y[i] - my - *slope * (x[i] - mx);
    rss += e * e;
    if (std::isfinite(s[i])) own += (x[i] - mx) * (x[i] - mx) * s[i] * s[i];
  }
  const double from_residuals = n > 2 ? std::sqrt(rss / static_cast<double>(n - 2) / sxx) : 0.0;
  *sigma = std::max(from_residuals, std::sqrt(own) / sxx);
}

std::string Num(double v) {
  if (!std::isfinite(v)) return "-";
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.5g", v);
  return buf;
}

nlohmann::ordered_json NumJ(double v) { return std::isfinite(v) ? nlohmann::ordered_json(v) : nlohmann::ordered_json(); }

// The physical changes that move a tracked quantity (what a flag on it reads as; the current alone does not
// tell them apart further).
std::string Reading(const std::string& name) {
  if (name == "R")
    return "a warmer or aging winding, a corroding connector or a series resistance in the leads; down: a cooler "
           "winding, or shorted turns (R falls with the turns, L0 and L1 with their square)";
  if (name == "L0" || name == "L1")
    return "the magnetic circuit: shorted turns move L0 and L1 by the same fraction, a core or gap change moves them "
           "apart";
  if (name == "R_p") return "eddy currents in the core (its material or lamination)";
  if (name == "R_hold")
    return "a warmer or aging winding (measured at the coil: a connector or a supply other than declared does not "
           "move it, unless the coil voltage is not recorded); down: a cooler winding or shorted turns";
  if (name == "L_hold")
    return "the held coil's magnetic circuit: shorted turns (with the square of the turns left), a worn stop or "
           "guide (the residual gap), a plunger that no longer holds";
  if (name == "i_dropout")
    return "down: the spring's force at the held stop weaker (a relaxing or broken spring, a lower pressure on "
           "the plunger); up: the pull per ampere weaker (shorted turns, a wider residual gap at the stop) or the "
           "spring stronger. A more resistive winding lowers it by a tenth to a quarter of its own change (the "
           "current decays faster while the plunger starts to move)";
  if (name == "F0*x_max")
    return "the spring's preload (a relaxing or replaced spring), the stroke, or dry friction in the guide (it "
           "opposes the pull-in as a preload does; the switch-on current does not tell them apart)";
  if (name == "k*x_max^2") return "the spring's stiffness or the stroke";
  if (name == "A_net*x_max") return "the pressure area (seat wear) or a supply pressure other than declared";
  if (name == "m*x_max^2") return "the moving mass or the stroke";
  if (name == "b*x_max^2") return "damping: friction in the guide, wear, a fluid of another viscosity";
  if (name == "B_sat") return "the core's saturation (its material or temperature)";
  return "";
}

}  // namespace

double CusumArl(double shift_sigma, double k_sigma, double h_sigma) {
  const double d = shift_sigma - k_sigma, b = h_sigma + kOvershoot;
  if (std::abs(d) < 1e-9) return b * b;
  return (std::exp(-2.0 * d * b) + 2.0 * d * b - 1.0) / (2.0 * d * d);
}

double CusumInterval(double k_sigma, double arl0) {
  double lo = 0.0, hi = 60.0;
  for (int i = 0; i < 200; ++i) {
    const double h = 0.5 * (lo + hi);
    (CusumArl(0.0, k_sigma, h) / 2.0 < arl0 ? lo : hi) = h;
  }
  return 0.5 * (lo + hi);
}

double SelfStartingZ(double d, double s, int n) {
  if (!(s > 0.0) || n < 2 || !std::isfinite(d)) return NAN;
  const double t = d / (s * std::sqrt(1.0 + 1.0 / n));
  const boost::math::students_t_distribution<double> dist(n - 1);
  const boost::math::normal_distribution<double> normal;
  // Through the upper tail for positive t (the lower one for negative): the tail keeps its precision where the
  // CDF rounds to 1.
  const double tail = std::max(boost::math::cdf(boost::math::complement(dist, std::abs(t))), 1e-300);
  const double z = -boost::math::quantile(normal, std::min(tail, 0.5));
  return t < 0.0 ? -z : z;
}

void TrackParameter(TrackedParameter* p, const TrackOptions& o) {
  const double h = CusumInterval(o.k_sigma, o.target_arl0_sessions);
  std::vector<int> ref;
  double up = 0.0, down = 0.0;
  int up_zero = -1, down_zero = -1;
  // The reference's mean and spread: the larger of the sessions' scatter and the identifications' own sigma. The
  // deviation over it is taken as a t with n - 1 degrees of freedom either way. The identification's sigma is an
  // estimate too, not a known sigma: on the independent plant's clean benches it is 0.1 to 10 times the nights'
  // scatter (docs/track.md, "What raised the in-control rate"). Taken as known where it was the larger (a normal
  // deviate, as before 2026-11-30), it flagged 0.67 % of in-control 60-session series drawn from normal values
  // whose sigma it understated by chance, where the target gives 0.28 %; as a t, 0.25 % (the same guard and
  // screen; 0.17 % with today's).
  auto stats = [&](double* mean, double* spread, double current_sigma) {
    const double n = static_cast<double>(ref.size());
    double m = 0.0, own = 0.0;
    for (int i : ref) m += p->sessions[i].value / n;
    double s2 = 0.0;
    for (int i : ref) {
      s2 += (p->sessions[i].value - m) * (p->sessions[i].value - m) / (n - 1.0);
      if (std::isfinite(p->sessions[i].sigma)) own += p->sessions[i].sigma * p->sessions[i].sigma / n;
    }
    const double cur = std::isfinite(current_sigma) ? current_sigma * current_sigma : 0.0;
    *mean = m;
    *spread = std::sqrt(std::max({s2, own, cur}));
  };
  std::vector<int> pending;  // sessions in control, waiting out the guard band
  double held_excess = 0.0;  // the part of the last session's z the clip held back (0: none held)
  double beyond_before = 0.0;  // the last session's z beyond the clip (signed; 0: within it)
  for (int j = 0; j < static_cast<int>(p->sessions.size()); ++j) {
    TrackedValue& v = p->sessions[j];
    while (!pending.empty() && j - pending.front() >= o.guard_sessions) {
      if (p->flagged < 0 && static_cast<int>(ref.size()) < o.baseline_max) ref.push_back(pending.front());
      pending.erase(pending.begin());
    }
    if (!std::isfinite(v.value)) continue;
    if (static_cast<int>(ref.size()) < o.min_reference) {
      ref.push_back(j);
      up_zero = down_zero = j;
      continue;
    }
    double mean = 0.0, spread = 0.0;
    stats(&mean, &spread, v.sigma);
    v.z = SelfStartingZ(v.value - mean, spread, static_cast<int>(ref.size()));
    if (!std::isfinite(v.z)) continue;
    // Clipped (TrackOptions::winsor_z), unless the session before was beyond the clip on the same side: then
    // both count in full (the excess held back from that one is added now), so a large step is flagged on its
    // second or third session while one outlying session is not.
    double zc = std::clamp(v.z, -o.winsor_z, o.winsor_z);
    const double excess = v.z - zc;
    if (o.two_in_a_row && excess != 0.0 && held_excess * excess > 0.0) zc = v.z + held_excess, held_excess = 0.0;
    else if (o.two_in_a_row && excess != 0.0 && beyond_before * excess > 0.0) zc = v.z;
    else held_excess = excess;
    beyond_before = excess;
    up = std::max(0.0, up + zc - o.k_sigma);
    down = std::max(0.0, down - zc - o.k_sigma);
    v.cusum_up = up, v.cusum_down = down;
    if (up == 0.0) up_zero = j;
    if (down == 0.0) down_zero = j;
    if (p->flagged < 0 && (up > h || down > h)) {
      p->flagged = j;
      p->direction = up > h ? "up" : "down";
      p->change_start = (up > h ? up_zero : down_zero) + 1;
    } else if (p->flagged < 0 && std::abs(v.z) <= kJoin_z) {
      pending.push_back(j);  // in control so far: it joins the reference guard_sessions later
    }
  }
  p->reference_sessions = static_cast<int>(ref.size());
  if (ref.size() >= 2) {
    stats(&p->center, &p->spread, NAN);
    p->lower_limit = p->center - 3.0 * p->spread;
    p->upper_limit = p->center + 3.0 * p->spread;
    // The smallest step the CUSUM flags within 5 sessions on average (its one-sided run length at that shift).
    // A step's z enters clipped at winsor_z, so a step beyond it is flagged no sooner than one of winsor_z.
    auto arl = [&](double m) { return CusumArl(std::min(m, o.winsor_z), o.k_sigma, h); };
    double lo = o.k_sigma, hi = 50.0;
    for (int i = 0; i < 100; ++i) {
      const double m = 0.5 * (lo + hi);
      (arl(m) > 5.0 ? lo : hi) = m;
    }
    if (arl(hi) <= 5.0) p->smallest_step = hi * p->spread;
  }
  const int last = static_cast<int>(p->sessions.size()) - 1;
  Slope(p->sessions, 0, last, &p->trend_per_session, &p->trend_sigma);
  if (p->flagged >= 0) Slope(p->sessions, p->change_start, last, &p->drift_per_session, &p->drift_sigma);
  const auto lim = o.limits.find(p->name);
  if (lim != o.limits.end()) {
    p->limit = lim->second;
    // The line the drift follows (the trend over every session when nothing was flagged), from its value at the
    // last session to the limit; only a drift heading to the limit crosses it.
    const bool flagged = p->flagged >= 0;
    const double slope = flagged ? p->drift_per_session : p->trend_per_session;
    const double sigma = flagged ? p->drift_sigma : p->trend_sigma;
    const int from = flagged ? p->change_start : 0;
    // Only a drift the sessions resolve (|slope| > 2 sigma: a 5 % chance of projecting a drift that is not there)
    // is projected; a step without a trend after it has no crossing to project.
    if (std::isfinite(slope) && std::abs(slope) > 2.0 * sigma) {
      double sx = 0, sy = 0, n = 0;
      for (int j = from; j <= last; ++j)
        if (std::isfinite(p->sessions[j].value)) sx += j, sy += p->sessions[j].value, ++n;
      const double at_last = sy / n + slope * (last - sx / n);
      // Session numbers are 1-based; a crossing before the change started is no projection of this drift.
      const double crossing = last + 1 + (p->limit - at_last) / slope;
      if (crossing >= from + 1) p->projected_crossing = crossing;
    }
  }
}

namespace {

Status CheckTrackOptions(const TrackOptions& options) {
  if (!(options.k_sigma > 0.0) || !(options.target_arl0_sessions > 1.0))
    return Status::InvalidArgument("track: k must be > 0 and the target run length > 1 session");
  if (!(options.winsor_z > options.k_sigma))
    return Status::InvalidArgument("track: the clip on z (winsor_z) must be above k");
  if (options.min_reference < 2 || options.baseline_max < options.min_reference)
    return Status::InvalidArgument("track: the reference needs at least 2 sessions and baseline_max >= min_reference");
  return Status::Ok();
}

}  // namespace

StatusOr<MovingIdentification> IdentifyForTracking(const Dataset& session, const model::PlantParams& family,
                                                   const MovingIdentification* anchor, const TrackOptions& options) {
  Dataset ds = session;
  for (auto& r : ds.runs) r.split = Split::kFit;
  MovingIdentifyOptions mo = options.identify;
  mo.warm_start = anchor;
  auto id = IdentifyMovingValve(ds, family, mo);
  if (id.ok() && anchor == nullptr) {
    // The first session from scratch, then polished from its own end as every later one will be: the chain
    // starts converged (a from-scratch end left above the optimum would make the next nights descend further
    // and their parameters trend with the search).
    const MovingIdentification scratch = *id;
    mo.warm_start = &scratch;
    auto polished = IdentifyMovingValve(ds, family, mo);
    if (polished.ok() && polished->fit_rmse_A <= scratch.fit_rmse_A) id = std::move(polished);
  }
  return id;
}

SessionValues ValuesOfSession(const std::string& name, const Dataset& ds, const StatusOr<MovingIdentification>& id) {
  SessionValues v;
  v.name = name;
  bool temperatures = !ds.runs.empty();
  double sum_C = 0.0;
  for (const auto& r : ds.runs) {
    temperatures = temperatures && std::isfinite(r.temperature_C());
    sum_C += r.temperature_C();
  }
  if (temperatures) v.temperature_C = sum_C / static_cast<double>(ds.runs.size());
  if (!id.ok()) {
    v.error = id.status().message();
    return v;
  }
  v.fit_rmse_A = id->fit_rmse_A;
  v.noise_floor_A = id->noise_floor_A;
  v.determined = id->determined;
  return v;
}

void AddHoldValues(SessionValues* values, const std::vector<RunData>& holds, const model::DriverParams& driver) {
  if (holds.empty()) return;
  for (auto& d : HoldValues(holds, driver, &values->notes)) values->determined.push_back(std::move(d));
}

std::string SessionValuesJson(const SessionValues& v) {
  nlohmann::ordered_json j;
  j["session"] = v.name;
  if (!v.error.empty()) j["error"] = v.error;
  j["fit_rmse_A"] = NumJ(v.fit_rmse_A);
  j["noise_floor_A"] = NumJ(v.noise_floor_A);
  j["temperature_C"] = NumJ(v.temperature_C);
  j["determined"] = nlohmann::ordered_json::array();
  for (const auto& d : v.determined)
    j["determined"].push_back({{"name", d.name},
                               {"unit", d.unit},
                               {"meaning", d.meaning},
                               {"value", NumJ(d.value)},
                               {"sigma", NumJ(d.sigma)},
                               {"sigma_white", NumJ(d.sigma_white)},
                               {"determined", d.determined}});
  if (!v.notes.empty()) j["notes"] = v.notes;
  return j.dump();
}

StatusOr<SessionValues> SessionValuesFromJson(const std::string& json) {
  const auto j = nlohmann::json::parse(json, nullptr, false);
  if (!j.is_object() || !j.contains("session") || !j["session"].is_string())
    return Status::InvalidArgument("a session's values: not a JSON object with \"session\"");
  auto num = [](const nlohmann::json& o, const char* k) {
    return o.contains(k) && o[k].is_number() ? o[k].get<double>() : NAN;
  };
  SessionValues v;
  v.name = j["session"].get<std::string>();
  v.error = j.value("error", std::string());
  v.fit_rmse_A = num(j, "fit_rmse_A");
  v.noise_floor_A = num(j, "noise_floor_A");
  v.temperature_C = num(j, "temperature_C");
  if (j.contains("determined") && j["determined"].is_array())
    for (const auto& d : j["determined"]) {
      if (!d.is_object() || !d.contains("name") || !d["name"].is_string())
        return Status::InvalidArgument("a session's values (" + v.name + "): a determined value without a name");
      DeterminedValue e;
      e.name = d["name"].get<std::string>();
      e.unit = d.value("unit", std::string());
      e.meaning = d.value("meaning", std::string());
      e.value = num(d, "value");
      e.sigma = num(d, "sigma");
      e.sigma_white = num(d, "sigma_white");
      e.determined = d.value("determined", true);
      v.determined.push_back(std::move(e));
    }
  if (j.contains("notes") && j["notes"].is_array())
    for (const auto& n : j["notes"])
      if (n.is_string()) v.notes.push_back(n.get<std::string>());
  return v;
}

StatusOr<Tracking> TrackValues(const std::vector<SessionValues>& sessions, const TrackOptions& options) {
  if (sessions.size() < 2) return Status::InvalidArgument("track: give at least two sessions (in time order)");
  VB_RETURN_IF_ERROR(CheckTrackOptions(options));
  Tracking t;
  t.k_sigma = options.k_sigma;
  t.winsor_z = options.winsor_z;
  t.min_reference = options.min_reference;
  t.guard_sessions = options.guard_sessions;
  t.screen_z = kJoin_z;
  t.target_arl0_sessions = options.target_arl0_sessions;
  t.h_sigma = CusumInterval(options.k_sigma, options.target_arl0_sessions);
  const SessionValues* first = nullptr;
  bool temperatures = true;  // every run of every session declares its winding's temperature
  for (const auto& s : sessions) {
    t.sessions.push_back(s.name);
    t.session_errors.push_back(s.error);
    t.fit_rmse_A.push_back(s.error.empty() ? s.fit_rmse_A : NAN);
    t.noise_floor_A.push_back(s.error.empty() ? s.noise_floor_A : NAN);
    temperatures = temperatures && std::isfinite(s.temperature_C);
    if (first == nullptr && s.error.empty()) first = &s;
  }
  if (first == nullptr) {
    return Status::InvalidArgument("track: no session could be identified; the first session's error: " +
                                   sessions.front().error);
  }
  // Winding temperatures declared everywhere: R is referred to 20 C (copper, 3.93e-3 1/K) so that a warmer night
  // is not a resistance change.
  const double alpha = 3.93e-3;
  if (temperatures)
    t.notes.push_back("every run declares its winding's temperature: R is referred to 20 C (copper, alpha 3.93e-3 1/K)");
  // A parameter is tracked when at least half of the identified sessions determine it (1-sigma below half its
  // value): one session whose Gauss-Newton step failed must not drop it, nor one lucky session add it. The sigma
  // is the white-noise one (DeterminedValue::sigma_white): night to night the same valve's form error is the
  // same, so what moves a value between recordings is the noise and the conditions; the scatter of the nights
  // (the reference's) carries the conditions.
  int identified = 0;
  for (const auto& s : sessions) identified += s.error.empty();
  for (const auto& d : first->determined) {
    int determined = 0;
    for (const auto& s : sessions)
      if (s.error.empty())
        for (const auto& e : s.determined)
          determined += e.name == d.name && std::isfinite(e.sigma_white) && e.sigma_white < 0.5 * std::abs(e.value);
    if (2 * determined < identified) {
      t.notes.push_back(d.name + " is repeatable in " + std::to_string(determined) + " of " +
                        std::to_string(identified) + " sessions (1-sigma below half its value): not tracked");
      continue;
    }
    TrackedParameter p;
    p.name = d.name, p.unit = d.unit, p.meaning = d.meaning;
    for (const auto& s : sessions) {
      TrackedValue v;
      if (s.error.empty())
        for (const auto& e : s.determined)
          if (e.name == d.name) v.value = e.value, v.sigma = e.sigma_white;
      if ((d.name == "R" || d.name == "R_hold") && temperatures) {
        const double f = 1.0 + alpha * (s.temperature_C - 20.0);
        v.value /= f, v.sigma /= f;
      }
      p.sessions.push_back(v);
    }
    if ((d.name == "R" || d.name == "R_hold") && temperatures) p.meaning += " at 20 C";
    TrackParameter(&p, options);
    t.parameters.push_back(std::move(p));
  }
  for (const auto& p : t.parameters) {
    if (p.flagged < 0) continue;
    TrackFlag f;
    f.session_index = p.flagged;
    f.session = t.sessions[p.flagged];
    f.parameter = p.name, f.unit = p.unit, f.direction = p.direction;
    f.meaning = p.meaning;
    if (const std::string r = Reading(p.name); !r.empty()) f.meaning += "; moved by " + r;
    f.change = p.sessions[p.flagged].value - p.center;
    f.change_relative = f.change / std::abs(p.center);
    f.z = p.sessions[p.flagged].z;
    f.since = t.sessions[std::clamp(p.change_start, 0, static_cast<int>(t.sessions.size()) - 1)];
    f.drift_per_session = p.drift_per_session, f.drift_sigma = p.drift_sigma;
    f.projected_crossing = p.projected_crossing;
    t.flags.push_back(f);
  }
  // The switch-on's R is a fit's value: a family that does not hold the valve's core or eddy ladder trades it
  // against the inductances (the independent plant's shorted turns moved R by -1.1 % while the winding stayed).
  // The hold's R_hold measures the winding itself, to a few times finer (gap/hold.h). When R is flagged and
  // R_hold, tracked on that night, has not moved although it sees a third of R's change, the winding did not
  // change: the flag says so and stands behind its night's others. Where R_hold moves too (flagged in R's
  // direction on any night, or a third of R's change tonight), nothing is said.
  const TrackedParameter* hold_R = nullptr;
  for (const auto& p : t.parameters)
    if (p.name == "R_hold") hold_R = &p;
  for (auto& f : t.flags) {
    if (f.parameter != "R" || hold_R == nullptr || !(hold_R->smallest_step > 0.0) || !(std::abs(hold_R->center) > 0.0))
      continue;
    const bool moved = hold_R->flagged >= 0 && hold_R->direction == f.direction;
    const double sees = hold_R->smallest_step / std::abs(hold_R->center);
    const double tonight = hold_R->sessions[f.session_index].value;
    const double tonight_relative = (tonight - hold_R->center) / std::abs(hold_R->center);
    if (moved || !std::isfinite(tonight) || !(std::abs(f.change_relative) > 3.0 * sees) ||
        !(std::abs(tonight_relative) < std::abs(f.change_relative) / 3.0))
      continue;
    f.contradicted_by = "R_hold";
    f.meaning += fmt::format("; but R_hold, the winding measured at the hold, has not moved ({:+.2f} % tonight; it "
                             "sees {:.2g} %): not the winding. The switch-on's R took another change: the magnetic "
                             "circuit or shorted turns (L0, L1), the supply or the driver",
                             100.0 * tonight_relative, 100.0 * sees);
  }
  std::stable_sort(t.flags.begin(), t.flags.end(), [](const TrackFlag& a, const TrackFlag& b) {
    if (a.session_index != b.session_index) return a.session_index < b.session_index;
    if (a.contradicted_by.empty() != b.contradicted_by.empty()) return a.contradicted_by.empty();
    return std::abs(a.z) > std::abs(b.z);
  });
  for (std::size_t i = 0; i < sessions.size(); ++i) {
    if (!t.session_errors[i].empty()) t.notes.push_back("session " + t.sessions[i] + " not identified: " + t.session_errors[i]);
    for (const auto& n : sessions[i].notes) t.notes.push_back("session " + t.sessions[i] + ": " + n);
  }
  return t;
}

std::optional<MovingIdentification> BetterAnchor(
    const MovingIdentification& anchor, const MovingIdentification& other, double min_ratio_gain,
    const std::function<StatusOr<MovingIdentification>(const MovingIdentification* start)>& refit_anchor) {
  const auto ratio = [](const MovingIdentification& id) {
    return id.noise_floor_A > 0.0 ? id.fit_rmse_A / id.noise_floor_A : HUGE_VAL;
  };
  if (!(ratio(other) * min_ratio_gain < ratio(anchor))) return std::nullopt;
  auto refit = refit_anchor(&other);
  if (!refit.ok() || !(refit->fit_rmse_A < 0.9 * anchor.fit_rmse_A)) return std::nullopt;
  return std::move(*refit);
}

std::vector<StatusOr<MovingIdentification>> IdentifyAnchored(const std::vector<std::string>& names,
                                                             const SessionIdentifier& identify,
                                                             const std::function<void(const std::string&)>& progress) {
  // Every later session starts from the first one identified (the anchor), not from the session before: a
  // chain of warm starts walks along the directions the runs barely determine (measured on the independent
  // plant: R wandered 1.3 % and back on a clean valve as L1, B_sat and R_p traded off), while starts from one
  // point make each session's end a function of its own data.
  auto pass = [&](const MovingIdentification* anchor, std::vector<StatusOr<MovingIdentification>>* ids) {
    std::optional<MovingIdentification> first;
    for (std::size_t i = 0; i < names.size(); ++i) {
      if (progress)
        progress("session " + names[i] + ": " +
                 (anchor || first ? "warm start from the anchor" : "identifying from scratch"));
      ids->push_back(identify(i, anchor ? anchor : first ? &*first : nullptr));
      if (ids->back().ok() && !anchor && !first) first = *ids->back();
    }
  };
  std::vector<StatusOr<MovingIdentification>> ids;
  pass(nullptr, &ids);
  // The anchor's basin, checked against the others' (docs/track.md, "Outliers"). A warm start from the anchor is
  // a local fit: where the sessions' optimum has two basins it mostly stays in the anchor's, and now and then a
  // session escapes to the other. On the independent plant one bench's first session ended at 10.5 mA in a
  // saturating basin (R 143 ohm) while a third of its later sessions ended at 5.6 mA in another (R 151 ohm):
  // R then jumped 5 % between nights with nothing changed. (That one came from L1's box, which now holds a warm
  // start's start: gap/moving_valve.cc; this check is for basins a local fit cannot leave by itself.) So the
  // first session is fitted again from the end of the session that fits best relative to its own noise floor;
  // when that lowers its own fit by more than 10 % (a fifth of its squared error: far beyond what a re-fit in the
  // same basin gains, which stops at 0.5 % a pass), that end is the better basin, and every session is identified
  // again from the first session refitted there.
  const auto ratio = [](const StatusOr<MovingIdentification>& id) {
    return id.ok() && id->noise_floor_A > 0.0 ? id->fit_rmse_A / id->noise_floor_A : HUGE_VAL;
  };
  for (int round = 0; round < 2; ++round) {
    std::size_t first = 0;
    while (first < ids.size() && !ids[first].ok()) ++first;
    if (first == ids.size()) break;
    std::size_t best = first;
    for (std::size_t i = first; i < ids.size(); ++i)
      if (ratio(ids[i]) < ratio(ids[best])) best = i;
    if (best == first) break;
    auto refit = BetterAnchor(*ids[first], *ids[best], 1.0,
                              [&](const MovingIdentification* start) { return identify(first, start); });
    if (!refit) break;
    if (progress)
      progress("anchor: " + names[first] + " refitted from " + names[best] + "'s end, " +
               Num(1e3 * ids[first]->fit_rmse_A) + " -> " + Num(1e3 * refit->fit_rmse_A) +
               " mA: every session again from there");
    const MovingIdentification anchor = std::move(*refit);
    ids.clear();
    pass(&anchor, &ids);
  }
  return ids;
}

StatusOr<std::vector<SessionValues>> IdentifySessions(const std::vector<TrackSession>& sessions,
                                                      const model::PlantParams& family, const TrackOptions& options) {
  if (sessions.size() < 2) return Status::InvalidArgument("track: give at least two sessions (in time order)");
  VB_RETURN_IF_ERROR(CheckTrackOptions(options));
  std::vector<std::string> names;
  for (const auto& s : sessions) names.push_back(s.name);
  // A session's hold runs (given apart, or still in its dataset) are measured beside the identification, which
  // fits the switch-ons.
  std::vector<Dataset> switch_ons;
  std::vector<std::vector<RunData>> holds;
  for (const auto& s : sessions) {
    switch_ons.push_back(s.dataset);
    holds.push_back(s.holds);
    for (auto& h : TakeHoldRuns(&switch_ons.back())) holds.back().push_back(std::move(h));
  }
  const auto ids = IdentifyAnchored(
      names,
      [&](std::size_t i, const MovingIdentification* anchor) {
        return IdentifyForTracking(switch_ons[i], family, anchor, options);
      },
      options.progress);
  std::vector<SessionValues> values;
  for (std::size_t i = 0; i < sessions.size(); ++i) {
    values.push_back(ValuesOfSession(sessions[i].name, switch_ons[i], ids[i]));
    AddHoldValues(&values.back(), holds[i], switch_ons[i].driver);
  }
  return values;
}

StatusOr<Tracking> TrackSessions(const std::vector<TrackSession>& sessions, const model::PlantParams& family,
                                 const TrackOptions& options) {
  VB_ASSIGN_OR_RETURN(std::vector<SessionValues> values, IdentifySessions(sessions, family, options));
  return TrackValues(values, options);
}

std::string TrackingJson(const Tracking& t) {
  nlohmann::ordered_json j;
  j["sessions"] = t.sessions;
  j["detector"] = {{"kind", "self-starting two-sided CUSUM (Hawkins 1987), z clipped (Lucas & Crosier 1982)"},
                   {"k_sigma", t.k_sigma},
                   {"h_sigma", t.h_sigma},
                   {"winsor_z", NumJ(t.winsor_z)},
                   {"target_arl0_sessions", t.target_arl0_sessions},
                   {"reference_min_sessions", t.min_reference},
                   {"guard_sessions", t.guard_sessions},
                   {"reference_screen_z", NumJ(t.screen_z)}};
  nlohmann::ordered_json fits = nlohmann::ordered_json::array();
  for (std::size_t i = 0; i < t.sessions.size(); ++i)
    fits.push_back({{"session", t.sessions[i]}, {"fit_rmse_A", NumJ(t.fit_rmse_A[i])},
                    {"noise_floor_A", NumJ(t.noise_floor_A[i])},
                    {"error", t.session_errors[i].empty() ? nlohmann::ordered_json() : nlohmann::ordered_json(t.session_errors[i])}});
  j["identifications"] = fits;
  nlohmann::ordered_json ps = nlohmann::ordered_json::array();
  for (const auto& p : t.parameters) {
    nlohmann::ordered_json values = nlohmann::ordered_json::array();
    for (std::size_t i = 0; i < p.sessions.size(); ++i) {
      const auto& v = p.sessions[i];
      values.push_back({{"session", t.sessions[i]}, {"value", NumJ(v.value)}, {"sigma", NumJ(v.sigma)}, {"z", NumJ(v.z)},
                        {"cusum_up", v.cusum_up}, {"cusum_down", v.cusum_down}});
    }
    auto session_at = [&](int i) {
      return i >= 0 && i < static_cast<int>(t.sessions.size()) ? nlohmann::ordered_json(t.sessions[i]) : nlohmann::ordered_json();
    };
    ps.push_back({{"parameter", p.name}, {"unit", p.unit}, {"meaning", p.meaning}, {"values", values},
                  {"reference_sessions", p.reference_sessions}, {"center", NumJ(p.center)}, {"sigma", NumJ(p.spread)},
                  {"lower_limit", NumJ(p.lower_limit)}, {"upper_limit", NumJ(p.upper_limit)},
                  {"flagged_session", session_at(p.flagged)}, {"change_since", session_at(p.change_start)},
                  {"direction", p.direction.empty() ? nlohmann::ordered_json() : nlohmann::ordered_json(p.direction)},
                  {"drift_per_session", NumJ(p.drift_per_session)}, {"drift_sigma", NumJ(p.drift_sigma)},
                  {"limit", NumJ(p.limit)}, {"projected_crossing_session", NumJ(p.projected_crossing)},
                  {"smallest_detectable_step", NumJ(p.smallest_step)},
                  {"trend_per_session", NumJ(p.trend_per_session)}, {"trend_sigma", NumJ(p.trend_sigma)}});
  }
  j["parameters"] = ps;
  nlohmann::ordered_json flags = nlohmann::ordered_json::array();
  for (const auto& f : t.flags)
    flags.push_back({{"session", f.session}, {"parameter", f.parameter}, {"meaning", f.meaning}, {"unit", f.unit},
                     {"direction", f.direction},
                     {"change", NumJ(f.change)}, {"change_relative", NumJ(f.change_relative)}, {"z", NumJ(f.z)},
                     {"since", f.since}, {"drift_per_session", NumJ(f.drift_per_session)},
                     {"drift_sigma", NumJ(f.drift_sigma)}, {"projected_crossing_session", NumJ(f.projected_crossing)},
                     {"contradicted_by", f.contradicted_by.empty() ? nlohmann::ordered_json()
                                                                   : nlohmann::ordered_json(f.contradicted_by)}});
  j["flags"] = flags;
  j["notes"] = t.notes;
  return j.dump(2);
}

std::string TrackingReport(const Tracking& t) {
  std::ostringstream o;
  char buf[400];
  std::snprintf(buf, sizeof buf,
                "%zu sessions; a self-starting two-sided CUSUM per parameter, k %.2g, h %.3g sigma, z clipped at "
                "%.3g\n(in control: %.0f sessions; monitoring from session %d; a session joins the reference %d "
                "sessions later if its |z| <= %.3g)\n\n",
                t.sessions.size(), t.k_sigma, t.h_sigma, t.winsor_z, t.target_arl0_sessions, t.min_reference + 1,
                t.guard_sessions, t.screen_z);
  o << buf;
  // The table in blocks of 5 parameters: 28 + 5 x 18 = 118 columns, within a 120-column terminal.
  constexpr std::size_t kPerBlock = 5;
  for (std::size_t first = 0; first < std::max<std::size_t>(t.parameters.size(), 1); first += kPerBlock) {
    const std::size_t end = std::min(t.parameters.size(), first + kPerBlock);
    if (first > 0) o << "\n";
    std::snprintf(buf, sizeof buf, "%-17s %10s", "session", "fit [mA]");
    o << buf;
    for (std::size_t k = first; k < end; ++k) {
      const auto& p = t.parameters[k];
      std::snprintf(buf, sizeof buf, " %17s", (p.name + " [" + p.unit + "]").c_str());
      o << buf;
    }
    o << "\n";
    for (std::size_t i = 0; i < t.sessions.size(); ++i) {
      std::snprintf(buf, sizeof buf, "%-17s %10s", t.sessions[i].c_str(), Num(t.fit_rmse_A[i] * 1e3).c_str());
      o << buf;
      for (std::size_t k = first; k < end; ++k) {
        const auto& p = t.parameters[k];
        const auto& v = p.sessions[i];
        std::string cell = Num(v.value);
        if (static_cast<int>(i) == p.flagged) cell += " !";
        else if (std::isfinite(v.z) && std::abs(v.z) > 3.0) cell += " *";
        std::snprintf(buf, sizeof buf, " %17s", cell.c_str());
        o << buf;
      }
      o << "\n";
    }
  }
  o << "(! the session flagged; * more than 3 sigma from the reference)\n";
  o << "\nlimits: the reference's mean -+ 3 sigma (sigma the larger of the sessions' scatter and the identification's\n"
       "own); the smallest step flagged within 5 sessions on average\n";
  for (const auto& p : t.parameters) {
    std::snprintf(buf, sizeof buf, "  %-12s %12s .. %-12s %-6s center %-12s (%d sessions); smallest step %s\n",
                  p.name.c_str(), Num(p.lower_limit).c_str(), Num(p.upper_limit).c_str(), p.unit.c_str(),
                  Num(p.center).c_str(), p.reference_sessions, Num(p.smallest_step).c_str());
    o << buf;
  }
  o << "\n";
  if (t.flags.empty()) o << "no parameter flagged\n";
  for (const auto& f : t.flags) {
    std::snprintf(buf, sizeof buf, "FLAG %s: %s %s by %s %s (%+.2f %%, z %.2f), changing since %s\n    ", f.session.c_str(),
                  f.parameter.c_str(), f.direction.c_str(), Num(std::abs(f.change)).c_str(), f.unit.c_str(),
                  100.0 * f.change_relative, f.z, f.since.c_str());
    o << buf;
    if (std::isfinite(f.drift_per_session)) {
      const bool drifting = std::abs(f.drift_per_session) > 2.0 * f.drift_sigma;
      std::snprintf(buf, sizeof buf, drifting ? "drifting %s +- %s %s per session" : "a step, no drift after it (%s +- %s %s per session)",
                    Num(f.drift_per_session).c_str(), Num(f.drift_sigma).c_str(), f.unit.c_str());
      o << buf;
    }
    if (std::isfinite(f.projected_crossing)) {
      std::snprintf(buf, sizeof buf, "; reaches its limit at session %.1f", f.projected_crossing);
      o << buf;
    }
    o << "\n" << Wrap({f.meaning}, 4);  // within 120 columns, as every report
  }
  for (const auto& p : t.parameters)
    if (p.flagged < 0 && std::isfinite(p.smallest_step)) {
      std::snprintf(buf, sizeof buf,
                    "%s: no change seen; a step below %.3g %s (%.2g %%) is too small to see; trend %.2g +- %.2g a session",
                    p.name.c_str(), p.smallest_step, p.unit.c_str(), 100.0 * p.smallest_step / std::abs(p.center),
                    p.trend_per_session, p.trend_sigma);
      o << buf;
      if (std::isfinite(p.projected_crossing)) {
        std::snprintf(buf, sizeof buf, "; the trend reaches the limit %s at session %.1f", Num(p.limit).c_str(),
                      p.projected_crossing);
        o << buf;
      }
      o << "\n";
    }
  for (const auto& n : t.notes) o << "note: " << n << "\n";
  return o.str();
}

}  // namespace vb::gap
