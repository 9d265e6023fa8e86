#include "model/simulator.h"

#include <algorithm>
#include <cmath>

namespace vb::model {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
// Two instants closer than this are the same instant (sample grid vs. edges computed in floating point).
constexpr double kSameInstant_s = 1e-12;

}  // namespace

const char* EventKindName(EventKind kind) {
  switch (kind) {
    case EventKind::kLift: return "lift";
    case EventKind::kOpen: return "open";
    case EventKind::kRelease: return "release";
    case EventKind::kClose: return "close";
    case EventKind::kCurrentZero: return "izero";
    case EventKind::kDriverSwitch: return "driver";
    case EventKind::kStick: return "stick";
    case EventKind::kSlip: return "slip";
  }
  return "?";
}

Simulator::Simulator(const Plant& plant, const DriverParams& driver, const Conditions& conditions,
                     const SolverOptions& options)
    : plant_(plant),
      driver_(driver),
      cond_(conditions),
      opt_(options),
      stepper_(boost::numeric::odeint::make_dense_output(options.abs_tol, options.rel_tol, options.max_step_s,
                                                         boost::numeric::odeint::runge_kutta_dopri5<State>())) {
  const PlantParams& p = plant_.params();
  x_lo_ = p.has_moving_part ? p.x_min_m : 0.0;
  x_hi_ = p.has_moving_part ? p.x_max_m : 0.0;
  x_scale_ = x_hi_ > x_lo_ ? x_hi_ - x_lo_ : 1.0;
  inv_x_scale_ = 1.0 / x_scale_;
  v_scale_ = x_scale_ / 1e-3;  // velocity in units of "full travel per millisecond"
  inv_v_scale_ = 1.0 / v_scale_;
  Reset();
}

void Simulator::Reset() {
  t_ = 0.0;
  i_ = 0.0;
  x_ = x_lo_;
  v_ = 0.0;
  v2_int_ = vi_int_ = 0.0;
  switches_ = 0;
  const Effects& fx = plant_.params().effects;
  dT_ = fx.heating ? fx.heating_dT0_K : 0.0;
  sensor_y_ = sensor_prev_i_ = 0.0;
  sensor_prev_t_ = -1.0;
  sensor_head_ = sensor_count_ = 0;
  last_reading_ = 0.0;
  im_ = fx.residual_w_A > 0.0 ? fx.residual_im0_A : 0.0;
  play_ = Play::kInside;
  general_ = fx.NeedsGeneralPath() || dist_.active();
  gate_ = 0;
  contact_ = Contact::kLower;
  blocked_ = true;
  t_gate_change_s_ = 0.0;
  chopper_started_ = false;
  chopper_on_ = false;
  next_sample_ = 0;
  stepper_valid_ = false;
  dt_guess_s_ = 1e-6;
  ode_steps_ = 0;
  restarts_ = 0;
  failure_ = nullptr;
  failure_t_s_ = 0.0;
  work_ = 0;
  tiny_steps_ = 0;
  stalled_pieces_ = 0;
}

void Simulator::SetWatchdog(std::uint64_t max_work, std::chrono::steady_clock::time_point deadline) {
  opt_.max_work = max_work;
  opt_.deadline = deadline;
  work_ = 0;
}

void Simulator::Fail(const char* why) {
  if (failure_ != nullptr) return;
  failure_ = why;
  failure_t_s_ = t_;
}

bool Simulator::CheckWatchdog() {
  ++work_;
  if (opt_.max_work > 0 && work_ > opt_.max_work) {
    Fail("the step budget ran out (SolverOptions::max_work)");
    return false;
  }
  // The clock is read at the first unit of work and every 256 after: a vDSO call, cheap, no allocation.
  if ((work_ & 255u) == 1 && opt_.deadline != std::chrono::steady_clock::time_point::max() &&
      std::chrono::steady_clock::now() > opt_.deadline) {
    Fail("the wall-clock deadline passed");
    return false;
  }
  return true;
}

void Simulator::SetSamplePeriod(double period_s) {
  sample_period_s_ = period_s > 0.0 ? period_s : 0.0;
  // The sensor latency's history (outside the loop: no allocation while it runs).
  const double delay = plant_.params().effects.sensor_delay_s;
  sensor_hist_.assign(sample_period_s_ > 0.0 && delay > 0.0
                          ? static_cast<std::size_t>(std::ceil(delay / sample_period_s_)) + 3
                          : 1,
                      0.0);
  sensor_head_ = sensor_count_ = 0;
  next_sample_ = sample_period_s_ > 0.0 ? static_cast<std::int64_t>(std::ceil(t_ / sample_period_s_ - 1e-9)) : 0;
}

void Simulator::SetGate(int gate) {
  if (gate == gate_) return;
  gate_ = gate;
  ++switches_;
  t_gate_change_s_ = t_;
  chopper_started_ = false;
  if (gate != 0) blocked_ = false;
  stepper_valid_ = false;
}

void Simulator::SetConditions(const Conditions& conditions) {
  cond_ = conditions;
  stepper_valid_ = false;
}

