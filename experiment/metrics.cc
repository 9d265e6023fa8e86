#include "experiment/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace vb::experiment {

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kTimeSlack_s = 1e-12;

// A channel a hand-built trace may leave empty reads as NaN.
double At(const std::vector<double>& channel, size_t k) { return k < channel.size() ? channel[k] : kNaN; }

double BandOf(double final_ref) { return std::max(0.02 * std::abs(final_ref), 1e-12); }

}  // namespace

MetricsAccumulator::MetricsAccumulator(ControlledVariable cv, double start_s, double end_s, double x_min_m,
                                       double x_max_m, const DriverLossInputs& driver, double final_ref_hint)
    : cv_(cv),
      start_s_(start_s),
      end_s_(end_s),
      x_min_m_(x_min_m),
      x_max_m_(x_max_m),
      driver_(driver),
      hint_ref_(final_ref_hint),
      hint_band_(BandOf(final_ref_hint)) {}

void MetricsAccumulator::Add(const Trace& block, size_t from, size_t to) {
  dt_ = block.sample_period_s;
  to = std::min(to, block.size());
  for (size_t k = from; k < to; ++k) AddSample(block, k);
}

void MetricsAccumulator::AddSample(const Trace& b, size_t k) {
  const double t = b.t_s[k];
  if (t < start_s_ - kTimeSlack_s || t > end_s_ + kTimeSlack_s) return;
  const double v = b.v_coil_V[k], i = b.i_A[k], ref = At(b.ref, k), x = At(b.x_m, k);
  const std::int8_t gate = b.gate[k];
  const double y = cv_ == ControlledVariable::kCurrent ? i : cv_ == ControlledVariable::kPosition ? x : kNaN;
  const bool first = count_ == 0;
  if (first) {
    t_first_ = t;
    v2int_first_ = At(b.v2_int_V2s, k);
    eint_first_ = At(b.energy_int_J, k);
    sw_first_ = At(b.switch_count, k);
    has_exact_ = std::isfinite(v2int_first_);
    y0_ = y;
    ref_first_ = ref;
    x_first_ = x;
    i_lo_ = i_hi_ = i;
    ymax_ = -std::numeric_limits<double>::infinity();
  } else if (gate != gate_prev_) {
    switches_ += 1.0;
  }
  ++count_;
  t_last_ = t;
  v2int_last_ = At(b.v2_int_V2s, k);
  eint_last_ = At(b.energy_int_J, k);
  sw_last_ = At(b.switch_count, k);
  ref_last_ = ref;

  // Effort, energy, wear, ripple.
  v2_ += v * v;
  p_ += v * i;
  isum_ += i;
  i_lo_ = std::min(i_lo_, i);
  i_hi_ = std::max(i_hi_, i);

  // Tracking: the settling time is the instant after the last sample outside the band (that sample's own time
  // when it is the window's last).
  if (cv_ != ControlledVariable::kNone) {
    const double e = y - ref;
    e2_ += e * e;
    ea_ += std::abs(e);
    emax_ = std::max(emax_, std::abs(e));
    ymax_ = std::max(ymax_, y);
    if (exceed_pending_) {
      settle_ = t - t_first_;
      exceed_pending_ = false;
    }
    if (std::abs(e) > hint_band_) {
      settle_ = t - t_first_;
      exceed_pending_ = true;
    }
  }

  // Valve.
  if (x_max_m_ > x_min_m_ && !std::isnan(x_first_)) {
    xs_ += x;
    const double flow = At(b.flow_kg_per_s, k);
    fs_ += std::isnan(flow) ? 0.0 : flow;
    const double open_at = x_max_m_ - 1e-6 * (x_max_m_ - x_min_m_);
    const double closed_at = x_min_m_ + 1e-6 * (x_max_m_ - x_min_m_);
    const bool rising = first ? (gate == 1 && x <= closed_at) : (gate == 1 && gate_prev_ != 1);
    const bool falling = !first && gate != 1 && gate_prev_ == 1;
    if (valve_ == Valve::kSeekRise && rising) {
      t_rise_ = t;
      // An opening delay only from a closed valve: a rising edge while the valve is open (a hold) opens nothing.
      valve_ = x > closed_at ? Valve::kDone : Valve::kSeekOpen;
    }
    if (valve_ == Valve::kSeekOpen && x >= open_at) {
      opening_s_ = t - t_rise_;
      opened_ = true;
      valve_ = Valve::kSeekFall;
    } else if (valve_ == Valve::kSeekFall && falling) {
      t_fall_ = t;
      valve_ = Valve::kSeekClosed;
    }
    if (valve_ == Valve::kSeekClosed && x <= closed_at) {
      closing_s_ = t - t_fall_;
      closed_ = true;
      valve_ = Valve::kDone;
    }
  }
  gate_prev_ = gate;
}

