#include "experiment/trajectory_metrics.h"

#include <algorithm>
#include <cmath>

namespace vb::experiment {

namespace {

// 5-point Gauss-Legendre on [-1, 1] (Abramowitz & Stegun, Table 25.4).
constexpr double kNode[5] = {-0.9061798459386640, -0.5384693101056831, 0.0, 0.5384693101056831,
                             0.9061798459386640};
constexpr double kWeight[5] = {0.2369268850561891, 0.4786286704993665, 0.5688888888888889, 0.4786286704993665,
                               0.2369268850561891};
constexpr int kPoints = 7;  // the piece's start, the five nodes, its end

// A zero of f in (a, b), f(a) and f(b) of opposite signs: Illinois false position (superlinear, bracketed).
template <class F>
double Root(const F& f, double a, double fa, double b, double fb) {
  int side = 0;
  for (int it = 0; it < 80 && b - a > 1e-15; ++it) {
    double c = (a * fb - b * fa) / (fb - fa);
    if (!(c > a && c < b)) c = 0.5 * (a + b);
    const double fc = f(c);
    if (fc == 0.0) return c;
    if ((fc > 0.0) == (fb > 0.0)) {
      b = c;
      fb = fc;
      if (side == -1) fa *= 0.5;
      side = -1;
    } else {
      a = c;
      fa = fc;
      if (side == 1) fb *= 0.5;
      side = 1;
    }
  }
  return 0.5 * (a + b);
}

// The largest of f over the piece from its values v at the points t: an end, or an interior point refined by
// golden-section search between its neighbours (f is smooth and, that close, unimodal): 40 steps shrink the
// bracket by 0.618^40 = 4e-9, so the maximum is exact to the solver's own accuracy.
template <class F>
double Largest(const F& f, const double* t, const double* v) {
  int k = 0;
  for (int j = 1; j < kPoints; ++j)
    if (v[j] > v[k]) k = j;
  double best = v[k];
  if (k > 0 && k < kPoints - 1) {
    constexpr double kInvPhi = 0.6180339887498949;
    double lo = t[k - 1], hi = t[k + 1];
    double c = hi - kInvPhi * (hi - lo), d = lo + kInvPhi * (hi - lo);
    double fc = f(c), fd = f(d);
    for (int it = 0; it < 40; ++it) {
      if (fc > fd) {
        hi = d;
        d = c;
        fd = fc;
        c = hi - kInvPhi * (hi - lo);
        fc = f(c);
      } else {
        lo = c;
        c = d;
        fc = fd;
        d = lo + kInvPhi * (hi - lo);
        fd = f(d);
      }
    }
    best = std::max({best, fc, fd});
  }
  return best;
}

}  // namespace

TrajectoryMetrics::TrajectoryMetrics(ControlledVariable cv, const ReferenceProfile* reference, double start_s,
                                     double end_s, double final_ref, double flow_per_m)
    : cv_(cv),
      ref_(reference != nullptr && reference->has_reference() ? reference : nullptr),
      w0_(start_s),
      w1_(end_s),
      hint_ref_(final_ref),
      band_(std::max(0.02 * std::abs(final_ref), 1e-12)),
      flow_per_m_(flow_per_m) {}

// The reference inside the piece: a step at the piece's end belongs to the next piece (the reference jumps only
// at breakpoints, which are piece ends), so the ends read it just inside.
double TrajectoryMetrics::RefAt(double t, double a, double b) const {
  if (ref_ == nullptr) return kNaN;
  const double d = 1e-6 * (b - a);
  return ref_->At(std::clamp(t, a + d, b - d)).value;
}

void TrajectoryMetrics::OnPiece(double t0_s, double t1_s, const hw::TrajectoryPiece& piece) {
  const double a = std::max(t0_s, w0_), b = std::min(t1_s, w1_);
  if (!(b > a)) return;
  const double half = 0.5 * (b - a), mid = 0.5 * (a + b);
  const bool tracking = cv_ != ControlledVariable::kNone && ref_ != nullptr;
  auto y_of = [&](double i, double x) {
    return cv_ == ControlledVariable::kCurrent ? i : cv_ == ControlledVariable::kPosition ? x : kNaN;
  };
  auto error_at = [&](double t) {
    double i, x;
    piece.At(t, &i, &x);
    return y_of(i, x) - RefAt(t, a, b);
  };
  double t[kPoints], i[kPoints], x[kPoints], y[kPoints], e[kPoints];
  t[0] = a;
  t[kPoints - 1] = b;
  for (int k = 0; k < 5; ++k) t[k + 1] = mid + half * kNode[k];
  for (int k = 0; k < kPoints; ++k) {
    piece.At(t[k], &i[k], &x[k]);
    y[k] = y_of(i[k], x[k]);
    e[k] = tracking ? y[k] - RefAt(t[k], a, b) : kNaN;
  }
  if (!started_) {
    started_ = true;
    y0_ = y[0];
  }
  covered_s_ += b - a;
  has_x_ = has_x_ && std::isfinite(x[0]);

  // Integrals on the nodes.
  for (int k = 0; k < 5; ++k) {
    const double w = kWeight[k] * half;
    i_int_ += w * i[k + 1];
    if (has_x_) {
      x_int_ += w * x[k + 1];
      xpos_int_ += w * std::max(x[k + 1], 0.0);
    }
    if (tracking) e2_ += w * e[k + 1] * e[k + 1];
  }
  // Extremes of the current (ripple).
  {
    auto cur = [&](double tt) {
      double ii, xx;
      piece.At(tt, &ii, &xx);
      return ii;
    };
    i_hi_ = std::max(i_hi_, Largest(cur, t, i));
    double neg[kPoints];
    for (int k = 0; k < kPoints; ++k) neg[k] = -i[k];
    i_lo_ = std::min(i_lo_, -Largest([&](double tt) { return -cur(tt); }, t, neg));
  }
  if (!tracking) return;
  r_end_ = RefAt(b, a, b);

  // |e|: split at its zeros, then Gauss-Legendre on each part (smooth there).
  double cuts[kPoints + 1];
  int n_cuts = 0;
  cuts[n_cuts++] = a;
  for (int k = 0; k + 1 < kPoints; ++k)
    if ((e[k] < 0.0 && e[k + 1] > 0.0) || (e[k] > 0.0 && e[k + 1] < 0.0))
      cuts[n_cuts++] = Root(error_at, t[k], e[k], t[k + 1], e[k + 1]);
  cuts[n_cuts++] = b;
  if (n_cuts == 2) {
    for (int k = 0; k < 5; ++k) ea_ += kWeight[k] * half * std::abs(e[k + 1]);
  } else {
    for (int c = 0; c + 1 < n_cuts; ++c) {
      const double h = 0.5 * (cuts[c + 1] - cuts[c]), m = 0.5 * (cuts[c + 1] + cuts[c]);
      for (int k = 0; k < 5; ++k) ea_ += kWeight[k] * h * std::abs(error_at(m + h * kNode[k]));
    }
  }
  // max |e| and max y.
  double ae[kPoints];
  for (int k = 0; k < kPoints; ++k) ae[k] = std::abs(e[k]);
  emax_ = std::max(emax_, Largest([&](double tt) { return std::abs(error_at(tt)); }, t, ae));
  ymax_ = std::max(ymax_, Largest(
                              [&](double tt) {
                                double ii, xx;
                                piece.At(tt, &ii, &xx);
                                return y_of(ii, xx);
                              },
                              t, y));
  // Settling: the last instant |e| leaves the band.
  int last_out = -1;
  for (int k = 0; k < kPoints; ++k)
    if (ae[k] > band_) last_out = k;
  if (last_out == kPoints - 1) {
    settle_t_ = b;
  } else if (last_out >= 0) {
    auto g = [&](double tt) { return std::abs(error_at(tt)) - band_; };
    settle_t_ = Root(g, t[last_out], ae[last_out] - band_, t[last_out + 1], ae[last_out + 1] - band_);
  }
}

void TrajectoryMetrics::ApplyTo(Metrics* m, double x_max_m, const DriverLossInputs& driver) const {
  if (empty()) return;
  const double T = covered_s_;
  m->mean_current_A = i_int_ / T;
  if (cv_ == ControlledVariable::kNone) {
    m->ripple_pp_A = i_hi_ - i_lo_;
    m->ripple_mid_A = 0.5 * (i_hi_ + i_lo_);
  }
  if (std::isfinite(m->mean_position_m) && has_x_) {
    m->mean_position_m = x_int_ / T;
    m->mean_position_pct = 100.0 * m->mean_position_m / x_max_m;
    // eq. (12) is linear in the (moving-average) opening: its mean is the mean opening's flow.
    m->mean_flow_kg_per_s = flow_per_m_ * xpos_int_ / T;
  }
  if (cv_ != ControlledVariable::kNone && ref_ != nullptr && std::isfinite(y0_) && std::isfinite(r_end_)) {
    m->rmse = std::sqrt(e2_ / T);
    m->iae = ea_;
    const double span = std::abs(r_end_ - y0_);
    // The same applicability rules as MetricsAccumulator::Finish (docs/metrics.md, "Which metrics apply").
    if (span > 0.1 * std::abs(r_end_)) {
      m->max_abs_error = kNaN;
      m->overshoot = span > 0 ? std::max(0.0, (ymax_ - r_end_) / span) : 0.0;
      const bool same_band = r_end_ == hint_ref_ || std::max(0.02 * std::abs(r_end_), 1e-12) == band_;
      m->settling_time_s = !same_band ? kNaN : std::isnan(settle_t_) ? 0.0 : settle_t_ - w0_;
    } else {
      m->max_abs_error = emax_;
      m->overshoot = m->settling_time_s = kNaN;
    }
  }
  FillDriverLosses(m, driver, T);
}

}  // namespace vb::experiment