void Simulator::SetDisturbance(const Disturbance& disturbance) {
  dist_ = disturbance;
  general_ = plant_.params().effects.NeedsGeneralPath() || dist_.active();
  stepper_valid_ = false;
}

double Simulator::ResistanceAt(double dT) const {
  const Effects& fx = plant_.params().effects;
  const double R = plant_.params().R_ohm;
  return fx.heating ? R * (1.0 + fx.heating_alpha_per_K * dT) : R;
}

// The coil as the driver and the sensor see it. Without eddy currents the terminal current is the magnetising
// current. With a loss resistance R_p across the magnetising inductance (one eddy branch):
//   v_source - R_s i = R i + v_L,  i = i_mag + v_L / R_p   =>   v_L = (v_source - (R + R_s) i_mag) / (1 + (R + R_s)/R_p)
// and with the switch and the diode both off (blocked) the terminal current is 0 and i_mag decays through
// R_p: v_L = -R_p i_mag.
Simulator::Terminal Simulator::TerminalAt(const Segment& seg, double t, double i_mag, double dT) const {
  const Effects& fx = plant_.params().effects;
  if (!fx.any()) {  // the nominal coil: the hot path of every integrated piece
    Terminal out;
    out.i_A = seg.blocked ? 0.0 : i_mag;
    out.v_V = seg.blocked ? 0.0 : SegmentVoltage(seg, t) + DisturbanceVoltage(t);
    out.vL_V = out.v_V - plant_.params().R_ohm * out.i_A;
    return out;
  }
  const double R = ResistanceAt(dT);
  const double Rs = seg.from_supply ? fx.supply_R_ohm : 0.0;
  Terminal out;
  if (seg.blocked) {
    out.i_A = 0.0;
    out.vL_V = fx.eddy_R_p_ohm > 0.0 ? -fx.eddy_R_p_ohm * i_mag : 0.0;
    out.v_V = out.vL_V;
    return out;
  }
  const double v0 = SegmentVoltage(seg, t) + DisturbanceVoltage(t);
  if (fx.eddy_R_p_ohm > 0.0) {
    const double Rser = R + Rs;
    out.vL_V = (v0 - Rser * i_mag) / (1.0 + Rser / fx.eddy_R_p_ohm);
    out.i_A = i_mag + out.vL_V / fx.eddy_R_p_ohm;
  } else {
    out.i_A = i_mag;
    out.vL_V = v0 - (R + Rs) * i_mag;
  }
  out.v_V = v0 - Rs * out.i_A;
  return out;
}

Simulator::Magnetics Simulator::MagneticsAt(double i, double x) const {
  double L, dLdx;
  plant_.InductanceAndSlope(x, &L, &dLdx);
  Magnetics m;
  const double B_sat = plant_.params().effects.saturation_B_T;
  if (B_sat <= 0.0) {  // linear: lambda = L(x) i
    m.dlambda_di = L;
    m.dlambda_dx = dLdx * i;
    m.force_N = 0.5 * i * i * dLdx;
    return m;
  }
  // A saturating core in parallel with the air path it can never lose (the core at mu_r -> 1):
  //   lambda = ls f(u) + La i,   u = Lc i / ls,   La = L / mu_r,  Lc = L - La,  ls = N A_e B_sat
  // with the knee f Frohlich's f(u) = u / (1 + |u|) (the classic magnetisation-curve fit, a gradual knee) or
  // tanh(u) (a sharp one); both give lambda = L i at small currents. Co-energy W' = ls^2/Lc G(u) + La i^2 / 2,
  // G' = f (Frohlich: G = |u| - ln(1 + |u|); tanh: G = ln cosh u), so at constant i
  //   F = dW'/dx = (dLc/dx) (ls i f(u) / Lc - ls^2 / Lc^2 G(u)) + (dLa/dx) i^2 / 2.
  // The air path keeps the incremental inductance >= La: deep saturation stays physical and non-stiff.
  const PlantParams& pp = plant_.params();
  const double air = pp.law == InductanceLaw::kReluctance ? 1.0 / std::max(pp.mu_r, 1.0) : 0.01;
  const double La = air * L, Lc = L - La, dLa = air * dLdx, dLc = dLdx - dLa;
  const double ls = pp.N_turns * pp.A_e_m2 * B_sat;
  const double u = Lc * i / ls;
  const double au = std::abs(u);
  double f, df, G;
  if (pp.effects.saturation_tanh >= 0.5) {
    f = std::tanh(u);
    df = 1.0 - f * f;
    G = au + std::log1p(std::exp(-2.0 * au)) - M_LN2;  // ln cosh u, stable for large |u|
  } else {
    f = u / (1.0 + au);
    df = 1.0 / ((1.0 + au) * (1.0 + au));
    G = au - std::log1p(au);
  }
  m.dlambda_di = Lc * df + La;
  m.dlambda_dx = (dLc * df + dLa) * i;
  m.force_N = dLc * (ls * i * f / Lc - ls * ls / (Lc * Lc) * G) + 0.5 * dLa * i * i;
  return m;
}

double Simulator::NetForceAtRest_N(double j, double x, double t) const {
  return MagneticsAt(j, x).force_N + plant_.PassiveForce_N(x, cond_.supply_pressure_Pa) + DisturbanceForce(t);
}

