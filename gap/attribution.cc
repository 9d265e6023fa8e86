#include "gap/attribution.h"

#include <nlopt.hpp>

#include <Eigen/Dense>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <atomic>
#include <cmath>
#include <functional>
#include <limits>
#include <mutex>
#include <thread>

#include "gap/predict.h"
#include "gap/replay.h"

namespace vb::gap {

const char* CauseKindName(CauseKind kind) {
  switch (kind) {
    case CauseKind::kEffect: return "effect";
    case CauseKind::kParameter: return "parameter";
    case CauseKind::kCombination: return "combination";
  }
  return "effect";
}

StatusOr<CauseKind> ParseCauseKind(std::string_view name) {
  for (CauseKind k : {CauseKind::kEffect, CauseKind::kParameter, CauseKind::kCombination})
    if (name == CauseKindName(k)) return k;
  return Status::InvalidArgument("cause kind: '" + std::string(name) + "' is not effect, parameter or combination");
}

const char* DisqualificationName(Disqualification why) {
  switch (why) {
    case Disqualification::kNone: return "";
    case Disqualification::kEffectVanished: return "effect_vanished";
    case Disqualification::kSaturatedFit: return "saturated_fit";
    case Disqualification::kRAloneDoesAsWell: return "r_alone_does_as_well";
    case Disqualification::kMemberVanished: return "member_vanished";
    case Disqualification::kNotDecisive: return "not_decisive";
  }
  return "";
}

StatusOr<Disqualification> ParseDisqualification(std::string_view name) {
  for (Disqualification d : {Disqualification::kNone, Disqualification::kEffectVanished, Disqualification::kSaturatedFit,
                             Disqualification::kRAloneDoesAsWell, Disqualification::kMemberVanished,
                             Disqualification::kNotDecisive})
    if (name == DisqualificationName(d)) return d;
  return Status::InvalidArgument("disqualification: '" + std::string(name) + "' is not a known reason");
}

void Disqualify(CandidateResult* row, Disqualification why, std::string words) {
  row->disqualification = why;
  row->disqualified = std::move(words);
}

Candidate ParamCandidate(const std::string& param, FreeParam free) {
  Candidate c{"param:" + param, {}, {std::move(free)}, {}};
  c.kind = CauseKind::kParameter;
  return c;
}

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Sets one named parameter: "R" (nominal) or "effect.param".
// coulomb_friction's static force as its excess over the kinetic one, F_s = F_c + F_s_excess [N].
constexpr const char* kStaticExcess = "coulomb_friction.F_s_excess";

Status SetNamed(model::PlantParams* p, const std::string& name, double value) {
  if (name.rfind("driver.", 0) == 0) return Status::Ok();  // ApplyCandidateDriver's
  if (name == kStaticExcess) {
    // Static friction as its excess over the kinetic one (set after F_c): a box on F_s itself has a flat region
    // below F_c, where the model clamps F_s to F_c and the fit stalls with no gradient (practice2m r03 ended at
    // F_s 0.17 N beside F_c 1.82 N, and a spring-preload drift patched the missing breakaway force).
    if (!std::isfinite(value) || value < 0.0 || value > 100.0)
      return Status::InvalidArgument(name + ": " + std::to_string(value) + " outside its bounds");
    p->effects.friction_F_s_N = p->effects.friction_F_c_N + value;
    return Status::Ok();
  }
  const size_t dot = name.find('.');
  if (dot == std::string::npos) return model::SetParam(p, name, value);
  const std::string effect = name.substr(0, dot), param = name.substr(dot + 1);
  for (const auto& e : model::EffectCatalog()) {
    if (e.name != effect) continue;
    for (const auto& info : e.params) {
      if (info.name != param) continue;
      if (!std::isfinite(value) || value < info.min || value > info.max)
        return Status::InvalidArgument(name + ": " + std::to_string(value) + " outside its bounds");
      p->effects.*(info.field) = value;
      return Status::Ok();
    }
  }
  return Status::InvalidArgument(name + ": unknown effect parameter");
}

// The session's replay, compared with the measurement: squared errors of the fit runs and of the holdout runs,
// and (with a nominal reference) the holdout errors and the change from the nominal model by nominal phase.
struct Sse {
  double fit = 0.0, holdout = 0.0;
  std::size_t fit_n = 0, holdout_n = 0;
  std::array<double, kPhaseCount> phase_holdout{}, diff{};
  std::array<std::size_t, kPhaseCount> phase_holdout_n{};
  bool ok = false;
  Status status;
};

Sse Evaluate(const Dataset& ds, const std::vector<bool>& fit_mask, const model::PlantParams& plant,
             const model::DriverParams& driver, const model::SolverOptions& solver, bool holdout_too,
             std::vector<double>* fit_residuals = nullptr, const NominalReference* nominal = nullptr,
             std::vector<std::vector<double>>* holdout_residuals = nullptr) {
  Sse out;
  PredictOptions popt;
  popt.solver = solver;
  popt.driver = &driver;
  // Only what is scored: runs after the last one scored cannot change the score (Predict skips them).
  auto pred = Predict(ds, plant, popt, holdout_too ? std::vector<bool>{} : fit_mask);
  if (!pred.ok()) {
    out.status = pred.status();
    return out;
  }
  for (std::size_t r = 0; r < ds.runs.size(); ++r) {
    if (!fit_mask[r] && !holdout_too) continue;
    const auto& meas = ds.runs[r].i_A;
    const auto& sim = pred->i_A[r];
    double e2 = 0.0;
    std::vector<double>* run_holdout = nullptr;
    if (!fit_mask[r] && holdout_residuals != nullptr) run_holdout = &holdout_residuals->emplace_back();
    for (std::size_t k = 0; k < meas.size(); ++k) {
      const double e = meas[k] - sim[k];
      e2 += e * e;
      if (fit_mask[r] && fit_residuals != nullptr) fit_residuals->push_back(e);
      if (run_holdout != nullptr) run_holdout->push_back(e);
      if (nominal != nullptr) {
        const int p = static_cast<int>(nominal->phase[r][k]);
        const double d = sim[k] - nominal->i_A[r][k];
        out.diff[p] += d * d;
        if (!fit_mask[r]) {
          out.phase_holdout[p] += e * e;
          ++out.phase_holdout_n[p];
        }
      }
    }
    if (fit_mask[r]) {
      out.fit += e2;
      out.fit_n += meas.size();
    } else {
      out.holdout += e2;
      out.holdout_n += meas.size();
    }
  }
  out.ok = true;
  return out;
}

double Rms(double sse, std::size_t n) { return n > 0 ? std::sqrt(sse / static_cast<double>(n)) : 0.0; }

}  // namespace