Metrics MetricsAccumulator::Finish() const {
  Metrics m;
  if (count_ == 0) {
    for (auto* f : {&m.rmse, &m.iae, &m.max_abs_error, &m.overshoot, &m.settling_time_s, &m.effort_l2,
                    &m.effort_rms, &m.energy_J, &m.mean_current_A, &m.opening_delay_s, &m.closing_delay_s,
                    &m.mean_position_m, &m.mean_position_pct, &m.mean_flow_kg_per_s,
                    &m.switching_rate_Hz, &m.diode_loss_W, &m.switching_loss_W, &m.driver_loss_W, &m.effort_u_l2,
                    &m.pwm_frequency_Hz, &m.pwm_duty, &m.ripple_pp_A, &m.ripple_mid_A})
      *f = kNaN;
    return m;
  }
  const double dt = dt_;
  const double inv_n = 1.0 / static_cast<double>(count_);

  // Effort, energy, wear.
  m.effort_l2 = std::sqrt(v2_ * dt);
  m.effort_rms = std::sqrt(v2_ * inv_n);
  m.energy_J = p_ * dt;
  m.switches = switches_;
  // Prefer the bench's exact running integrals: sampled sums cannot see a PWM faster than the sample rate.
  const bool exact = has_exact_ && std::isfinite(v2int_last_) && count_ > 1;
  if (exact) {
    const double span_s = t_last_ - t_first_;
    const double v2_exact = v2int_last_ - v2int_first_;
    m.effort_l2 = std::sqrt(std::max(0.0, v2_exact));
    m.effort_rms = std::sqrt(std::max(0.0, v2_exact) / span_s);
    m.energy_J = eint_last_ - eint_first_;
    m.switches = sw_last_ - sw_first_;
  }
  m.mean_current_A = isum_ * inv_n;
  m.effort_u_l2 = m.pwm_frequency_Hz = m.pwm_duty = kNaN;  // the Runner's (it sees the law)

  // Switching rate and the driver's losses (docs/metrics.md, "Effort per experiment kind").
  const double window_s = exact ? t_last_ - t_first_ : static_cast<double>(count_) * dt;
  m.switching_rate_Hz = window_s > 0 ? m.switches / window_s : kNaN;
  FillDriverLosses(&m, driver_, window_s);
  // Ripple of an open-loop PWM run (seed 003 eqs. 10-11): peak-to-peak and mid-range of the current.
  m.ripple_pp_A = m.ripple_mid_A = kNaN;
  if (cv_ == ControlledVariable::kNone) {
    m.ripple_pp_A = i_hi_ - i_lo_;
    m.ripple_mid_A = 0.5 * (i_hi_ + i_lo_);
  }

  // Tracking.
  if (cv_ == ControlledVariable::kNone || std::isnan(ref_first_)) {
    m.rmse = m.iae = m.max_abs_error = m.overshoot = m.settling_time_s = kNaN;
  } else {
    m.rmse = std::sqrt(e2_ * inv_n);
    m.iae = ea_ * dt;
    m.max_abs_error = emax_;
    const double r_end = ref_last_;
    const double span = std::abs(r_end - y0_);
    m.overshoot = span > 0 ? std::max(0.0, (ymax_ - r_end) / span) : 0.0;
    // The band was the hint's; a window that ended at another reference has no settling time to report.
    m.settling_time_s = r_end == hint_ref_ || BandOf(r_end) == hint_band_ ? settle_ : kNaN;
    // A step response only when the window starts away from the final set-point (more than 10 % of it):
    // then overshoot and settling time mean something and max |e| is just the step. A window that starts at
    // the set-point (a hold) has no overshoot or settling, and its max |e| is the worst excursion
    // (docs/metrics.md "Which metrics apply").
    const bool step_response = span > 0.1 * std::abs(r_end);
    if (step_response) {
      m.max_abs_error = kNaN;
    } else {
      m.overshoot = m.settling_time_s = kNaN;
    }
  }

  // Valve.
  if (std::isnan(x_first_) || !(x_max_m_ > x_min_m_)) {
    m.opening_delay_s = m.closing_delay_s = m.mean_position_m = m.mean_position_pct = m.mean_flow_kg_per_s = kNaN;
  } else {
    m.mean_position_m = xs_ * inv_n;
    m.mean_position_pct = 100.0 * m.mean_position_m / x_max_m_;
    m.mean_flow_kg_per_s = fs_ * inv_n;
    m.opening_delay_s = opened_ ? opening_s_ : kNaN;
    m.closing_delay_s = closed_ ? closing_s_ : kNaN;
  }
  return m;
}