double Simulator::FluxCurrent(double i, double i_m) const {
  const Effects& fx = plant_.params().effects;
  if (fx.residual_w_A <= 0.0) return i;
  return fx.residual_alpha * i + (1.0 - fx.residual_alpha) * i_m;
}

void Simulator::Rhs(const Segment& seg, const State& y, State& dy, double t) const {
  const Effects& fx = plant_.params().effects;
  const PlantParams& pp = plant_.params();
  double i, x, v;
  Unscale(y, &i, &x, &v);
  const Terminal term = TerminalAt(seg, t, i, y[5]);
  // dlambda/dt = v_L with lambda = lambda(j, x), j the flux-equivalent current (= i without hysteresis):
  //   (dlambda/dj)(dj/di) di/dt = v_L - (dlambda/dx) v          (seed 000 eq. 7 for the linear law)
  const double j = FluxCurrent(i, y[6]);
  const Magnetics mag = MagneticsAt(j, x);
  const double dj_di = fx.residual_w_A > 0.0 && play_ == Play::kInside ? fx.residual_alpha : 1.0;
  dy[0] = (term.vL_V - mag.dlambda_dx * (frozen_ ? 0.0 : v)) / (mag.dlambda_di * dj_di);
  dy[3] = term.v_V * term.v_V;
  dy[4] = term.v_V * term.i_A;
  dy[5] = 0.0;
  dy[6] = fx.residual_w_A > 0.0 && play_ != Play::kInside ? dy[0] : 0.0;
  if (fx.heating)
    dy[5] = (term.i_A * term.i_A * ResistanceAt(y[5]) - y[5] / fx.heating_R_th_K_per_W) / fx.heating_C_th_J_per_K;
  if (frozen_) {
    dy[1] = 0.0;
    dy[2] = 0.0;
  } else {
    dy[1] = v * inv_x_scale_;
    const double force = mag.force_N + plant_.PassiveForce_N(x, cond_.supply_pressure_Pa) + DisturbanceForce(t) -
                         pp.b_N_s_per_m * v - fx.friction_F_c_N * free_dir_;
    dy[2] = force / pp.m_kg * inv_v_scale_;
  }
}

double Simulator::measured_current_A() const {
  const Effects& fx = plant_.params().effects;
  if ((fx.sensor_tau_s > 0.0 || fx.sensor_delay_s > 0.0) && sensor_prev_t_ >= 0.0) return SenseChain(last_reading_);
  if (fx.eddy_R_p_ohm > 0.0) {
    Simulator* self = const_cast<Simulator*>(this);  // CurrentSegment() only normalises driver bookkeeping
    return SenseChain(TerminalAt(self->CurrentSegment(), t_, i_, dT_).i_A);
  }
  return SenseChain(i_);
}

double Simulator::SenseChain(double i_A) const {
  const Effects& fx = plant_.params().effects;
  return fx.sensor_gain * i_A + fx.sensor_offset_A;
}

void Simulator::SetCoilCurrent(double i_A) {
  i_ = std::max(i_A, 0.0);
  if (i_ > 0.0) blocked_ = false;
  stepper_valid_ = false;
}

double Simulator::SensorReading(double t, double i_true) const {
  const Effects& fx = plant_.params().effects;
  if (fx.sensor_tau_s <= 0.0 && fx.sensor_delay_s <= 0.0) return SenseChain(i_true);
  // First-order lag, exact for a current linear between samples (first-order hold):
  //   y_k = a y_(k-1) + (1 - a) i_(k-1) + (i_k - i_(k-1)) (1 - tau (1 - a) / h),   a = exp(-h / tau)
  if (sensor_prev_t_ < 0.0 || fx.sensor_tau_s <= 0.0) {
    sensor_y_ = i_true;
  } else {
    const double h = t - sensor_prev_t_;
    if (h > 0.0) {
      const double tau = fx.sensor_tau_s;
      const double a = std::exp(-h / tau);
      sensor_y_ = a * sensor_y_ + (1.0 - a) * sensor_prev_i_ + (i_true - sensor_prev_i_) * (1.0 - tau * (1.0 - a) / h);
    }
  }
  sensor_prev_i_ = i_true;
  sensor_prev_t_ = t;
  double out = sensor_y_;
  if (fx.sensor_delay_s > 0.0 && sample_period_s_ > 0.0) {
    // Latency: the lagged reading delay_s ago, interpolated between the samples around it (0 before the run).
    const std::size_t cap = sensor_hist_.size();
    sensor_hist_[sensor_head_] = sensor_y_;
    sensor_head_ = (sensor_head_ + 1) % cap;
    sensor_count_ = std::min(sensor_count_ + 1, cap);
    const double back = fx.sensor_delay_s / sample_period_s_;
    const auto k0 = static_cast<std::size_t>(std::floor(back));
    const double frac = back - static_cast<double>(k0);
    auto at = [&](std::size_t ago) {  // the reading `ago` samples back; before the first sample: 0
      if (ago >= sensor_count_) return 0.0;
      return sensor_hist_[(sensor_head_ + cap - 1 - ago) % cap];
    };
    out = (1.0 - frac) * at(k0) + frac * at(k0 + 1);
  }
  last_reading_ = out;
  return SenseChain(out);
}