double IntegratedAutocorrelationTime(const std::vector<std::vector<double>>& series) {
  // Second moments about zero, pooled over the series: a residual's mean is structure too (an offset the model
  // misses is as correlated as it gets), so it is not removed.
  auto moment = [&](std::size_t lag) {
    double sum = 0.0;
    std::size_t n = 0;
    for (const auto& x : series) {
      if (x.size() <= lag) continue;
      for (std::size_t k = lag; k < x.size(); ++k) sum += x[k] * x[k - lag];
      n += x.size() - lag;
    }
    return n > 0 ? sum / static_cast<double>(n) : 0.0;
  };
  std::size_t longest = 0;
  for (const auto& x : series) longest = std::max(longest, x.size());
  const double c0 = moment(0);
  if (!(c0 > 0.0) || longest < 4) return 1.0;
  // Geyer's initial positive sequence (Statistical Science 7, 1992): the sums of adjacent lags
  // Gamma_m = rho_2m + rho_2m+1 are positive and decreasing for a stationary process; the sum stops at the first
  // that is not (noise in the far lags), and each is held to the one before (the initial monotone sequence).
  double tau = -1.0, last = INFINITY;
  for (std::size_t m = 0; 2 * m + 1 < longest / 2; ++m) {
    const double gamma = (m == 0 ? 1.0 : moment(2 * m) / c0) + moment(2 * m + 1) / c0;
    if (!(gamma > 0.0)) break;
    last = std::min(last, gamma);
    tau += 2.0 * last;
  }
  return std::max(tau, 1.0);
}

StatusOr<NominalReference> ReplayNominal(const Dataset& ds, const model::PlantParams& nominal,
                                         const model::SolverOptions& solver) {
  PredictOptions popt;
  popt.solver = solver;
  auto pred = Predict(ds, nominal, popt);
  if (!pred.ok()) return pred.status();
  NominalReference ref;
  std::array<double, kPhaseCount> e2{};
  for (std::size_t r = 0; r < ds.runs.size(); ++r) {
    for (std::size_t k = 0; k < ds.runs[r].i_A.size(); ++k) {
      const double e = ds.runs[r].i_A[k] - pred->i_A[r][k];
      e2[static_cast<int>(pred->phase[r][k])] += e * e;
    }
    ref.i_A.push_back(std::move(pred->i_A[r]));
    ref.phase.push_back(std::move(pred->phase[r]));
  }
  double total = 0.0;
  for (double e : e2) total += e;
  for (int p = 0; p < kPhaseCount; ++p) ref.residual_share[p] = total > 0.0 ? e2[p] / total : 0.0;
  return ref;
}