void FillDriverLosses(Metrics* mp, const DriverLossInputs& driver, double window_s) {
  Metrics& m = *mp;
  m.diode_loss_W = m.switching_loss_W = m.driver_loss_W = kNaN;
  if (driver.low_side_flyback && std::isfinite(driver.supply_V) && std::isfinite(driver.diode_drop_V) &&
      driver.supply_V > 0 && window_s > 0) {
    const double vs = driver.supply_V, vd = driver.diode_drop_V;
    // Charge through the coil, Q = Q_on + Q_off, and energy into it, E = V_s Q_on - V_d Q_off (the switch puts
    // V_s on the coil, the freewheeling diode -V_d, and no current flows otherwise): Q_off = (V_s Q - E)/(V_s + V_d).
    const double q_C = m.mean_current_A * window_s;
    const double q_off_C = std::max(0.0, (vs * q_C - m.energy_J) / (vs + vd));
    m.diode_loss_W = vd * q_off_C / window_s;
    // Mohan, Undeland, Robbins, Power Electronics (3rd ed.) eq. 2-6, P_s = 1/2 V I f_s (t_c(on) + t_c(off)),
    // per edge: the switch blocks V_s + V_d while the diode conducts; |i| at the edges is the window's mean
    // current (turn-on at the ripple's troughs, turn-off at its peaks: they average to the mean).
    m.switching_loss_W =
        0.5 * (vs + vd) * std::abs(m.mean_current_A) * driver.switch_transition_s * m.switching_rate_Hz;
    m.driver_loss_W = m.diode_loss_W + m.switching_loss_W;
  }
}

Metrics ComputeMetrics(const Trace& tr, ControlledVariable cv, double start_s, double end_s, double x_min_m,
                       double x_max_m, const DriverLossInputs& driver) {
  // The reference at the window's last sample: the settling band (MetricsAccumulator), exact for a whole trace.
  double final_ref = kNaN;
  for (size_t k = tr.size(); k-- > 0;) {
    if (tr.t_s[k] < start_s - kTimeSlack_s) break;
    if (tr.t_s[k] <= end_s + kTimeSlack_s) {
      final_ref = At(tr.ref, k);
      break;
    }
  }
  MetricsAccumulator acc(cv, start_s, end_s, x_min_m, x_max_m, driver, final_ref);
  acc.Add(tr);
  return acc.Finish();
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
          {"mean_flow_kg_per_s", m.mean_flow_kg_per_s},
          {"switching_rate_Hz", m.switching_rate_Hz},
          {"diode_loss_W", m.diode_loss_W},
          {"switching_loss_W", m.switching_loss_W},
          {"driver_loss_W", m.driver_loss_W},
          {"effort_u_l2", m.effort_u_l2},
          {"pwm_frequency_Hz", m.pwm_frequency_Hz},
          {"pwm_duty", m.pwm_duty},
          {"ripple_pp_A", m.ripple_pp_A},
          {"ripple_mid_A", m.ripple_mid_A}};
}

}  // namespace vb::experiment
