#include "experiment/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace vb::experiment {

Metrics ComputeMetrics(const Trace& tr, ControlledVariable cv, double start_s, double end_s, double x_min_m,
                       double x_max_m) {
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  Metrics m;
  const size_t n = tr.size();
  const double dt = tr.sample_period_s;
  size_t k0 = 0, k1 = 0;
  while (k0 < n && tr.t_s[k0] < start_s - 1e-12) ++k0;
  k1 = k0;
  while (k1 < n && tr.t_s[k1] <= end_s + 1e-12) ++k1;
  const size_t count = k1 > k0 ? k1 - k0 : 0;
  if (count == 0) {
    for (auto* f : {&m.rmse, &m.iae, &m.max_abs_error, &m.overshoot, &m.settling_time_s, &m.effort_l2,
                    &m.effort_rms, &m.energy_J, &m.mean_current_A, &m.opening_delay_s, &m.closing_delay_s,
                    &m.mean_position_m, &m.mean_position_pct, &m.mean_flow_kg_per_s})
      *f = kNaN;
    return m;
  }
  const double inv_n = 1.0 / static_cast<double>(count);

  // Effort, energy, wear.
  double v2 = 0, p = 0, isum = 0;
  int switches = 0;
  for (size_t k = k0; k < k1; ++k) {
    v2 += tr.v_coil_V[k] * tr.v_coil_V[k];
    p += tr.v_coil_V[k] * tr.i_A[k];
    isum += tr.i_A[k];
    if (k > k0 && tr.gate[k] != tr.gate[k - 1]) ++switches;
  }
  m.effort_l2 = std::sqrt(v2 * dt);
  m.effort_rms = std::sqrt(v2 * inv_n);
  m.energy_J = p * dt;
  m.switches = switches;
  // Prefer the bench's exact running integrals: sampled sums cannot see a PWM faster than the sample rate.
  const bool exact = !tr.v2_int_V2s.empty() && std::isfinite(tr.v2_int_V2s[k0]) &&
                     std::isfinite(tr.v2_int_V2s[k1 - 1]) && k1 - 1 > k0;
  if (exact) {
    const double span_s = tr.t_s[k1 - 1] - tr.t_s[k0];
    const double v2_exact = tr.v2_int_V2s[k1 - 1] - tr.v2_int_V2s[k0];
    m.effort_l2 = std::sqrt(std::max(0.0, v2_exact));
    m.effort_rms = std::sqrt(std::max(0.0, v2_exact) / span_s);
    m.energy_J = tr.energy_int_J[k1 - 1] - tr.energy_int_J[k0];
    m.switches = tr.switch_count[k1 - 1] - tr.switch_count[k0];
  }
  m.mean_current_A = isum * inv_n;

  // Tracking.
  const std::vector<double>* y = cv == ControlledVariable::kCurrent    ? &tr.i_A
                                 : cv == ControlledVariable::kPosition ? &tr.x_m
                                                                       : nullptr;
  if (y == nullptr || std::isnan(tr.ref[k0])) {
    m.rmse = m.iae = m.max_abs_error = m.overshoot = m.settling_time_s = kNaN;
  } else {
    double e2 = 0, ea = 0, emax = 0, ymax = -std::numeric_limits<double>::infinity();
    for (size_t k = k0; k < k1; ++k) {
      const double e = (*y)[k] - tr.ref[k];
      e2 += e * e;
      ea += std::abs(e);
      emax = std::max(emax, std::abs(e));
      ymax = std::max(ymax, (*y)[k]);
    }
    m.rmse = std::sqrt(e2 * inv_n);
    m.iae = ea * dt;
    m.max_abs_error = emax;
    const double r_end = tr.ref[k1 - 1];
    const double y0 = (*y)[k0];
    const double span = std::abs(r_end - y0);
    m.overshoot = span > 0 ? std::max(0.0, (ymax - r_end) / span) : 0.0;
    const double band = std::max(0.02 * std::abs(r_end), 1e-12);
    double settle = 0.0;
    for (size_t k = k1; k-- > k0;) {
      if (std::abs((*y)[k] - tr.ref[k]) > band) {
        settle = (k + 1 < k1 ? tr.t_s[k + 1] : tr.t_s[k]) - tr.t_s[k0];
        break;
      }
    }
    m.settling_time_s = settle;
  }

  // Valve.
  if (std::isnan(tr.x_m[k0]) || !(x_max_m > x_min_m)) {
    m.opening_delay_s = m.closing_delay_s = m.mean_position_m = m.mean_position_pct = m.mean_flow_kg_per_s = kNaN;
  } else {
    double xs = 0, fs = 0;
    for (size_t k = k0; k < k1; ++k) {
      xs += tr.x_m[k];
      fs += std::isnan(tr.flow_kg_per_s[k]) ? 0.0 : tr.flow_kg_per_s[k];
    }
    m.mean_position_m = xs * inv_n;
    m.mean_position_pct = 100.0 * m.mean_position_m / x_max_m;
    m.mean_flow_kg_per_s = fs * inv_n;
    const double open_at = x_max_m - 1e-6 * (x_max_m - x_min_m);
    const double closed_at = x_min_m + 1e-6 * (x_max_m - x_min_m);
    m.opening_delay_s = m.closing_delay_s = kNaN;
    size_t rise = k1, opened = k1, fall = k1;
    for (size_t k = k0 + 1; k < k1; ++k)
      if (tr.gate[k] == 1 && tr.gate[k - 1] != 1) {
        rise = k;
        break;
      }
    if (k0 < k1 && tr.gate[k0] == 1 && tr.x_m[k0] <= closed_at) rise = k0;
    for (size_t k = rise; k < k1; ++k)
      if (tr.x_m[k] >= open_at) {
        opened = k;
        break;
      }
    if (opened < k1) {
      m.opening_delay_s = tr.t_s[opened] - tr.t_s[rise];
      for (size_t k = opened + 1; k < k1; ++k)
        if (tr.gate[k] != 1 && tr.gate[k - 1] == 1) {
          fall = k;
          break;
        }
      for (size_t k = fall; k < k1; ++k)
        if (tr.x_m[k] <= closed_at) {
          m.closing_delay_s = tr.t_s[k] - tr.t_s[fall];
          break;
        }
    }
  }
  return m;
}

std::vector<std::pair<std::string, double>> MetricList(const Metrics& m) {
  return {{"rmse", m.rmse},
          {"iae", m.iae},
          {"max_abs_error", m.max_abs_error},
          {"overshoot", m.overshoot},
          {"settling_time_s", m.settling_time_s},
          {"effort_l2", m.effort_l2},
          {"effort_rms", m.effort_rms},
          {"energy_J", m.energy_J},
          {"switches", m.switches},
          {"mean_current_A", m.mean_current_A},
          {"opening_delay_s", m.opening_delay_s},
          {"closing_delay_s", m.closing_delay_s},
          {"mean_position_m", m.mean_position_m},
          {"mean_position_pct", m.mean_position_pct},
          {"mean_flow_kg_per_s", m.mean_flow_kg_per_s}};
}

}  // namespace vb::experiment