Simulator::State Simulator::CurrentState() const {
  State y = Scale(i_, x_, v_);
  return y;
}

double Simulator::DisturbanceVoltage(double t) const {
  if (dist_.voltage_V == 0.0) return 0.0;
  return dist_.frequency_Hz > 0.0 ? dist_.voltage_V * std::sin(2.0 * M_PI * dist_.frequency_Hz * t) : dist_.voltage_V;
}

double Simulator::DisturbanceForce(double t) const {
  if (dist_.force_N == 0.0) return 0.0;
  return dist_.frequency_Hz > 0.0 ? dist_.force_N * std::sin(2.0 * M_PI * dist_.frequency_Hz * t) : dist_.force_N;
}

Simulator::Segment Simulator::CurrentSegment() {
  Segment s;
  const double supply = cond_.supply_V;
  const double drop = driver_.diode_drop_V;
  const bool eddy = plant_.params().effects.eddy_R_p_ohm > 0.0;
  auto freewheel_or_block = [&](double v_if_positive) {
    if (blocked_ || i_ <= 0.0) {
      blocked_ = true;
      if (!eddy) i_ = 0.0;
      s.blocked = true;
    } else {
      s.v0_V = v_if_positive;
      s.clamp = +1;
    }
  };
  switch (driver_.kind) {
    case DriverKind::kLowSideFlyback:
      if (gate_ == 1) {
        s.v0_V = supply;
        s.from_supply = true;
      } else {
        freewheel_or_block(-drop);
      }
      break;
    case DriverKind::kHBridge:
      if (gate_ == 1) {
        s.v0_V = supply;
        s.from_supply = true;
      } else if (gate_ == -1) {
        s.v0_V = -supply;
        s.from_supply = true;
      } else if (!blocked_ && i_ > 0.0) {
        s.v0_V = -(supply + 2.0 * drop);
        s.clamp = +1;
      } else if (!blocked_ && i_ < 0.0) {
        s.v0_V = supply + 2.0 * drop;
        s.clamp = -1;
      } else {
        blocked_ = true;
        if (!eddy) i_ = 0.0;
        s.blocked = true;
      }
      break;
    case DriverKind::kInternalElectronics: {
      if (gate_ == 1) {
        const double boost_end = t_gate_change_s_ + driver_.boost_time_s;
        if (t_ < boost_end - kSameInstant_s) {
          s.v0_V = supply;
          s.from_supply = true;
          s.t_end_s = boost_end;
          break;
        }
        const double lo = driver_.hold_current_A - 0.5 * driver_.hold_band_A;
        const double hi = driver_.hold_current_A + 0.5 * driver_.hold_band_A;
        if (!chopper_started_) {
          chopper_started_ = true;
          chopper_on_ = i_ < lo;
        }
        if (!chopper_on_ && (blocked_ || i_ <= 0.0)) chopper_on_ = true;
        if (chopper_on_) {
          blocked_ = false;
          s.v0_V = supply;
          s.from_supply = true;
          s.level_A = hi;
          s.level_dir = +1;
        } else {
          s.v0_V = -drop;
          s.clamp = +1;
          s.level_A = lo;
          s.level_dir = -1;
        }
      } else {
        // Reverse voltage from the capacitor, decaying from the gate's falling edge.
        if (blocked_ || i_ <= 0.0) {
          blocked_ = true;
          if (!eddy) i_ = 0.0;
          s.blocked = true;
        } else {
          s.v0_V = -driver_.reverse_V;
          s.tau_s = driver_.reverse_tau_s;
          s.t_origin_s = t_gate_change_s_;
          s.clamp = +1;
        }
      }
      break;
    }
  }
  return s;
}

double Simulator::SegmentVoltage(const Segment& seg, double t) const {
  if (seg.blocked) return 0.0;
  if (seg.tau_s > 0.0) return seg.v0_V * std::exp(-(t - seg.t_origin_s) / seg.tau_s);
  return seg.v0_V;
}

void Simulator::EmitSample(const Segment& /*seg*/, double t, double i_meas, double v_term, double x, double v,
                           double v2_int, double vi_int, SimObserver* obs) const {
  PlantSample s;
  s.t_s = t;
  s.gate = static_cast<std::int8_t>(gate_);
  s.v_coil_V = v_term;
  s.i_A = SensorReading(t, i_meas);
  s.x_m = x;
  s.v_mps = v;
  s.v2_integral_V2s = v2_int;
  s.energy_J = vi_int;
  s.switches = switches_;
  obs->OnSample(s);
}

void Simulator::EmitPendingSample(SimObserver* observer) {
  if (sample_period_s_ <= 0.0 || observer == nullptr) return;
  if (SampleTime(next_sample_) <= t_ + kSameInstant_s) {
    Segment seg = CurrentSegment();
    const Terminal term = TerminalAt(seg, t_, i_, dT_);
    EmitSample(seg, SampleTime(next_sample_), term.i_A, term.v_V, x_, v_, v2_int_, vi_int_, observer);
    ++next_sample_;
  }
}

