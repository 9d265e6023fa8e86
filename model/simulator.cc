#include "model/simulator.h"

#include <algorithm>
#include <cmath>

#include <boost/numeric/odeint.hpp>

#include "model/event_locator.h"

namespace vb::model {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// A piece at rest with no current change (a blocked segment: the coil carries nothing).
class FixedPiece final : public PieceView {
 public:
  FixedPiece(double i_A, double x_m) : i_A_(i_A), x_m_(x_m) {}
  void At(double /*t_s*/, double* i_A, double* x_m) const override {
    *i_A = i_A_;
    *x_m = x_m_;
  }

 private:
  double i_A_, x_m_;
};

// The closed-form piece: i = i_inf + d0 exp(-(t - t0)/tau) at a fixed position.
class ExponentialPiece final : public PieceView {
 public:
  ExponentialPiece(const CurrentSensor* sensor, double t0, double i_inf, double d0, double tau, double x_m)
      : sensor_(sensor), t0_(t0), i_inf_(i_inf), d0_(d0), tau_(tau), x_m_(x_m) {}
  void At(double t_s, double* i_A, double* x_m) const override {
    *i_A = sensor_->Static(i_inf_ + d0_ * std::exp(-(t_s - t0_) / tau_));
    *x_m = x_m_;
  }