namespace {

CandidateResult FitContinuous(const Dataset& ds, const std::vector<bool>& fit_mask, const model::PlantParams& nominal,
                              const NominalReference& ref, const Candidate& c, double holdout_before, double noise,
                              const AttributionOptions& options);

// A candidate with a discrete parameter (FreeParam::levels, a form): the others fitted at each level, the level
// whose fit runs end lowest kept. Chosen on the fit runs, as every other parameter is, so the holdout runs still
// judge the candidate as a whole. The result is laid out as the candidate's own parameters (the level's value in
// `params`, a zero row and column in `correlation`, no uncertainty) and scored with the choice counted as one
// parameter.
CandidateResult Fit(const Dataset& ds, const std::vector<bool>& fit_mask, const model::PlantParams& nominal,
                    const NominalReference& ref, const Candidate& c, double holdout_before, double noise,
                    const AttributionOptions& options) {
  const auto discrete = std::find_if(c.params.begin(), c.params.end(), [](const FreeParam& f) { return f.levels > 1; });
  if (discrete == c.params.end()) return FitContinuous(ds, fit_mask, nominal, ref, c, holdout_before, noise, options);
  const std::size_t at = static_cast<std::size_t>(discrete - c.params.begin());
  const FreeParam form = *discrete;
  CandidateResult best;
  bool have = false;
  int evaluations = 0;
  for (int level = 0; level < form.levels; ++level) {
    const double value = form.lower + (form.upper - form.lower) * level / (form.levels - 1);
    Candidate sub = c;
    sub.params.erase(sub.params.begin() + static_cast<std::ptrdiff_t>(at));
    sub.fixed.emplace_back(form.name, value);
    CandidateResult r = FitContinuous(ds, fit_mask, nominal, ref, sub, holdout_before, noise, options);
    evaluations += r.evaluations;
    if (!r.status.ok()) {
      if (!have) best = std::move(r);
      continue;
    }
    r.params[form.name] = value;
    if (!have || !best.status.ok() || r.fit_rmse_A < best.fit_rmse_A) best = std::move(r);
    have = have || best.status.ok();
  }
  best.evaluations = evaluations;
  if (best.status.ok()) {
    if (!best.correlation.empty()) {
      const std::size_t k = c.params.size();
      std::vector<std::vector<double>> full(k, std::vector<double>(k, 0.0));
      for (std::size_t a = 0, sa = 0; a < k; ++a) {
        if (a == at) continue;
        for (std::size_t b = 0, sb = 0; b < k; ++b) {
          if (b == at) continue;
          full[a][b] = best.correlation[sa][sb];
          ++sb;
        }
        ++sa;
      }
      full[at][at] = 1.0;
      best.correlation = std::move(full);
    }
    if (std::isfinite(best.score))
      best.score = best.holdout_rmse_after_A * (1.0 + options.complexity_penalty * static_cast<double>(c.params.size()));
  }
  return best;
}

CandidateResult FitContinuous(const Dataset& ds, const std::vector<bool>& fit_mask, const model::PlantParams& nominal,
                              const NominalReference& ref, const Candidate& c, double holdout_before, double noise,
                              const AttributionOptions& options) {
  CandidateResult res;
  res.name = c.name;
  res.kind = c.kind;
  // The fit's own wall-time budget, within the caller's deadline: every simulation it runs stops there.
  using Clock = std::chrono::steady_clock;
  const auto fit_start = Clock::now();
  const auto budget = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(options.candidate_budget_s));
  const auto fit_deadline = std::min(options.deadline, fit_start + budget);
  if (fit_start >= fit_deadline) {
    res.status = Status::Aborted("not fitted: the diagnosis's time budget had run out");
    res.score = kInf;
    return res;
  }
  AttributionOptions opt = options;
  opt.solver.deadline = fit_deadline;
  const std::size_t k = c.params.size();
  std::vector<double> u(k);
  for (std::size_t j = 0; j < k; ++j) u[j] = std::clamp(Normalised(c.params[j], c.params[j].initial), 0.0, 1.0);
  auto values_of = [&](const std::vector<double>& uu) {
    std::vector<double> v(k);
    for (std::size_t j = 0; j < k; ++j) v[j] = ValueAt(c.params[j], uu[j]);
    return v;
  };
  struct Ctx {
    const Dataset* ds;
    const std::vector<bool>* mask;
    const model::PlantParams* nominal;
    const Candidate* c;
    const AttributionOptions* opt;
    std::function<std::vector<double>(const std::vector<double>&)> values_of;
    int evaluations = 0;
    Status last_error;
    std::vector<std::pair<double, std::vector<double>>>* seen = nullptr;  // the global stage's points
  } ctx{&ds, &fit_mask, &nominal, &c, &opt, values_of, 0, Status::Ok()};
  auto mse = [](Ctx* cx, const std::vector<double>& x) -> double {
    ++cx->evaluations;
    const std::vector<double> values = cx->values_of(x);
    auto plant = ApplyCandidate(*cx->nominal, *cx->c, values);
    if (!plant.ok()) {
      cx->last_error = plant.status();
      return 1e30;
    }
    auto driver = ApplyCandidateDriver(cx->ds->driver, *cx->c, values);
    if (!driver.ok()) {
      cx->last_error = driver.status();
      return 1e30;
    }
    const Sse s = Evaluate(*cx->ds, *cx->mask, *plant, *driver, cx->opt->solver, false);
    if (!s.ok) {
      cx->last_error = s.status;
      return 1e30;
    }
    return s.fit / static_cast<double>(std::max<std::size_t>(s.fit_n, 1));
  };
  auto objective = [](const std::vector<double>& x, std::vector<double>& /*grad*/, void* data) -> double {
    auto* cx = static_cast<Ctx*>(data);
    const double f = decltype(mse){}(cx, x);  // a captureless lambda: its type is default-constructible
    if (cx->seen != nullptr) cx->seen->emplace_back(f, x);
    return f;
  };
  // Local fits start from the initial point and, after a global search, from the best distinct points it
  // found (a basin the global search sampled but did not descend is still explored); the best end wins.
  std::vector<std::vector<double>> starts;
  if (k > 0 && opt.global_evaluations > 0) {
    std::vector<std::pair<double, std::vector<double>>> seen;
    ctx.seen = &seen;
    nlopt::srand(opt.seed);
    nlopt::opt g(nlopt::GN_CRS2_LM, static_cast<unsigned>(k));
    g.set_lower_bounds(std::vector<double>(k, 0.0));
    g.set_upper_bounds(std::vector<double>(k, 1.0));
    g.set_min_objective(objective, &ctx);
    g.set_maxeval(opt.global_evaluations);
    std::vector<double> ug = u;
    double gmin = 0.0;
    try {
      g.optimize(ug, gmin);
    } catch (const std::exception& e) {
      (void)e;  // out of evaluations: the points seen are what counts
    }
    ctx.seen = nullptr;
    std::stable_sort(seen.begin(), seen.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    for (const auto& [f, x] : seen) {
      if (starts.size() >= 3) break;
      bool distinct = true;
      for (const auto& st : starts) {
        double d2 = 0.0;
        for (std::size_t j = 0; j < k; ++j) d2 += (x[j] - st[j]) * (x[j] - st[j]);
        distinct = distinct && d2 > 0.1 * 0.1;
      }
      if (distinct) starts.push_back(x);
    }
  }
  starts.push_back(u);
  if (k > 0) {
    double best_f = INFINITY;
    std::vector<double> best_u = u;
    for (auto start : starts) {
      nlopt::opt o(nlopt::LN_BOBYQA, static_cast<unsigned>(k));
      o.set_lower_bounds(std::vector<double>(k, 0.0));
      o.set_upper_bounds(std::vector<double>(k, 1.0));
      o.set_min_objective(objective, &ctx);
      o.set_xtol_rel(opt.xtol_rel);
      o.set_maxeval(opt.max_evaluations);
      o.set_initial_step(std::vector<double>(k, 0.15));
      double minf = INFINITY;
      try {
        o.optimize(start, minf);
      } catch (const std::exception& e) {
        // Out of evaluations or a roundoff stop: keep the best point NLopt reached (start holds it).
        (void)e;
        minf = decltype(mse){}(&ctx, start);
      }
      if (minf < best_f) {
        best_f = minf;
        best_u = start;
      }
    }
    u = best_u;
  }
  res.evaluations = ctx.evaluations;
  if (Clock::now() >= fit_deadline) {
    char buf[160];
    std::snprintf(buf, sizeof buf, "the fit stopped after %.1f s, its wall-time budget (%d evaluations)",
                  std::chrono::duration<double>(Clock::now() - fit_start).count(), ctx.evaluations);
    res.status = Status::Aborted(buf);
    res.score = kInf;
    return res;
  }
  // The scoring and the uncertainty get half a budget of their own.
  // (options.deadline may be time_point::max(): never add to it.)
  const auto half = Clock::now() + budget / 2;
  opt.solver.deadline = options.deadline == Clock::time_point::max() || options.deadline - Clock::now() > budget / 2
                            ? half
                            : options.deadline + budget / 2;
  const std::vector<double> best = values_of(u);
  auto plant = ApplyCandidate(nominal, c, best);
  auto driver = ApplyCandidateDriver(ds.driver, c, best);
  if (!plant.ok() || !driver.ok()) {
    res.status = plant.ok() ? driver.status() : plant.status();
    res.score = kInf;
    return res;
  }
  std::vector<double> residuals;
  std::vector<std::vector<double>> holdout_residuals;
  const Sse s = Evaluate(ds, fit_mask, *plant, *driver, opt.solver, true, &residuals, &ref, &holdout_residuals);
  if (!s.ok) {
    res.status = s.status;
    res.score = kInf;
    return res;
  }
  for (std::size_t j = 0; j < k; ++j) res.params[c.params[j].name] = best[j];
  res.fit_rmse_A = Rms(s.fit, s.fit_n);
  res.holdout_rmse_before_A = holdout_before;
  res.holdout_rmse_after_A = Rms(s.holdout, s.holdout_n);
  res.holdout_samples = s.holdout_n;
  res.holdout_autocorrelation_time = IntegratedAutocorrelationTime(holdout_residuals);
  double diff_total = 0.0;
  for (double d : s.diff) diff_total += d;
  for (int p = 0; p < kPhaseCount; ++p) {
    res.phase_holdout_after_A[p] = Rms(s.phase_holdout[p], s.phase_holdout_n[p]);
    res.signature[p] = diff_total > 0.0 ? s.diff[p] / diff_total : 0.0;
    res.signature_match += std::sqrt(res.signature[p] * ref.residual_share[p]);
  }
  const double denom = holdout_before - noise;
  res.closed = denom > 0.0 ? std::clamp((holdout_before - res.holdout_rmse_after_A) / denom, 0.0, 1.0) : 0.0;
  res.score = res.holdout_rmse_after_A * (1.0 + opt.complexity_penalty * static_cast<double>(k));
  // An effect that ended where it vanishes found nothing; a fit with as many free parameters as values
  // can match anything. Neither may be the verdict.
  bool has_effect_param = false, all_absent = true;
  for (std::size_t j = 0; j < k; ++j) {
    const FreeParam& f = c.params[j];
    if (!std::isfinite(f.absent)) continue;
    has_effect_param = true;
    if (std::abs(Normalised(f, best[j]) - Normalised(f, f.absent)) > 0.02) all_absent = false;
  }
  if (has_effect_param && all_absent)
    Disqualify(&res, Disqualification::kEffectVanished,
               "fitted at the value where the effect vanishes: no such effect in the data");
  if (k > 0 && s.fit_n <= k)
    Disqualify(&res, Disqualification::kSaturatedFit,
               "as many free parameters (" + std::to_string(k) + ") as fit values (" + std::to_string(s.fit_n) + ")");

  // 1-sigma from the Gauss-Newton approximation: cov = s^2 (J^T J)^-1, J by forward differences.
  if (k > 0 && !residuals.empty()) {
    const std::size_t n = residuals.size();
    Eigen::MatrixXd J(n, k);
    bool ok = true;
    for (std::size_t j = 0; j < k && ok; ++j) {
      std::vector<double> v = best;
      const double h = std::max(1e-6, 1e-3 * std::abs(best[j]));
      v[j] = best[j] + h <= c.params[j].upper ? best[j] + h : best[j] - h;
      const double step = v[j] - best[j];
      auto pj = ApplyCandidate(nominal, c, v);
      auto dj = ApplyCandidateDriver(ds.driver, c, v);
      std::vector<double> rj;
      if (!pj.ok() || !dj.ok() || !Evaluate(ds, fit_mask, *pj, *dj, opt.solver, false, &rj).ok || rj.size() != n) {
        ok = false;
        break;
      }
      for (std::size_t i = 0; i < n; ++i) J(static_cast<Eigen::Index>(i), static_cast<Eigen::Index>(j)) =
          -(rj[i] - residuals[i]) / step;  // d(sim)/dp = -d(residual)/dp
    }
    if (ok && n > k) {
      const double s2 = s.fit / static_cast<double>(n - k);
      const Eigen::MatrixXd JtJ = J.transpose() * J;
      Eigen::FullPivLU<Eigen::MatrixXd> lu(JtJ);
      // A parameter the residuals do not move (a zero column) or a near-singular J^T J: not determined, and
      // no uncertainty is reported for any parameter (0 would read as "exactly known").
      // Judged on J^T J with its columns scaled to unit norm (a correlation-like matrix), so that units (ohm
      // against metres) do not pass for ill-conditioning.
      const double cond_limit = 1e10;
      Eigen::VectorXd d = JtJ.diagonal().cwiseSqrt();
      bool zero_column = false;
      for (Eigen::Index j = 0; j < d.size(); ++j) zero_column = zero_column || !(d(j) > 0.0);
      bool well_posed = lu.isInvertible() && !zero_column;
      if (well_posed) {
        const Eigen::MatrixXd scaled = d.cwiseInverse().asDiagonal() * JtJ * d.cwiseInverse().asDiagonal();
        Eigen::JacobiSVD<Eigen::MatrixXd> svd(scaled);
        const auto& sv = svd.singularValues();
        well_posed = sv(0) > 0.0 && sv(sv.size() - 1) > sv(0) / cond_limit;
      }
      if (well_posed) {
        const Eigen::MatrixXd cov = s2 * lu.inverse();
        for (std::size_t j = 0; j < k; ++j)
          res.uncertainty[c.params[j].name] = std::sqrt(std::max(0.0, cov(static_cast<Eigen::Index>(j), static_cast<Eigen::Index>(j))));
        res.correlation.assign(k, std::vector<double>(k, 0.0));
        for (std::size_t a = 0; a < k; ++a)
          for (std::size_t b = 0; b < k; ++b) {
            const auto ia = static_cast<Eigen::Index>(a), ib = static_cast<Eigen::Index>(b);
            const double d = std::sqrt(cov(ia, ia) * cov(ib, ib));
            res.correlation[a][b] = d > 0.0 ? cov(ia, ib) / d : 0.0;
          }
      }
    }
  }
  return res;
}

}  // namespace