void Simulator::CheckStopRelease(SimObserver* obs) {
  if (!plant_.has_moving_part() || contact_ == Contact::kFree) return;
  const double f = NetForceAtRest_N(FluxCurrent(i_, im_), x_, t_);
  const double fs = plant_.params().effects.friction_F_s_N;  // static friction: 0 for the nominal model
  EventKind kind;
  if (contact_ == Contact::kLower && f > fs) {
    kind = EventKind::kLift;
  } else if (contact_ == Contact::kUpper && f < -fs) {
    kind = EventKind::kRelease;
  } else if (contact_ == Contact::kStuck && std::abs(f) > fs) {
    kind = EventKind::kSlip;
  } else {
    return;
  }
  contact_ = Contact::kFree;
  v_ = 0.0;
  stepper_valid_ = false;
  if (obs) obs->OnEvent(kind, t_, i_, x_, v_);
}

void Simulator::AdvanceTo(double t_end_s, SimObserver* observer) {
  while (t_ < t_end_s && failure_ == nullptr) {
    const double t_before = t_;
    CheckStopRelease(observer);
    const Segment seg = CurrentSegment();
    const double t_stop = std::min(t_end_s, seg.t_end_s);
    if (contact_ != Contact::kFree && seg.tau_s == 0.0 && !general_) {
      AdvanceClosedForm(seg, t_stop, observer);
    } else {
      AdvanceOde(seg, t_stop, observer);
    }
    if (seg.t_end_s < kInf && t_ >= seg.t_end_s - kSameInstant_s) {
      t_ = std::max(t_, seg.t_end_s);
      stepper_valid_ = false;
      if (observer) observer->OnEvent(EventKind::kDriverSwitch, t_, i_, x_, v_);
    }
    if (!std::isfinite(i_) || !std::isfinite(x_) || !std::isfinite(v_) || !std::isfinite(dT_) || !std::isfinite(t_)) {
      Fail("the state is not finite (a non-physical parameter or input?)");
      return;
    }
    stalled_pieces_ = t_ > t_before ? 0 : stalled_pieces_ + 1;
    if (stalled_pieces_ > 100000) {
      Fail("events repeat at one instant (the simulation cannot advance)");
      return;
    }
    if (!CheckWatchdog()) return;
  }
}

void Simulator::AdvanceClosedForm(const Segment& seg, double t_stop, SimObserver* obs) {
  stepper_valid_ = false;
  const double t0 = t_;
  if (seg.blocked) {
    if (sample_period_s_ > 0.0 && obs) {
      for (double tk = SampleTime(next_sample_); tk < t_stop - kSameInstant_s; tk = SampleTime(++next_sample_))
        EmitSample(seg, tk, 0.0, 0.0, x_, 0.0, v2_int_, vi_int_, obs);
    }
    t_ = t_stop;
    return;
  }
  // The coil with the source resistance in series (supply_resistance), at a fixed position: linear.
  const double Rs = seg.from_supply ? plant_.params().effects.supply_R_ohm : 0.0;
  const double R = plant_.params().R_ohm + Rs;
  const double tau = plant_.L_H(x_) / R;
  const double i_inf = seg.v0_V / R;
  const double d0 = i_ - i_inf;

  double best_t = t_stop;
  Ev best_ev = Ev::kNone;
  double best_level = 0.0;
  // The exponential moves monotonically from i0 towards i_inf: level c is reached iff it lies strictly between.
  auto consider = [&](double c, Ev ev) {
    if (d0 == 0.0) return;
    const double r = (c - i_inf) / d0;
    if (!(r > 0.0 && r < 1.0)) return;
    const double t = t0 - tau * std::log(r);
    if (t < best_t) {
      best_t = t;
      best_ev = ev;
      best_level = c;
    }
  };
  if (seg.clamp != 0) consider(0.0, Ev::kClamp);
  if (seg.level_dir != 0) consider(seg.level_A, Ev::kLevel);
  if (plant_.has_moving_part()) {
    const double i_bal = plant_.BalanceCurrent_A(x_, cond_.supply_pressure_Pa);
    if (i_bal > 0.0) {
      // At the lower stop the spool lifts when |i| rises above i_bal; at the upper stop it leaves when |i|
      // falls below it. consider() keeps only levels the exponential actually crosses.
      if (contact_ == Contact::kLower) {
        if (std::abs(i_) < i_bal) {
          consider(i_bal, Ev::kLeaveStop);
          consider(-i_bal, Ev::kLeaveStop);
        }
      } else if (std::abs(i_) > i_bal) {
        consider(i_ > 0.0 ? i_bal : -i_bal, Ev::kLeaveStop);
      }
    }
  }

  // Exact integrals over [t0, t] of the terminal voltage v = v0 - Rs i, with i = i_inf + d0 e^{-(t-t0)/tau}:
  //   int i = i_inf dt + d0 tau (1 - e),  int i^2 = i_inf^2 dt + 2 i_inf d0 tau (1 - e) + d0^2 tau/2 (1 - e^2)
  const double v0 = seg.v0_V;
  auto int_i = [&](double dt, double e) { return i_inf * dt + d0 * tau * (1.0 - e); };
  auto int_i2 = [&](double dt, double e) {
    return i_inf * i_inf * dt + 2.0 * i_inf * d0 * tau * (1.0 - e) + d0 * d0 * 0.5 * tau * (1.0 - e * e);
  };
  auto v2_at = [&](double dt, double e) {
    return v2_int_ + v0 * v0 * dt - 2.0 * v0 * Rs * int_i(dt, e) + Rs * Rs * int_i2(dt, e);
  };
  auto vi_at = [&](double dt, double e) { return vi_int_ + v0 * int_i(dt, e) - Rs * int_i2(dt, e); };
  if (sample_period_s_ > 0.0 && obs) {
    const double limit = best_t - kSameInstant_s;
    if (Rs == 0.0) {  // the nominal coil: v is constant, so the integrals need no i^2 term
      for (double tk = SampleTime(next_sample_); tk < limit; tk = SampleTime(++next_sample_)) {
        const double dt = tk - t0, e = std::exp(-dt / tau);
        EmitSample(seg, tk, i_inf + d0 * e, v0, x_, 0.0, v2_int_ + v0 * v0 * dt, vi_int_ + v0 * int_i(dt, e), obs);
      }
    } else {
      for (double tk = SampleTime(next_sample_); tk < limit; tk = SampleTime(++next_sample_)) {
        const double dt = tk - t0, e = std::exp(-dt / tau);
        const double i = i_inf + d0 * e;
        EmitSample(seg, tk, i, v0 - Rs * i, x_, 0.0, v2_at(dt, e), vi_at(dt, e), obs);
      }
    }
  }
  const double dt_end = best_t - t0, e_end = std::exp(-dt_end / tau);
  v2_int_ = v2_at(dt_end, e_end);
  vi_int_ = vi_at(dt_end, e_end);
  t_ = best_t;
  i_ = best_ev != Ev::kNone ? best_level : i_inf + d0 * e_end;
  if (best_ev != Ev::kNone) ApplyEvent(best_ev, seg, obs);
}