 private:
  const CurrentSensor* sensor_;
  double t0_, i_inf_, d0_, tau_, x_m_;
};

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

struct Simulator::Ode {
  using Stepper = boost::numeric::odeint::result_of::make_dense_output<
      boost::numeric::odeint::runge_kutta_dopri5<State>>::type;
  explicit Ode(const SolverOptions& o)
      : stepper(boost::numeric::odeint::make_dense_output(o.abs_tol, o.rel_tol, o.max_step_s,
                                                          boost::numeric::odeint::runge_kutta_dopri5<State>())) {
    locator.time_tol_s = o.event_time_tol_s;
  }
  Stepper stepper;
  EventLocatorOptions locator;
};

Simulator::OdeHolder::OdeHolder(const SolverOptions& options) : p_(std::make_unique<Ode>(options)) {}
Simulator::OdeHolder::OdeHolder(const OdeHolder& other)
    : p_(other.p_ ? std::make_unique<Ode>(*other.p_) : nullptr) {}
Simulator::OdeHolder& Simulator::OdeHolder::operator=(const OdeHolder& other) {
  if (this != &other) p_ = other.p_ ? std::make_unique<Ode>(*other.p_) : nullptr;
  return *this;
}
Simulator::OdeHolder::OdeHolder(OdeHolder&& other) noexcept = default;
Simulator::OdeHolder& Simulator::OdeHolder::operator=(OdeHolder&& other) noexcept = default;
Simulator::OdeHolder::~OdeHolder() = default;

Simulator::Simulator(const Plant& plant, const DriverParams& driver, const Conditions& conditions,
                     const SolverOptions& options)
    : plant_(plant),
      driver_(driver),
      cond_(conditions),
      opt_(options),
      sensor_(plant.params().effects),
      ode_(options) {
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
  gate_ = 0;
  pending_head_ = pending_n_ = 0;
  gate_on_before_s_ = gate_on_since_s_ = 0.0;
  const Effects& fx = plant_.params().effects;
  dT_ = fx.heating ? fx.heating_dT0_K : 0.0;
  sensor_.Reset();
  im_ = fx.residual_w_A > 0.0 ? fx.residual_im0_A : 0.0;
  play_ = Play::kInside;
  general_ = fx.NeedsGeneralPath() || dist_.active();
  driver_.Reset();
  contact_ = Contact::kLower;
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
  sensor_.SetSamplePeriod(sample_period_s_);  // sizes the latency's ring: no allocation while the loop runs
  next_sample_ = sample_period_s_ > 0.0 ? static_cast<std::int64_t>(std::ceil(t_ / sample_period_s_ - 1e-9)) : 0;
}

void Simulator::SetGate(int gate) {
  if (gate == gate_) return;
  gate_ = gate;
  ++switches_;
  if (gate_ != 0) gate_on_since_s_ = t_;
  else gate_on_before_s_ += t_ - gate_on_since_s_;
  const double delay_s = plant_.params().effects.driver_delay_s;
  if (delay_s <= 0.0) {
    driver_.SetGate(gate, t_);
    stepper_valid_ = false;
    return;
  }
  if (pending_n_ == pending_.size()) {
    Fail("driver_delay: more gate edges within the delay than the driver can hold (64)");
    return;
  }
  pending_[(pending_head_ + pending_n_) % pending_.size()] = {t_ + delay_s, gate};
  ++pending_n_;
}

// driver_delay: the driver takes each commanded edge whose time has come.
void Simulator::ApplyDueEdges() {
  while (pending_n_ > 0 && pending_[pending_head_].t_s <= t_ + kSameInstant_s) {
    if (driver_.SetGate(pending_[pending_head_].gate, t_)) stepper_valid_ = false;
    pending_head_ = (pending_head_ + 1) % pending_.size();
    --pending_n_;
  }
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

Terminal Simulator::TerminalAt(const Segment& seg, double t, double i_mag, double dT) const {
  const double v_source = seg.blocked ? 0.0 : seg.VoltageAt(t) + DisturbanceVoltage(t);
  return model::TerminalAt(plant_, seg, v_source, i_mag, dT);
}

double Simulator::NetForceAtRest_N(double j, double x, double t) const {
  return MagneticsAt(j, x).force_N + plant_.PassiveForce_N(x, cond_.supply_pressure_Pa) + DisturbanceForce(t);
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
    dy[5] = (term.i_A * term.i_A * model::ResistanceAt(plant_, y[5]) - y[5] / fx.heating_R_th_K_per_W) /
            fx.heating_C_th_J_per_K;
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
  if (sensor_.has_reading()) return sensor_.LastReading_A();
  if (plant_.params().effects.eddy_R_p_ohm > 0.0) {
    // The terminal current now: the driver's segment as it stands (PeekSegment changes nothing).
    const Segment seg = driver_.PeekSegment(SupplyV(), t_, i_);
    return sensor_.Static(TerminalAt(seg, t_, i_, dT_).i_A);
  }
  return sensor_.Static(i_);
}

void Simulator::SetCoilCurrent(double i_A) {
  i_ = std::max(i_A, 0.0);
  if (i_ > 0.0) driver_.Unblock();
  stepper_valid_ = false;
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
  const Segment s = driver_.Segment(SupplyV(), t_, i_);
  if (s.blocked && plant_.params().effects.eddy_R_p_ohm <= 0.0) i_ = 0.0;
  return s;
}

void Simulator::EmitSample(double t, double i_meas, double v_term, double x, double v, double v2_int,
                           double vi_int, SimObserver* obs) {
  PlantSample s;
  s.t_s = t;
  s.gate = static_cast<std::int8_t>(gate_);
  s.v_coil_V = v_term;
  s.i_A = sensor_.Sample(t, i_meas);
  s.x_m = x;
  s.v_mps = v;
  s.v2_integral_V2s = v2_int;
  s.energy_J = vi_int;
  s.switches = switches_;
  s.gate_on_s = gate_on_before_s_ + (gate_ != 0 ? std::max(0.0, t - gate_on_since_s_) : 0.0);
  obs->OnSample(s);
}

void Simulator::EmitPendingSample(SimObserver* observer) {
  if (sample_period_s_ <= 0.0 || observer == nullptr) return;
  if (SampleTime(next_sample_) <= t_ + kSameInstant_s) {
    Segment seg = CurrentSegment();
    const Terminal term = TerminalAt(seg, t_, i_, dT_);
    EmitSample(SampleTime(next_sample_), term.i_A, term.v_V, x_, v_, v2_int_, vi_int_, observer);
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
    ApplyDueEdges();
    CheckStopRelease(observer);
    const Segment seg = CurrentSegment();
    double t_stop = std::min(t_end_s, seg.t_end_s);
    if (pending_n_ > 0) t_stop = std::min(t_stop, pending_[pending_head_].t_s);
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
    if (obs != nullptr && obs->wants_pieces() && t_stop > t0) {
      const FixedPiece piece(sensor_.Static(0.0), x_);
      obs->OnPiece(t0, t_stop, piece);
    }
    if (sample_period_s_ > 0.0 && obs) {
      for (double tk = SampleTime(next_sample_); tk < t_stop - kSameInstant_s; tk = SampleTime(++next_sample_))
        EmitSample(tk, 0.0, 0.0, x_, 0.0, v2_int_, vi_int_, obs);
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
        EmitSample(tk, i_inf + d0 * e, v0, x_, 0.0, v2_int_ + v0 * v0 * dt, vi_int_ + v0 * int_i(dt, e), obs);
      }
    } else {
      for (double tk = SampleTime(next_sample_); tk < limit; tk = SampleTime(++next_sample_)) {
        const double dt = tk - t0, e = std::exp(-dt / tau);
        const double i = i_inf + d0 * e;
        EmitSample(tk, i, v0 - Rs * i, x_, 0.0, v2_at(dt, e), vi_at(dt, e), obs);
      }
    }
  }
  if (obs != nullptr && obs->wants_pieces() && best_t > t0) {
    const ExponentialPiece piece(&sensor_, t0, i_inf, d0, tau, x_);
    obs->OnPiece(t0, best_t, piece);
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
    ode_->stepper.initialize(Scale(i_, x_, v_), t_, std::min(dt_guess_s_, opt_.max_step_s));
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

  for (;;) {
    if (ode_->stepper.current_time() <= t_ + kSameInstant_s) {
      try {
        ode_->stepper.do_step(rhs);
      } catch (const std::exception&) {
        // Boost.Odeint gives up after 500 rejected step-size adjustments (a NaN or an exploding derivative).
        Fail("the step-size control failed (the state or its derivative is not finite)");
        return;
      }
      ++ode_steps_;
      for (double y : ode_->stepper.current_state()) {
        if (!std::isfinite(y)) {
          Fail("the state is not finite (a non-physical parameter or input?)");
          return;
        }
      }
      // A step that collapses to nothing (a force of 1e308 N, a stiff non-physical parameter) would never reach
      // the end: stop with the reason instead of hanging.
      const double scale = std::max(1e-6, std::abs(ode_->stepper.current_time()));
      tiny_steps_ = ode_->stepper.current_time_step() < 1e-15 * scale ? tiny_steps_ + 1 : 0;
      if (tiny_steps_ > 1000) {
        Fail("the integration stalled: steps below 1e-15 of the time scale (a non-physical input?)");
        return;
      }
      if (!CheckWatchdog()) return;
    }
    const double a = t_;
    const double b = std::min(ode_->stepper.current_time(), t_stop);
    State yb;
    if (b >= ode_->stepper.current_time()) {
      yb = ode_->stepper.current_state();
    } else {
      ode_->stepper.calc_state(b, yb);
    }
    const State ya = CurrentState();
    double best_t = b;
    Ev best_ev = Ev::kNone;
    for (int k = 0; k < n_events; ++k) {
      const Ev ev = events[k];
      const double gb = EventFunction(ev, seg, b, yb);
      if (gb > 0.0) continue;  // no event in this step (LocateEvent would say so; g(a) is not needed)
      // The event function on the step's dense output (model/event_locator.h).
      auto g = [&](double t) {
        State y;
        ode_->stepper.calc_state(t, y);
        return EventFunction(ev, seg, t, y);
      };
      const EventHit hit = LocateEvent(g, a, EventFunction(ev, seg, a, ya), b, gb, ode_->locator);
      if (hit.found == EventFound::kNone) continue;
      // Never let the state pass through a stop: the earliest event wins (at a tie, the first listed).
      if (hit.t_s < best_t || best_ev == Ev::kNone) {
        best_t = hit.t_s;
        best_ev = ev;
      }
    }

    if (obs != nullptr && obs->wants_pieces() && best_t > a) {
      // The step's dense output between a and best_t (the terminal current as EmitSample measures it).
      class DensePiece final : public PieceView {
       public:
        DensePiece(const Simulator* sim, const Segment* seg) : sim_(sim), seg_(seg) {}
        void At(double t, double* i_A, double* x_m) const override {
          State y;
          sim_->ode_->stepper.calc_state(t, y);
          double i, x, v;
          sim_->Unscale(y, &i, &x, &v);
          if (seg_->blocked && sim_->plant_.params().effects.eddy_R_p_ohm == 0.0) i = 0.0;
          *i_A = sim_->sensor_.Static(sim_->TerminalAt(*seg_, t, i, y[5]).i_A);
          *x_m = std::clamp(x, sim_->x_lo_, sim_->x_hi_);
        }

       private:
        const Simulator* sim_;
        const Segment* seg_;
      };
      const DensePiece piece(this, &seg);
      obs->OnPiece(a, best_t, piece);
    }
    if (sample_period_s_ > 0.0 && obs) {
      const double limit = best_t - kSameInstant_s;
      for (double tk = SampleTime(next_sample_); tk < limit; tk = SampleTime(++next_sample_)) {
        State y;
        ode_->stepper.calc_state(tk, y);
        double i, x, v;
        Unscale(y, &i, &x, &v);
        if (seg.blocked && fx.eddy_R_p_ohm == 0.0) i = 0.0;
        const Terminal term = TerminalAt(seg, tk, i, y[5]);
        EmitSample(tk, term.i_A, term.v_V, std::clamp(x, x_lo_, x_hi_), v, ode_piece_v2_ + y[3],
                   ode_piece_vi_ + y[4], obs);
      }
    }

    {
      State y;
      if (best_t >= ode_->stepper.current_time()) {
        y = ode_->stepper.current_state();
      } else {
        ode_->stepper.calc_state(best_t, y);
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
      dt_guess_s_ = ode_->stepper.current_time_step();
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
      driver_.OnCurrentZero();
      kind = EventKind::kCurrentZero;
      break;
    case Ev::kLevel:
      if (plant_.params().effects.eddy_R_p_ohm == 0.0) i_ = seg.level_A;
      driver_.OnLevelCrossed();
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