double ValueAt(const FreeParam& f, double u) {
  u = std::clamp(u, 0.0, 1.0);
  if (f.log_scale) return std::exp(std::log(f.lower) + u * (std::log(f.upper) - std::log(f.lower)));
  return f.lower + u * (f.upper - f.lower);
}

double Normalised(const FreeParam& f, double v) {
  if (f.log_scale) return (std::log(v) - std::log(f.lower)) / (std::log(f.upper) - std::log(f.lower));
  return (v - f.lower) / (f.upper - f.lower);
}

void SortRanking(std::vector<CandidateResult>* rows) {
  std::stable_sort(rows->begin(), rows->end(), [](const CandidateResult& a, const CandidateResult& b) {
    const bool qa = a.disqualified.empty() && a.status.ok(), qb = b.disqualified.empty() && b.status.ok();
    if (qa != qb) return qa;
    return a.score < b.score;
  });
}

StatusOr<model::DriverParams> ApplyCandidateDriver(const model::DriverParams& driver, const Candidate& c,
                                                   const std::vector<double>& values) {
  model::DriverParams d = driver;
  if (values.size() != c.params.size()) return Status::Internal("candidate " + c.name + ": value count");
  for (const auto& [name, v] : c.fixed)
    if (name.rfind("driver.", 0) == 0) VB_RETURN_IF_ERROR(model::SetDriverParam(&d, name.substr(7), v).WithContext(name));
  for (std::size_t j = 0; j < values.size(); ++j) {
    const std::string& name = c.params[j].name;
    if (name.rfind("driver.", 0) != 0) continue;
    VB_RETURN_IF_ERROR(model::SetDriverParam(&d, name.substr(7), values[j]).WithContext(name));
  }
  return d;
}