double Simulator::EventFunction(Ev ev, const Segment& seg, double t, const State& y) const {
  double i, x, v;
  Unscale(y, &i, &x, &v);
  switch (ev) {
    case Ev::kUpper: return (x_hi_ - x) * inv_x_scale_;
    case Ev::kLower: return (x - x_lo_) * inv_x_scale_;
    case Ev::kLeaveStop: {
      const double f = NetForceAtRest_N(FluxCurrent(i, y[6]), x_, t);
      const double fs = plant_.params().effects.friction_F_s_N;
      if (contact_ == Contact::kLower) return fs - f;
      if (contact_ == Contact::kUpper) return f + fs;
      return fs - std::abs(f);  // kStuck
    }
    case Ev::kVelocityZero: return free_dir_ * v;
    // residual_magnetism's play: a band edge reached (inside), or the current turning (on an edge).
    case Ev::kPlayUpper: return y[6] - (i - plant_.params().effects.residual_w_A);
    case Ev::kPlayLower: return (i + plant_.params().effects.residual_w_A) - y[6];
    case Ev::kPlayTurn: {
      State dy;
      Rhs(seg, y, dy, t);
      return play_ == Play::kRising ? dy[0] : -dy[0];
    }
    // The diode and the chopper act on the terminal current.
    case Ev::kClamp: return seg.clamp * TerminalAt(seg, t, i, y[5]).i_A;
    case Ev::kLevel: return seg.level_dir * (seg.level_A - TerminalAt(seg, t, i, y[5]).i_A);
    case Ev::kNone: break;
  }
  return 1.0;
}

