#include "control/dither_planner.h"

#include <fmt/format.h>

#include <boost/math/policies/policy.hpp>
#include <boost/math/tools/toms748_solve.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <utility>

namespace vb::control {
namespace {

bool FinitePositive(double v) { return std::isfinite(v) && v > 0.0; }

Status ValidateCoil(const RlCoil& coil) {
  if (!FinitePositive(coil.R_ohm)) {
    return Status::InvalidArgument(fmt::format("coil.R_ohm: must be a finite resistance > 0 ohm, got {:.10g}", coil.R_ohm));
  }
  if (!FinitePositive(coil.L_H)) {
    return Status::InvalidArgument(fmt::format("coil.L_H: must be a finite inductance > 0 H, got {:.10g}", coil.L_H));
  }
  if (!FinitePositive(coil.supply_V)) {
    return Status::InvalidArgument(fmt::format("coil.supply_V: must be a finite voltage > 0 V, got {:.10g}", coil.supply_V));
  }
  return Status::Ok();
}

Status ValidateOptions(const DitherPlannerOptions& o) {
  if (!FinitePositive(o.min_frequency_Hz)) {
    return Status::InvalidArgument(
        fmt::format("options.min_frequency_Hz: must be a finite frequency > 0 Hz, got {:.10g}", o.min_frequency_Hz));
  }
  if (!std::isfinite(o.max_frequency_Hz) || !(o.max_frequency_Hz > o.min_frequency_Hz)) {
    return Status::InvalidArgument(
        fmt::format("options.max_frequency_Hz: must be finite and > options.min_frequency_Hz ({:.10g} Hz), got {:.10g}",
               o.min_frequency_Hz, o.max_frequency_Hz));
  }
  if (!(o.min_duty >= 0.0 && o.min_duty <= 1.0)) {
    return Status::InvalidArgument(fmt::format("options.min_duty: must be in [0, 1], got {:.10g}", o.min_duty));
  }
  if (!(o.max_duty >= 0.0 && o.max_duty <= 1.0)) {
    return Status::InvalidArgument(fmt::format("options.max_duty: must be in [0, 1], got {:.10g}", o.max_duty));
  }
  if (!(o.min_duty < o.max_duty)) {
    return Status::InvalidArgument(fmt::format("options.min_duty: {:.10g} must be < options.max_duty ({:.10g})", o.min_duty,
                                          o.max_duty));
  }
  return Status::Ok();
}

Status ValidateRequest(const DitherRequest& r) {
  if (!FinitePositive(r.average_current_A)) {
    return Status::InvalidArgument(
        fmt::format("dither.average_current_A: must be a finite current > 0 A, got {:.10g}", r.average_current_A));
  }
  if (!FinitePositive(r.dither_amplitude_A)) {
    return Status::InvalidArgument(
        fmt::format("dither.dither_amplitude_A: must be a finite peak-to-peak current > 0 A, got {:.10g}", r.dither_amplitude_A));
  }
  return Status::Ok();
}

// Eqs. (6)-(11) without input checks. Uses expm1 so that 1 - alpha etc. keep full relative precision when
// T/tau is small (high frequency), where i_c - i_d would otherwise cancel.
RlPwmSteadyStateResult Eval(const RlCoil& coil, double frequency_Hz, double duty) {
  const double i_inf_A = coil.supply_V / coil.R_ohm;            // V/R
  const double x = coil.R_ohm / (coil.L_H * frequency_Hz);       // T/tau
  const double one_minus_alpha = -std::expm1(-duty * x);          // 1 - alpha, eq. (6)
  const double one_minus_beta = -std::expm1(-(1.0 - duty) * x);   // 1 - beta,  eq. (7)
  const double beta = std::exp(-(1.0 - duty) * x);                // not 1 - (1 - beta): keeps tiny beta exact
  const double one_minus_alpha_beta = -std::expm1(-x);            // alpha*beta = exp(-T/tau)
  RlPwmSteadyStateResult r;
  r.i_mean_A = duty * i_inf_A;
  if (!(one_minus_alpha_beta > 0.0)) {  // T/tau underflowed (absurd frequency): no ripple, DC current.
    r.i_max_A = r.i_min_A = r.i_avg_A = r.i_mean_A;
    r.i_amp_A = 0.0;
    return r;
  }
  const double i_c = i_inf_A * one_minus_alpha / one_minus_alpha_beta;  // eq. (8)
  r.i_max_A = i_c;
  r.i_min_A = i_c * beta;                                                 // eq. (9)
  r.i_avg_A = 0.5 * i_c * (1.0 + beta);                                   // eq. (10)
  r.i_amp_A = i_c * one_minus_beta;                                       // eq. (11)
  return r;
}

// A bracketed root by Boost.Math's TOMS 748 solver (Alefeld, Potra, Shi, ACM TOMS 21 (1995), algorithm 748;
// docs/decisions.md, "Bracketing solvers"). Requires f(a) and f(b) of opposite signs (or one of them zero); every
// iterate stays inside the bracket. Narrows the bracket to abs_tol + 4 eps |x| and returns its midpoint.
template <typename F>
double BracketedRoot(F&& f, double a, double b, double fa, double fb, double abs_tol) {
  if (fa == 0.0) return a;
  if (fb == 0.0) return b;
  constexpr double kEps = std::numeric_limits<double>::epsilon();
  auto narrow = [abs_tol](double lo, double hi) {
    return hi - lo <= abs_tol + 4.0 * kEps * std::max(std::fabs(lo), std::fabs(hi));
  };
  using NoThrow = boost::math::policies::policy<
      boost::math::policies::domain_error<boost::math::policies::ignore_error>,
      boost::math::policies::evaluation_error<boost::math::policies::ignore_error>>;
  std::uintmax_t max_evaluations = 300;
  const std::pair<double, double> r =
      boost::math::tools::toms748_solve(f, a, b, fa, fb, narrow, max_evaluations, NoThrow());
  return 0.5 * (r.first + r.second);
}

constexpr double kDutyTol = 1e-15;  // absolute, on duty in [0, 1]

// D_f(f): the duty with I_avg(f, D) = i_avg_A (eq. 10). I_avg(f, .) rises strictly from 0 at D = 0 to V/R at
// D = 1, so the root is unique; the caller guarantees 0 < i_avg_A < V/R.
double DutyForAverage(const RlCoil& coil, double frequency_Hz, double i_avg_A) {
  auto h = [&](double duty) { return Eval(coil, frequency_Hz, duty).i_avg_A - i_avg_A; };
  return BracketedRoot(h, 0.0, 1.0, h(0.0), h(1.0), kDutyTol);
}

// The interval of frequencies [f_lo, f_hi] whose D_f lies inside the duty bounds (PlanDitherExact step 2).
struct Band {
  double f_lo_Hz, f_hi_Hz;
  double duty_at_lo, duty_at_hi;
};

StatusOr<Band> FeasibleBand(const RlCoil& coil, double i_avg_A, const DitherPlannerOptions& o) {
  const double f_min = o.min_frequency_Hz, f_max = o.max_frequency_Hz;
  const double i_inf_A = coil.supply_V / coil.R_ohm;
  auto unreachable = [&]() {
    // I_avg(f, D) is monotone in f at fixed D, so the reachable range is spanned by the box corners.
    const double lo = std::min(Eval(coil, f_min, o.min_duty).i_avg_A, Eval(coil, f_max, o.min_duty).i_avg_A);
    const double hi = std::max(Eval(coil, f_min, o.max_duty).i_avg_A, Eval(coil, f_max, o.max_duty).i_avg_A);
    return Status::InvalidArgument(
        fmt::format("dither.average_current_A: {:.6g} A is not reachable with duty in [{:.10g}, {:.10g}] and f in [{:.10g}, {:.10g}] Hz "
               "(reachable {:.4g}..{:.4g} A; supply_V/R_ohm = {:.4g} A)",
               i_avg_A, o.min_duty, o.max_duty, f_min, f_max, lo, hi, i_inf_A));
  };
  if (!(i_avg_A < i_inf_A)) return unreachable();

  const double duty_a = DutyForAverage(coil, f_min, i_avg_A);
  const double duty_b = DutyForAverage(coil, f_max, i_avg_A);
  // A duty within kDutySlack of a bound counts as on it (a request computed from a plan on the boundary must
  // plan again); the reported duties are clamped into the box.
  constexpr double kDutySlack = 1e-12;
  auto below = [&](double d) { return d < o.min_duty - kDutySlack; };
  auto above = [&](double d) { return d > o.max_duty + kDutySlack; };
  const bool a_in = !below(duty_a) && !above(duty_a);
  const bool b_in = !below(duty_b) && !above(duty_b);
  // D_f is monotone in f: if both ends violate the same bound, no frequency in the box works.
  if (!a_in && !b_in && below(duty_a) == below(duty_b)) return unreachable();

  // Where D_f crosses a duty bound: solve I_avg(f, bound) = i_avg_A in f. Because I_avg rises with D, the sign
  // of I_avg(f, bound) - i_avg_A is the sign of bound - D_f(f), which differs at f_min and f_max here (or the
  // other end is within kDutySlack of the bound: then that end is the crossing).
  auto crossing = [&](double bound) {
    auto h = [&](double f) { return Eval(coil, f, bound).i_avg_A - i_avg_A; };
    const double h_min = h(f_min), h_max = h(f_max);
    if ((h_min > 0.0 && h_max > 0.0) || (h_min < 0.0 && h_max < 0.0)) {
      return std::fabs(h_min) < std::fabs(h_max) ? f_min : f_max;
    }
    return BracketedRoot(h, f_min, f_max, h_min, h_max, 1e-12 * f_max);
  };
  auto clamp_duty = [&](double d) { return std::clamp(d, o.min_duty, o.max_duty); };
  Band band{f_min, f_max, clamp_duty(duty_a), clamp_duty(duty_b)};
  if (!a_in) {
    const double bound = below(duty_a) ? o.min_duty : o.max_duty;
    band.f_lo_Hz = crossing(bound);
    band.duty_at_lo = bound;
  }
  if (!b_in) {
    const double bound = below(duty_b) ? o.min_duty : o.max_duty;
    band.f_hi_Hz = crossing(bound);
    band.duty_at_hi = bound;
  }
  return band;
}

Status ValidateAll(const RlCoil& coil, const DitherPlannerOptions& o) {
  VB_RETURN_IF_ERROR(ValidateCoil(coil));
  return ValidateOptions(o);
}

}  // namespace

StatusOr<RlPwmSteadyStateResult> RlPwmSteadyState(const RlCoil& coil, double frequency_Hz, double duty) {
  VB_RETURN_IF_ERROR(ValidateCoil(coil));
  if (!FinitePositive(frequency_Hz)) {
    return Status::InvalidArgument(fmt::format("frequency_Hz: must be a finite frequency > 0 Hz, got {:.10g}", frequency_Hz));
  }
  if (!(duty >= 0.0 && duty <= 1.0)) {
    return Status::InvalidArgument(fmt::format("duty: must be in [0, 1], got {:.10g}", duty));
  }
  return Eval(coil, frequency_Hz, duty);
}

StatusOr<DitherAmplitudeRange> DitherAmplitudeRangeAt(const RlCoil& coil, double average_current_A,
                                                      const DitherPlannerOptions& options) {
  VB_RETURN_IF_ERROR(ValidateAll(coil, options));
  if (!FinitePositive(average_current_A)) {
    return Status::InvalidArgument(
        fmt::format("dither.average_current_A: must be a finite current > 0 A, got {:.10g}", average_current_A));
  }
  StatusOr<Band> band = FeasibleBand(coil, average_current_A, options);
  if (!band.ok()) return band.status();
  DitherAmplitudeRange r;
  r.frequency_at_max_Hz = band->f_lo_Hz;
  r.duty_at_max = band->duty_at_lo;
  r.max_amplitude_A = Eval(coil, band->f_lo_Hz, band->duty_at_lo).i_amp_A;
  r.frequency_at_min_Hz = band->f_hi_Hz;
  r.duty_at_min = band->duty_at_hi;
  r.min_amplitude_A = Eval(coil, band->f_hi_Hz, band->duty_at_hi).i_amp_A;
  return r;
}

StatusOr<DitherPlan> PlanDitherExact(const RlCoil& coil, const DitherRequest& request,
                                     const DitherPlannerOptions& options) {
  VB_RETURN_IF_ERROR(ValidateAll(coil, options));
  VB_RETURN_IF_ERROR(ValidateRequest(request));
  const double i_avg_A = request.average_current_A, i_amp_A = request.dither_amplitude_A;
  StatusOr<DitherAmplitudeRange> range = DitherAmplitudeRangeAt(coil, i_avg_A, options);
  if (!range.ok()) return range.status();

  // Requests within kAmpSlack (relative) of an end of the range are planned at that end: a request computed from
  // a plan on the boundary of the box must plan again despite last-bit rounding.
  constexpr double kAmpSlack = 1e-12;
  if (i_amp_A > range->max_amplitude_A * (1.0 + kAmpSlack)) {
    return Status::InvalidArgument(
        fmt::format("dither.dither_amplitude_A: {:.6g} A is not reachable at average {:.6g} A within f in [{:.10g}, {:.10g}] Hz and duty "
               "in [{:.10g}, {:.10g}] (max {:.4g} A, at {:.4g} Hz)",
               i_amp_A, i_avg_A, options.min_frequency_Hz, options.max_frequency_Hz, options.min_duty,
               options.max_duty, range->max_amplitude_A, range->frequency_at_max_Hz));
  }
  if (i_amp_A < range->min_amplitude_A * (1.0 - kAmpSlack)) {
    return Status::InvalidArgument(
        fmt::format("dither.dither_amplitude_A: {:.6g} A is not reachable at average {:.6g} A within f in [{:.10g}, {:.10g}] Hz and duty "
               "in [{:.10g}, {:.10g}] (min {:.4g} A, at {:.4g} Hz; a smaller ripple needs a higher frequency)",
               i_amp_A, i_avg_A, options.min_frequency_Hz, options.max_frequency_Hz, options.min_duty,
               options.max_duty, range->min_amplitude_A, range->frequency_at_min_Hz));
  }

  // Step 3: g(f) = I_amp(f, D_f(f)) decreases strictly in f; bracket [f_lo, f_hi] holds the root.
  auto g = [&](double f) { return Eval(coil, f, DutyForAverage(coil, f, i_avg_A)).i_amp_A - i_amp_A; };
  const double f_lo = range->frequency_at_max_Hz, f_hi = range->frequency_at_min_Hz;
  double f;
  if (i_amp_A >= range->max_amplitude_A) {
    f = f_lo;
  } else if (i_amp_A <= range->min_amplitude_A) {
    f = f_hi;
  } else {
    f = BracketedRoot(g, f_lo, f_hi, range->max_amplitude_A - i_amp_A, range->min_amplitude_A - i_amp_A, 1e-13 * f_hi);
  }
  // D_f(f) is inside the duty box for f in [f_lo, f_hi]; the clamp only removes last-bit rounding.
  const double duty = std::clamp(DutyForAverage(coil, f, i_avg_A), options.min_duty, options.max_duty);
  const RlPwmSteadyStateResult ss = Eval(coil, f, duty);
  return DitherPlan{f, duty, ss.i_avg_A, ss.i_amp_A, ss.i_mean_A};
}

StatusOr<ApproxDitherModel> FitApproxDitherModel(const RlCoil& coil, const DitherPlannerOptions& options,
                                                 const ApproxFitOptions& fit) {
  VB_RETURN_IF_ERROR(ValidateAll(coil, options));
  if (!(options.min_duty > 0.0 && options.max_duty < 1.0)) {
    return Status::InvalidArgument(
        fmt::format("options.min_duty: the approximate model needs duty bounds inside (0, 1) (k2 is infinite where "
               "there is no ripple), got [{:.10g}, {:.10g}]",
               options.min_duty, options.max_duty));
  }
  const double f1 = fit.k1_fit_frequency_Hz.value_or(options.max_frequency_Hz);
  if (!FinitePositive(f1)) {
    return Status::InvalidArgument(
        fmt::format("fit.k1_fit_frequency_Hz: must be a finite frequency > 0 Hz, got {:.10g}", f1));
  }
  if (fit.k1_duty_points < 2) {
    return Status::InvalidArgument(fmt::format("fit.k1_duty_points: must be >= 2, got {}", fit.k1_duty_points));
  }
  if (fit.k2_duty_points < 2) {
    return Status::InvalidArgument(fmt::format("fit.k2_duty_points: must be >= 2, got {}", fit.k2_duty_points));
  }
  if (fit.k2_frequency_points < 2) {
    return Status::InvalidArgument(
        fmt::format("fit.k2_frequency_points: must be >= 2, got {}", fit.k2_frequency_points));
  }
  auto grid = [](double lo, double hi, int n, int i) { return lo + (hi - lo) * i / (n - 1); };

  ApproxDitherModel m;
  m.coil = coil;
  m.options = options;
  m.k1_fit_frequency_Hz = f1;

  // k1, eq. (12): minimise sum_j (I_avg(f1, D_j) - k1 D_j)^2  =>  k1 = sum D_j I_avg_j / sum D_j^2.
  double s_xy = 0.0, s_xx = 0.0;
  for (int j = 0; j < fit.k1_duty_points; ++j) {
    const double d = grid(options.min_duty, options.max_duty, fit.k1_duty_points, j);
    s_xy += d * Eval(coil, f1, d).i_avg_A;
    s_xx += d * d;
  }
  m.k1_A = s_xy / s_xx;

  // k2(D_j), eq. (13): minimise sum_i (1/I_amp(f_i, D_j) - k2 f_i)^2  =>  k2 = sum f_i / I_amp_i / sum f_i^2.
  m.k2_per_A_Hz.resize(static_cast<std::size_t>(fit.k2_duty_points));
  for (int j = 0; j < fit.k2_duty_points; ++j) {
    const double d = grid(options.min_duty, options.max_duty, fit.k2_duty_points, j);
    double f_y = 0.0, f_f = 0.0;
    for (int i = 0; i < fit.k2_frequency_points; ++i) {
      const double f = grid(options.min_frequency_Hz, options.max_frequency_Hz, fit.k2_frequency_points, i);
      f_y += f / Eval(coil, f, d).i_amp_A;
      f_f += f * f;
    }
    m.k2_per_A_Hz[static_cast<std::size_t>(j)] = f_y / f_f;
  }
  return m;
}

double ApproxK2PerAHz(const ApproxDitherModel& model, double duty) {
  const std::vector<double>& k2 = model.k2_per_A_Hz;
  if (k2.empty()) return std::numeric_limits<double>::quiet_NaN();
  if (k2.size() == 1) return k2[0];
  const double last = static_cast<double>(k2.size() - 1);
  const double span = model.options.max_duty - model.options.min_duty;
  const double pos = std::clamp((duty - model.options.min_duty) / span * last, 0.0, last);
  const std::size_t j = std::min(static_cast<std::size_t>(pos), k2.size() - 2);
  const double t = pos - static_cast<double>(j);
  // 1/k2 ~ (supply_V / L_H) D (1 - D) (the high-frequency limit of eq. 11), so the normalised slope
  // s = 1 / (k2 D (1-D)) is nearly constant in D: interpolate s linearly, then undo the normalisation.
  auto grid_duty = [&](std::size_t i) { return model.options.min_duty + span * static_cast<double>(i) / last; };
  auto s = [&](std::size_t i) {
    const double d = grid_duty(i);
    return 1.0 / (k2[i] * d * (1.0 - d));
  };
  const double d = model.options.min_duty + span * pos / last;
  const double s_d = (1.0 - t) * s(j) + t * s(j + 1);
  return 1.0 / (s_d * d * (1.0 - d));
}

StatusOr<DitherPlan> PlanDitherApprox(const ApproxDitherModel& model, const DitherRequest& request) {
  if (!FinitePositive(model.k1_A) || model.k2_per_A_Hz.size() < 2) {
    return Status::InvalidArgument("model: not fitted (use FitApproxDitherModel)");
  }
  VB_RETURN_IF_ERROR(ValidateRequest(request));
  const DitherPlannerOptions& o = model.options;
  const double duty = request.average_current_A / model.k1_A;  // eq. (12)
  if (duty < o.min_duty || duty > o.max_duty) {
    return Status::InvalidArgument(
        fmt::format("dither.average_current_A: {:.6g} A needs duty {:.4g} by eq. (12) (k1 = {:.6g} A), outside [{:.10g}, {:.10g}]",
               request.average_current_A, duty, model.k1_A, o.min_duty, o.max_duty));
  }
  const double k2 = ApproxK2PerAHz(model, duty);
  const double f = 1.0 / (k2 * request.dither_amplitude_A);  // eq. (13)
  if (f < o.min_frequency_Hz || f > o.max_frequency_Hz) {
    return Status::InvalidArgument(
        fmt::format("dither.dither_amplitude_A: {:.6g} A at average {:.6g} A needs f = {:.4g} Hz by eq. (13) (k2 = {:.6g} 1/(A Hz) "
               "at duty {:.4g}), outside [{:.10g}, {:.10g}] Hz",
               request.dither_amplitude_A, request.average_current_A, f, k2, duty, o.min_frequency_Hz,
               o.max_frequency_Hz));
  }
  const RlPwmSteadyStateResult ss = Eval(model.coil, f, duty);
  return DitherPlan{f, duty, ss.i_avg_A, ss.i_amp_A, ss.i_mean_A};
}

}  // namespace vb::control