namespace {

// A result's fitted values in the candidate's parameter order.
StatusOr<std::vector<double>> FittedValues(const Candidate& c, const CandidateResult& r) {
  std::vector<double> values;
  for (const auto& p : c.params) {
    auto it = r.params.find(p.name);
    if (it == r.params.end()) return Status::Internal("candidate " + c.name + ": no fitted " + p.name);
    values.push_back(it->second);
  }
  return values;
}

}  // namespace

StatusOr<model::DriverParams> FittedDriver(const model::DriverParams& driver, const Candidate& c,
                                           const CandidateResult& r) {
  auto values = FittedValues(c, r);
  if (!values.ok()) return values.status();
  return ApplyCandidateDriver(driver, c, *values);
}

StatusOr<model::PlantParams> ApplyCandidate(const model::PlantParams& nominal, const Candidate& c,
                                            const std::vector<double>& values) {
  model::PlantParams p = nominal;
  for (const auto& e : c.effects) VB_RETURN_IF_ERROR(model::AddEffect(&p.effects, e, {}).WithContext(c.name));
  for (const auto& [name, v] : c.fixed) VB_RETURN_IF_ERROR(SetNamed(&p, name, v));
  if (values.size() != c.params.size()) return Status::Internal("candidate " + c.name + ": value count");
  for (std::size_t j = 0; j < values.size(); ++j) VB_RETURN_IF_ERROR(SetNamed(&p, c.params[j].name, values[j]));
  // Static friction is at least the kinetic one.
  p.effects.friction_F_s_N = std::max(p.effects.friction_F_s_N, p.effects.friction_F_c_N);
  return p;
}