void Simulator::AdvanceOde(const Segment& seg, double t_stop, SimObserver* obs) {
  const bool frozen = contact_ != Contact::kFree;
  const Effects& fx = plant_.params().effects;
  frozen_ = frozen;
  const Simulator& self = *this;
  auto rhs = [&self, &seg](const State& y, State& dy, double t) { self.Rhs(seg, y, dy, t); };

  if (!stepper_valid_) {
    // Kinetic friction opposes the motion; from rest, the motion the net force starts.
    if (!frozen)
      free_dir_ = v_ != 0.0 ? (v_ > 0.0 ? 1.0 : -1.0) : (NetForceAtRest_N(FluxCurrent(i_, im_), x_, t_) >= 0.0 ? 1.0 : -1.0);
    if (fx.residual_w_A > 0.0) {
      // The play's mode from the state: on an edge only if the current moves outward.
      const double w = fx.residual_w_A;
      play_ = Play::kInside;
      const double tiny = 1e-12;
      im_ = std::clamp(im_, i_ - w, i_ + w);  // the play's output never leaves its band around the input
      if (i_ - w >= im_ - tiny || i_ + w <= im_ + tiny) {
        const bool upper = i_ - w >= im_ - tiny;
        const double im_saved = im_;
        im_ = upper ? i_ - w : i_ + w;
        play_ = upper ? Play::kRising : Play::kFalling;
        State dy;
        Rhs(seg, Scale(i_, x_, v_), dy, t_);
        if ((upper && dy[0] <= 0.0) || (!upper && dy[0] >= 0.0)) {
          play_ = Play::kInside;
          im_ = im_saved;
        }
      }
    }
    stepper_.initialize(Scale(i_, x_, v_), t_, std::min(dt_guess_s_, opt_.max_step_s));
    ode_piece_v2_ = v2_int_;
    ode_piece_vi_ = vi_int_;
    stepper_valid_ = true;
    ++restarts_;
  }

  Ev events[7];
  int n_events = 0;
  if (fx.residual_w_A > 0.0) {
    if (play_ == Play::kInside) {
      events[n_events++] = Ev::kPlayUpper;
      events[n_events++] = Ev::kPlayLower;
    } else {
      events[n_events++] = Ev::kPlayTurn;
    }
  }
  if (frozen) {
    if (plant_.has_moving_part()) events[n_events++] = Ev::kLeaveStop;
  } else {
    events[n_events++] = Ev::kUpper;
    events[n_events++] = Ev::kLower;
    if (fx.friction()) events[n_events++] = Ev::kVelocityZero;
  }
  if (seg.clamp != 0) events[n_events++] = Ev::kClamp;
  if (seg.level_dir != 0) events[n_events++] = Ev::kLevel;

  auto g_at = [&](Ev ev, double t) {
    State y;
    stepper_.calc_state(t, y);
    return EventFunction(ev, seg, t, y);
  };
  // Illinois (modified regula falsi) on the dense output: g(lo) > 0 >= g(hi); returns the first instant
  // with g <= 0, to event_time_tol_s.
  auto locate = [&](Ev ev, double lo, double flo, double hi, double fhi) {
    int side = 0;
    for (int iter = 0; iter < 200 && hi - lo > opt_.event_time_tol_s; ++iter) {
      double m = (lo * fhi - hi * flo) / (fhi - flo);
      if (!(m > lo && m < hi)) m = 0.5 * (lo + hi);
      const double fm = g_at(ev, m);
      if (fm > 0.0) {
        lo = m;
        flo = fm;
        if (side == -1) fhi *= 0.5;
        side = -1;
      } else {
        hi = m;
        fhi = fm;
        if (side == +1) flo *= 0.5;
        side = +1;
      }
    }
    return hi;
  };

  for (;;) {
    if (stepper_.current_time() <= t_ + kSameInstant_s) {
      try {
        stepper_.do_step(rhs);
      } catch (const std::exception&) {
        // Boost.Odeint gives up after 500 rejected step-size adjustments (a NaN or an exploding derivative).
        Fail("the step-size control failed (the state or its derivative is not finite)");
        return;
      }
      ++ode_steps_;
      for (double y : stepper_.current_state()) {
        if (!std::isfinite(y)) {
          Fail("the state is not finite (a non-physical parameter or input?)");
          return;
        }
      }
      // A step that collapses to nothing (a force of 1e308 N, a stiff non-physical parameter) would never reach
      // the end: stop with the reason instead of hanging.
      const double scale = std::max(1e-6, std::abs(stepper_.current_time()));
      tiny_steps_ = stepper_.current_time_step() < 1e-15 * scale ? tiny_steps_ + 1 : 0;
      if (tiny_steps_ > 1000) {
        Fail("the integration stalled: steps below 1e-15 of the time scale (a non-physical input?)");
        return;
      }
      if (!CheckWatchdog()) return;
    }
    const double a = t_;
    const double b = std::min(stepper_.current_time(), t_stop);
    State yb;
    if (b >= stepper_.current_time()) {
      yb = stepper_.current_state();
    } else {
      stepper_.calc_state(b, yb);
    }
    const State ya = CurrentState();
    double best_t = b;
    Ev best_ev = Ev::kNone;
    for (int k = 0; k < n_events; ++k) {
      const Ev ev = events[k];
      const double gb = EventFunction(ev, seg, b, yb);
      if (gb > 0.0) continue;
      double ga = EventFunction(ev, seg, a, ya);
      double lo = a;
      if (!(ga > 0.0)) {
        // Started exactly on the surface (just lifted, released, rebounded): find an instant where it has left
        // it. Probe close to the start first (a short rebound can be over long before the step's end), then
        // across the step.
        bool found = false;
        static constexpr double kProbe[] = {1e-9, 1e-7, 1e-5, 1e-3, 1.0 / 64, 1.0 / 16, 2.0 / 16, 3.0 / 16,
                                            4.0 / 16, 6.0 / 16, 8.0 / 16, 10.0 / 16, 12.0 / 16, 14.0 / 16};
        for (double frac : kProbe) {
          const double tj = a + (b - a) * frac;
          if (!(tj > a)) continue;
          const double gj = g_at(ev, tj);
          if (gj > 0.0) {
            lo = tj;
            ga = gj;
            found = true;
            break;
          }
        }
        if (!found) {
          // Still exactly on the surface (g = 0: nothing moved, e.g. a current held at zero on a play edge):
          // no crossing. Past it at the step's end without ever being measurably off it: it is back on the
          // surface at once (a vanishing rebound). Never let the state pass through a stop.
          // Round-off-level excursions (a spool at rest with zero net force over a few nanoseconds) are not a
          // crossing: the surface functions are O(1), so 1e-9 is far below any real pass (a missed micro-rebound
          // is ~1e-5 of the travel) and far above round-off.
          if (!(gb < -1e-9)) continue;
          if (a < best_t || best_ev == Ev::kNone) {
            best_t = a;
            best_ev = ev;
          }
          continue;
        }
      }
      const double t_ev = locate(ev, lo, ga, b, gb);
      if (t_ev < best_t || (t_ev == best_t && best_ev == Ev::kNone)) {
        best_t = t_ev;
        best_ev = ev;
      }
    }

    if (sample_period_s_ > 0.0 && obs) {
      const double limit = best_t - kSameInstant_s;
      for (double tk = SampleTime(next_sample_); tk < limit; tk = SampleTime(++next_sample_)) {
        State y;
        stepper_.calc_state(tk, y);
        double i, x, v;
        Unscale(y, &i, &x, &v);
        if (seg.blocked && fx.eddy_R_p_ohm == 0.0) i = 0.0;
        const Terminal term = TerminalAt(seg, tk, i, y[5]);
        EmitSample(seg, tk, term.i_A, term.v_V, std::clamp(x, x_lo_, x_hi_), v, ode_piece_v2_ + y[3],
                   ode_piece_vi_ + y[4], obs);
      }
    }

    {
      State y;
      if (best_t >= stepper_.current_time()) {
        y = stepper_.current_state();
      } else {
        stepper_.calc_state(best_t, y);
      }
      Unscale(y, &i_, &x_, &v_);
      v2_int_ = ode_piece_v2_ + y[3];
      vi_int_ = ode_piece_vi_ + y[4];
      dT_ = y[5];
      im_ = y[6];
    }
    t_ = best_t;
    if (seg.blocked && fx.eddy_R_p_ohm == 0.0) i_ = 0.0;
    x_ = std::clamp(x_, x_lo_, x_hi_);
    if (best_ev != Ev::kNone) {
      dt_guess_s_ = stepper_.current_time_step();
      ApplyEvent(best_ev, seg, obs);
      return;
    }
    if (t_ >= t_stop) return;
  }
}

