#include "control/fuzzy_current.h"
#include "control/param_check.h"

#include <cmath>
#include <cstdio>
#include <string>

namespace vb::control {
namespace {

double Clamp(double x, double lo, double hi) { return x < lo ? lo : (x > hi ? hi : x); }

// Aggregated output membership on one unit-wide segment between a falling edge (set with strength a_fall, value
// 1 - s) and a rising edge (set with strength a_rise, value s), s in [0, 1].
double SegmentMu(double a_fall, double a_rise, double s) {
  const double f = (1.0 - s) < a_fall ? (1.0 - s) : a_fall;
  const double g = s < a_rise ? s : a_rise;
  return f > g ? f : g;
}

}  // namespace

Status FuzzyCurrent::Validate(const Params& p) {
  VB_RETURN_IF_ERROR(CheckPositive("fuzzy.", "error_scale_A", p.error_scale_A));
  VB_RETURN_IF_ERROR(CheckPositive("fuzzy.", "rate_scale_A_per_s", p.rate_scale_A_per_s));
  VB_RETURN_IF_ERROR(CheckNonNegative("fuzzy.", "rate_filter_tau_s", p.rate_filter_tau_s));
  VB_RETURN_IF_ERROR(CheckPositive("fuzzy.", "output_scale_V", p.output_scale_V));
  VB_RETURN_IF_ERROR(CheckNonNegative("fuzzy.", "feedforward_R_ohm", p.feedforward_R_ohm));
  VB_RETURN_IF_ERROR(CheckPositive("fuzzy.", "carrier_Hz", p.carrier_Hz));
  return Status::Ok();
}

StatusOr<FuzzyCurrent> FuzzyCurrent::Create(const Params& p) {
  Status s = Validate(p);
  if (!s.ok()) return s;
  return FuzzyCurrent(p);
}

std::array<double, 5> FuzzyCurrent::Fuzzify(double x_n) {
  const double x = std::isnan(x_n) ? 0.0 : Clamp(x_n, -1.0, 1.0);
  std::array<double, 5> mu{};
  for (int k = 0; k < 5; ++k) {
    const double d = std::fabs(x - kInputCentres[k]) / 0.5;
    mu[k] = d < 1.0 ? 1.0 - d : 0.0;
  }
  return mu;
}

std::array<double, 5> FuzzyCurrent::Fire(double error_n, double rate_n) {
  const std::array<double, 5> mu_e = Fuzzify(error_n);
  const std::array<double, 5> mu_r = Fuzzify(rate_n);
  std::array<double, 5> alpha{};
  for (int row = 0; row < 5; ++row) {
    if (mu_r[row] <= 0.0) continue;
    for (int col = 0; col < 5; ++col) {
      const double w = mu_r[row] < mu_e[col] ? mu_r[row] : mu_e[col];  // AND = min
      double& a = alpha[kRuleTable[row][col]];
      if (w > a) a = w;  // aggregation = max
    }
  }
  return alpha;
}

double FuzzyCurrent::Centroid(const std::array<double, 5>& alpha_in) {
  // Output sets j = 0..4 are triangles centred at c_j = j - 1 with half-width 1, so on each unit segment
  // [c_{q-1}, c_q] (q = 0..5, y0 = q - 2) at most two sets are non-zero: set q-1 falling, set q rising. The
  // aggregated membership there is max(min(a_{q-1}, 1 - s), min(a_q, s)), which is linear between the kink points
  // {0, 1/2, a_{q-1}, 1 - a_{q-1}, a_q, 1 - a_q, 1}. Between kinks mu is linear and y*mu quadratic, so Simpson's
  // rule integrates both exactly.
  std::array<double, 5> alpha{};
  for (int j = 0; j < 5; ++j) alpha[j] = std::isnan(alpha_in[j]) ? 0.0 : Clamp(alpha_in[j], 0.0, 1.0);

  double area = 0.0;
  double moment = 0.0;
  for (int q = 0; q <= 5; ++q) {
    const double a_fall = q >= 1 ? alpha[q - 1] : 0.0;
    const double a_rise = q <= 4 ? alpha[q] : 0.0;
    if (a_fall <= 0.0 && a_rise <= 0.0) continue;
    const double y0 = kOutputCentres[0] - 1.0 + q;
    std::array<double, 7> s = {0.0, 0.5, 1.0, a_fall, 1.0 - a_fall, a_rise, 1.0 - a_rise};
    for (int a = 1; a < 7; ++a) {  // insertion sort, fixed size
      const double v = s[a];
      int b = a - 1;
      while (b >= 0 && s[b] > v) {
        s[b + 1] = s[b];
        --b;
      }
      s[b + 1] = v;
    }
    for (int n = 0; n + 1 < 7; ++n) {
      const double s0 = s[n];
      const double s1 = s[n + 1];
      const double w = s1 - s0;
      if (w <= 0.0) continue;
      const double sm = 0.5 * (s0 + s1);
      const double m0 = SegmentMu(a_fall, a_rise, s0);
      const double mm = SegmentMu(a_fall, a_rise, sm);
      const double m1 = SegmentMu(a_fall, a_rise, s1);
      area += w / 6.0 * (m0 + 4.0 * mm + m1);
      moment += w / 6.0 * ((y0 + s0) * m0 + 4.0 * (y0 + sm) * mm + (y0 + s1) * m1);
    }
  }
  if (area <= 0.0) return kOutputCentres[kS];
  return moment / area;
}

SwitchCommand FuzzyCurrent::Step(const Measurement& m, const Reference& r, ControllerState* state) const {
  if (!r.command_on) {
    *state = InitialState();
    return SwitchCommand::Gate(0);
  }
  const double i = m.current_A;
  if (!std::isfinite(i) || !std::isfinite(r.value) || !std::isfinite(r.rate)) return SwitchCommand::Gate(0);

  const double supply = (std::isfinite(m.supply_V) && m.supply_V > 0.0) ? m.supply_V : 0.0;
  const double T = 1.0 / p_.carrier_Hz;

  // Error rate: derivative on the measurement minus the reference rate; 0 on the first tick after a reset.
  double rate = state->x[kRate];
  if (state->mode == 1) {
    const double raw = (i - state->x[kPrevCurrent]) / T - r.rate;
    const double a = T / (p_.rate_filter_tau_s + T);  // backward-Euler first-order low-pass; 1 when tau = 0
    rate += a * (raw - rate);
  } else {
    rate = 0.0;
  }
  state->x[kPrevCurrent] = i;
  state->x[kRate] = rate;
  state->mode = 1;

  const double e = i - r.value;  // eq. (21): E = A - D
  const double u = Infer(e / p_.error_scale_A, rate / p_.rate_scale_A_per_s);
  double v = p_.feedforward_R_ohm * r.value + p_.output_scale_V * u;
  v = Clamp(v, 0.0, supply);
  state->x[kLastOutput] = u;
  state->x[kLastVoltage] = v;
  return VoltageToPwm(v, supply, p_.carrier_Hz);
}

}  // namespace vb::control