std::vector<Candidate> DefaultCandidates(const model::PlantParams& nominal) {
  std::vector<Candidate> out;
  auto around = [](double v, double lo_f, double hi_f) { return std::make_pair(v * lo_f, v * hi_f); };
  // The parametric part of the gap: each uncertain nominal parameter alone, +/-40 %.
  for (const char* name : {"R", "k", "delta", "b", "mu_r", "x_t", "m", "l_c", "A_e"}) {
    const double v = *model::GetParam(nominal, name);
    auto [lo, hi] = around(v, 0.6, 1.4);
    out.push_back(ParamCandidate(name, {name, lo, hi, v, false}));
  }
  // Structural effects, each with R free too; `absent` marks where each effect vanishes.
  const auto [rlo, rhi] = around(nominal.R_ohm, 0.8, 1.2);
  const FreeParam R{"R", rlo, rhi, nominal.R_ohm, false};
  out.push_back({"coil_heating", {"coil_heating"},
                 {R, {"coil_heating.R_th", 0.05, 100.0, 2.0, true, 0.05}, {"coil_heating.C_th", 0.01, 100.0, 1.0, true}}, {}});
  out.push_back({"supply_resistance", {"supply_resistance"}, {R, {"supply_resistance.R_s", 0.01, 20.0, 0.5, true, 0.01}}, {}});
  out.push_back({"eddy_currents", {"eddy_currents"}, {R, {"eddy_currents.R_p", 10.0, 1e5, 500.0, true, 1e5}}, {}});
  out.push_back({"sensor_lag", {"sensor_lag"},
                 {R, {"sensor_lag.tau_s", 1e-6, 5e-3, 1e-4, true, 1e-6}, {"sensor_lag.delay_s", 0.0, 1e-3, 2e-5, false, 0.0}}, {}});
  // The saturation's knee in each of the model's forms (Frohlich's, tanh, arctan: model/coil.h), the best on the
  // fit runs kept (issue 36, point 3: a knee of another form left a structured residual that a second cause was
  // then fitted to).
  FreeParam knee{"magnetic_saturation.tanh", 0.0, 2.0, 0.0, false};
  knee.levels = 3;
  out.push_back({"magnetic_saturation", {"magnetic_saturation"},
                 {R, {"magnetic_saturation.B_sat", 0.3, 300.0, 3.0, true, 300.0}, knee}, {}});
  out.push_back({"residual_magnetism", {"residual_magnetism"},
                 {R, {"residual_magnetism.w", 0.002, 1.0, 0.05, true, 0.002}, {"residual_magnetism.alpha", 0.05, 1.0, 0.4, false}}, {}});
  out.push_back({"coulomb_friction", {"coulomb_friction"},
                 {R, {"coulomb_friction.F_c", 0.0, 10.0, 1.0, false, 0.0}, {kStaticExcess, 0.0, 10.0, 0.5, false, 0.0}}, {}});
  out.push_back({"end_stop_bounce", {"end_stop_bounce"}, {R, {"end_stop_bounce.e", 0.0, 0.95, 0.4, false, 0.0}}, {}});
  // The sense chain: a gain and an offset off their nominal values, each with R free. Not in the gapbench
  // vocabulary, but a real chain has them, and naming them beats "unknown" (docs/gap.md).
  const double gain0 = nominal.effects.sensor_gain, off0 = nominal.effects.sensor_offset_A;
  out.push_back({"sensor_gain", {"sensor_gain"}, {R, {"sensor_gain.gain", gain0 * 0.7, gain0 * 1.4, gain0, false, gain0}}, {}});
  out.push_back({"sensor_offset", {"sensor_offset"}, {R, {"sensor_offset.offset_A", off0 - 0.3, off0 + 0.3, off0, false, off0}}, {}});
  return out;
}