void Simulator::ApplyEvent(Ev ev, const Segment& seg, SimObserver* obs) {
  stepper_valid_ = false;
  EventKind kind = EventKind::kDriverSwitch;
  switch (ev) {
    case Ev::kUpper:
    case Ev::kLower: {
      // Impact. Nominal: perfectly inelastic. end_stop_bounce: rebound with -e v unless slower than v_stick.
      const bool upper = ev == Ev::kUpper;
      const Effects& fx = plant_.params().effects;
      const double rebound = -fx.bounce_e * v_;
      x_ = upper ? x_hi_ : x_lo_;
      kind = upper ? EventKind::kOpen : EventKind::kClose;
      if (fx.bounce_e > 0.0 && std::abs(rebound) > fx.bounce_v_stick_mps) {
        v_ = rebound;
        contact_ = Contact::kFree;
        break;
      }
      v_ = 0.0;
      const double f = NetForceAtRest_N(FluxCurrent(i_, im_), x_, t_);
      contact_ = upper ? (f >= -fx.friction_F_s_N ? Contact::kUpper : Contact::kFree)
                       : (f <= fx.friction_F_s_N ? Contact::kLower : Contact::kFree);
      break;
    }
    case Ev::kLeaveStop:
      kind = contact_ == Contact::kLower   ? EventKind::kLift
             : contact_ == Contact::kUpper ? EventKind::kRelease
                                           : EventKind::kSlip;
      contact_ = Contact::kFree;
      v_ = 0.0;
      break;
    case Ev::kVelocityZero: {
      // Motion stops mid-travel: static friction holds the spool unless the net force exceeds F_s.
      v_ = 0.0;
      const double f = NetForceAtRest_N(FluxCurrent(i_, im_), x_, t_);
      if (std::abs(f) <= plant_.params().effects.friction_F_s_N) {
        contact_ = Contact::kStuck;
        kind = EventKind::kStick;
      } else {
        contact_ = Contact::kFree;  // reverses: the next piece starts in the force's direction
        kind = EventKind::kSlip;
      }
      break;
    }
    case Ev::kClamp:
      // The terminal current reached zero; without an eddy branch that is the whole coil current.
      if (plant_.params().effects.eddy_R_p_ohm == 0.0) i_ = 0.0;
      blocked_ = true;
      kind = EventKind::kCurrentZero;
      break;
    case Ev::kLevel:
      if (plant_.params().effects.eddy_R_p_ohm == 0.0) i_ = seg.level_A;
      chopper_on_ = !chopper_on_;
      kind = EventKind::kDriverSwitch;
      break;
    case Ev::kPlayUpper:
    case Ev::kPlayLower:
    case Ev::kPlayTurn:
      return;  // the play changes mode; the next piece starts in it (nothing to report)
    case Ev::kNone: return;
  }
  if (obs) obs->OnEvent(kind, t_, i_, x_, v_);
}

}  // namespace vb::model