std::vector<Candidate> DefaultCandidates(const model::PlantParams& nominal, const Dataset& ds,
                                         const std::vector<bool>& fit_mask, double reference_C) {
  const bool waveforms = HasWaveforms(ds);
  const bool moving = CanShowMotion(ds, nominal);
  bool all_held = true;
  for (const auto& r : ds.runs) all_held = all_held && std::isfinite(r.stroke_m);
  const bool constant_law = nominal.law == model::InductanceLaw::kConstant || all_held;
  auto law_param = [&](const std::string& name) {
    if (name == "R") return true;
    static const std::vector<std::string> mech = {"k", "delta", "b", "m"};
    if (std::find(mech.begin(), mech.end(), name) != mech.end()) return moving;
    if (constant_law) return false;  // L is the only magnetic parameter left (added below)
    if (nominal.law == model::InductanceLaw::kReluctance) return name == "mu_r" || name == "x_t" || name == "l_c" || name == "A_e";
    return false;
  };
  std::vector<Candidate> out;
  for (auto& c : DefaultCandidates(nominal)) {
    if (c.kind == CauseKind::kParameter) {
      if (law_param(c.params.front().name)) out.push_back(std::move(c));
      continue;
    }
    const std::string& e = c.effects.front();
    if (e == "sensor_gain" || e == "sensor_offset") continue;  // bounded by this dataset's currents below
    if ((e == "coulomb_friction" || e == "end_stop_bounce") && !moving) continue;
    // Sampled chains and within-run dynamics of slow states show on waveforms only.
    if ((e == "sensor_lag" || e == "coil_heating" || e == "residual_magnetism") && !waveforms) continue;
    // The knee's form is judged by the current's shape within a run: readings (a few values a run) carry no shape,
    // and there the choice among three knees is one more free parameter for a few values (akita11's hot coil:
    // tanh's knee took 3.20 -> 2.86 mA, both below the 3.08 mA floor, from param:R). Fröhlich's knee only.
    if (e == "magnetic_saturation" && !waveforms)
      std::erase_if(c.params, [](const FreeParam& f) { return f.levels > 1; });
    out.push_back(std::move(c));
  }
  // A coil with one inductance: L itself (unless a table gives it per stroke).
  const bool table = !nominal.inductance_stroke_m.empty();
  if (constant_law && !(all_held && table)) {
    double L = nominal.L_H;
    if (nominal.law != model::InductanceLaw::kConstant && all_held) {
      auto held = model::AtState(nominal, model::HeldState{ds.runs.front().stroke_m, NAN});
      if (held.ok()) L = held->L_H;
    }
    out.insert(out.begin() + 1, ParamCandidate("L", {"L", L * 0.6, L * 1.4, L, false}));
  }
  // The sense chain: an offset (bounded by the currents seen) and a gain, each with R free.
  double peak = 0.0;
  for (const auto& r : ds.runs)
    for (double i : r.i_A) peak = std::max(peak, std::abs(i));
  const double off = std::max(0.3 * peak, 1e-3);
  const FreeParam R{"R", nominal.R_ohm * 0.8, nominal.R_ohm * 1.2, nominal.R_ohm, false};
  const double off0 = nominal.effects.sensor_offset_A, gain0 = nominal.effects.sensor_gain;
  out.push_back({"sensor_offset", {"sensor_offset"}, {R, {"sensor_offset.offset_A", off0 - off, off0 + off, off0, false, off0}}, {}});
  out.push_back({"sensor_gain", {"sensor_gain"}, {R, {"sensor_gain.gain", gain0 * 0.7, gain0 * 1.4, gain0, false, gain0}}, {}});
  // The winding's resistance against the runs' temperatures.
  std::vector<double> fit_T, all_T;
  for (std::size_t r = 0; r < ds.runs.size(); ++r) {
    const double T = ds.runs[r].temperature_C();
    if (!std::isfinite(T)) continue;
    all_T.push_back(T);
    if (fit_mask.empty() || fit_mask[r]) fit_T.push_back(T);
  }
  if (!all_T.empty()) {
    const auto [fmin, fmax] = std::minmax_element(fit_T.begin(), fit_T.end());
    const auto [amin, amax] = std::minmax_element(all_T.begin(), all_T.end());
    const FreeParam alpha{"resistance_temperature.alpha", 0.0, 0.02, 3.93e-3, false, 0.0};
    if (std::isfinite(reference_C) && (*amax != reference_C || *amin != reference_C)) {
      // R is the reference session's, at its temperature: how fast it rose is all that is left to find.
      out.push_back({"resistance_temperature", {"resistance_temperature"}, {alpha},
                     {{"resistance_temperature.T_ref", reference_C}}});
    } else if (!fit_T.empty() && *fmax - *fmin > 1.0) {
      out.push_back({"resistance_temperature", {"resistance_temperature"}, {R, alpha},
                     {{"resistance_temperature.T_ref", *fmin}}});
    } else if (!fit_T.empty() && (*amax - *amin > 1.0)) {
      // One temperature to fit at, others held out: copper's coefficient carries R to them.
      out.push_back({"resistance_temperature", {"resistance_temperature"}, {R},
                     {{"resistance_temperature.T_ref", *fmin}, {"resistance_temperature.alpha", 3.93e-3}}});
    }
  }
  return out;
}

StatusOr<std::vector<CandidateResult>> Attribute(const Dataset& ds, const std::vector<bool>& fit_mask,
                                                 const model::PlantParams& nominal,
                                                 const std::vector<Candidate>& candidates, double noise_floor_A,
                                                 const AttributionOptions& opt) {
  if (fit_mask.size() != ds.runs.size()) return Status::InvalidArgument("fit_mask: one entry per run");
  if (std::find(fit_mask.begin(), fit_mask.end(), true) == fit_mask.end())
    return Status::InvalidArgument("split: no fit runs to fit on");
  auto ref = ReplayNominal(ds, nominal, opt.solver);
  if (!ref.ok()) return ref.status().WithContext("nominal replay");
  double hold_e2 = 0.0;
  std::size_t hold_n = 0;
  for (std::size_t r = 0; r < ds.runs.size(); ++r) {
    if (fit_mask[r]) continue;
    for (std::size_t k = 0; k < ds.runs[r].i_A.size(); ++k) {
      const double e = ds.runs[r].i_A[k] - ref->i_A[r][k];
      hold_e2 += e * e;
    }
    hold_n += ds.runs[r].i_A.size();
  }
  const double holdout_before = Rms(hold_e2, hold_n);
  std::vector<CandidateResult> results(candidates.size());
  std::atomic<std::size_t> next{0};
  std::mutex progress_mu;
  int done = 0;
  auto worker = [&]() {
    for (std::size_t i = next++; i < candidates.size(); i = next++) {
      results[i] = Fit(ds, fit_mask, nominal, *ref, candidates[i], holdout_before, noise_floor_A, opt);
      if (opt.progress) {
        std::lock_guard<std::mutex> lock(progress_mu);
        opt.progress(candidates[i].name, ++done, static_cast<int>(candidates.size()));
      }
    }
  };
  std::vector<std::thread> pool;
  const int threads = std::clamp(opt.threads, 1, static_cast<int>(std::max<std::size_t>(candidates.size(), 1)));
  for (int t = 0; t < threads; ++t) pool.emplace_back(worker);
  for (auto& t : pool) t.join();
  SortRanking(&results);
  return results;
}

namespace {
bool IsParametricSingle(const Candidate& c) {
  return c.kind == CauseKind::kParameter && c.params.size() == 1;
}
}  // namespace

std::vector<std::string> Members(const Candidate& c) {
  if (IsParametricSingle(c)) return {c.name};
  std::vector<std::string> out = c.effects;
  for (const auto& p : c.param_members) out.push_back("param:" + p);
  return out;
}

Candidate PairCandidate(const Candidate& a, const Candidate& b) {
  Candidate c{a.name + "+" + b.name, a.effects, a.params};
  c.kind = CauseKind::kCombination;
  c.effects.insert(c.effects.end(), b.effects.begin(), b.effects.end());
  for (const Candidate* side : {&a, &b}) {
    if (IsParametricSingle(*side)) c.param_members.push_back(side->params.front().name);
    c.param_members.insert(c.param_members.end(), side->param_members.begin(), side->param_members.end());
  }
  for (const auto& p : b.params) {
    const bool dup = std::any_of(c.params.begin(), c.params.end(), [&](const FreeParam& q) { return q.name == p.name; });
    if (!dup) c.params.push_back(p);
  }
  return c;
}

StatusOr<model::PlantParams> FittedPlant(const model::PlantParams& nominal, const Candidate& c,
                                         const CandidateResult& r) {
  auto values = FittedValues(c, r);
  if (!values.ok()) return values.status();
  return ApplyCandidate(nominal, c, *values);
}

}  // namespace vb::gap
