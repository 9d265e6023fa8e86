// Event-exact simulation of a Plant behind a Driver.
//
// Time is never rounded to a grid. The simulation is a sequence of pieces separated by events, each located
// to ~1e-13 s: gate edges (the caller advances to each edge, then calls SetGate), end-stop contact and
// release, the current reaching zero in a freewheel path, the internal-electronics chopper thresholds and
// boost end. Within a piece:
//   * spool held at a stop and a constant coil voltage: the coil is linear with constant L, and
//     i(t) = v/R + (i0 - v/R) exp(-(t - t0) R / L) is exact (closed form; events by logarithms);
//   * otherwise (spool moving, or a decaying voltage): Dormand-Prince 5(4) with dense output
//     (Boost.Odeint), on states scaled to O(1); events are located by root finding on the dense output.
// Samples on a uniform grid t_k = k * sample_period_s are produced inside pieces from the closed form or the
// dense output, so sampling costs no steps and never perturbs the solution.
//
// Real-time: AdvanceTo() does not allocate, lock or do I/O (the observer may, in its own code).
//
// The simulator composes the ideas that live in their own files (docs/model.md, "Structure"): the plant's
// equations (model/plant.h), the coil with effects (model/coil.h), the driver's state machine
// (model/driver.h), the current sensor (model/sensor.h) and the event locator (model/event_locator.h).
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <limits>
#include <memory>
#include <vector>

#include "model/coil.h"
#include "model/driver.h"
#include "model/plant.h"
#include "model/sensor.h"

namespace vb::model {

struct Conditions {
  double supply_V = 24.0;             // supply across switch + coil when the gate is on
  double supply_pressure_Pa = 0.0;    // gauge supply pressure P_sup (seed 000 eq. 10)
};

// kStuck: at rest mid-travel, held by static friction (coulomb_friction).
enum class Contact : std::uint8_t { kLower, kUpper, kFree, kStuck };

enum class EventKind : std::uint8_t {
  kLift,         // the spool leaves the lower stop
  kOpen,         // the spool reaches the upper stop (x_max)
  kRelease,      // the spool leaves the upper stop
  kClose,        // the spool reaches the lower stop
  kCurrentZero,  // the current reaches zero in a freewheel path and stays there
  kDriverSwitch, // the driver changed its internal state (boost end, chopper threshold)
  kStick,        // the spool came to rest mid-travel and static friction holds it
  kSlip,         // the spool broke away from rest mid-travel
};
const char* EventKindName(EventKind kind);

struct PlantSample {
  double t_s;
  std::int8_t gate;    // the command in force from this instant
  double v_coil_V;
  double i_A;
  double x_m;
  double v_mps;
  // Exact running integrals from t = 0 (not sampled sums: a 20 kHz PWM is invisible to 50 kHz samples).
  double v2_integral_V2s;   // integral of v_coil^2 dt
  double energy_J;          // integral of v_coil * i dt
  std::uint64_t switches;   // gate transitions so far
  double gate_on_s;         // integral of the gate command dt: the time it was on so far (exact, at its edges)
};

// The trajectory inside one piece [t0, t1] of the simulation (between two events, gate edges or AdvanceTo ends;
// on moving-spool pieces between two accepted solver steps): smooth there, evaluated from the closed form or the
// solver's dense output. Valid only during the OnPiece call that hands it over.
class PieceView {
 public:
  virtual ~PieceView() = default;
  // The terminal current through the sensor's static chain (gain, offset: no lag, no latency) and the position.
  virtual void At(double t_s, double* i_A, double* x_m) const = 0;
};

class SimObserver {
 public:
  virtual ~SimObserver() = default;
  virtual void OnSample(const PlantSample& sample) = 0;
  // Every piece, in time order, with no gaps: the exact trajectory, for metrics that must not depend on the
  // sample rate (docs/metrics.md). Observers that want it return true from wants_pieces().
  virtual bool wants_pieces() const { return false; }
  virtual void OnPiece(double /*t0_s*/, double /*t1_s*/, const PieceView& /*piece*/) {}
  virtual void OnEvent(EventKind /*kind*/, double /*t_s*/, double /*i_A*/, double /*x_m*/, double /*v_mps*/) {}
};

// Additive disturbances for robustness runs (seed 002 IV.D, eq. 14): a sinusoidal voltage in series with the
// coil while it conducts, and a sinusoidal force on the spool (eq. 14's "33 sin wt" is that force over M).
struct Disturbance {
  double voltage_V = 0.0;      // amplitude
  double force_N = 0.0;        // amplitude
  double frequency_Hz = 0.0;   // common frequency; 0 = constant offsets
  bool active() const { return voltage_V != 0.0 || force_N != 0.0; }
};

struct SolverOptions {
  double rel_tol = 1e-9;           // Dormand-Prince relative tolerance
  double abs_tol = 1e-10;          // absolute tolerance on the scaled states (i in A, x and v in units of travel)
  double max_step_s = 2e-4;        // a step never spans more than this (guards against missed grazing contacts)
  double event_time_tol_s = 1e-14; // events are located to this
  // Watchdogs (docs/model.md, "When the simulation stops"): work (ODE steps + pieces) allowed since the last
  // Reset (0: no limit) and a wall-clock deadline (max(): none). Independently of both, a state that is not
  // finite, steps that shrink below 1e-15 of the time scale for 1000 steps in a row, and 100000 pieces at one
  // instant stop the simulation with the reason (Simulator::failed).
  std::uint64_t max_work = 0;
  std::chrono::steady_clock::time_point deadline = std::chrono::steady_clock::time_point::max();
};

class Simulator {
 public:
  Simulator(const Plant& plant, const DriverParams& driver, const Conditions& conditions,
            const SolverOptions& options = {});

  // Back to rest: t = 0, i = 0, x = x_min, v = 0, gate 0, no sample emitted yet.
  void Reset();
  // Sets the coil's (magnetising) current now, leaving every other state as it is: the shooting step of a
  // periodic steady-state search (gap/predict.h), which guesses the current at a gate edge and integrates one
  // period from it. Negative values are taken as 0 (the low-side driver's diode blocks reverse current).
  void SetCoilCurrent(double i_A);
  // Samples at t_k = k * period_s (k = 0, 1, ...); 0 disables sampling.
  void SetSamplePeriod(double period_s);
  // Changes the gate at the current time. The caller guarantees the driver accepts the level.
  void SetGate(int gate);
  void SetConditions(const Conditions& conditions);
  // With a disturbance every piece is integrated (the closed form assumes a constant coil voltage).
  void SetDisturbance(const Disturbance& disturbance);
  // Integrates to t_end_s, reporting samples with t_k in [t, t_end_s) and events in (t, t_end_s].
  void AdvanceTo(double t_end_s, SimObserver* observer);
  // Emits the sample at the current time if it lies on the grid and has not been emitted (end of a run).
  void EmitPendingSample(SimObserver* observer);

  // The watchdog stopped the simulation: AdvanceTo then does nothing until Reset. failure() says why
  // (a static string; no allocation on the real-time path), failure_t_s() when.
  bool failed() const { return failure_ != nullptr; }
  const char* failure() const { return failure_; }
  double failure_t_s() const { return failure_t_s_; }
  // Replaces the watchdog's budget and deadline for the following AdvanceTo calls and restarts its count (a
  // bench sets one per control tick).
  void SetWatchdog(std::uint64_t max_work, std::chrono::steady_clock::time_point deadline);

  double t_s() const { return t_; }
  double i_A() const { return i_; }  // the magnetising current (the force current)
  // What the bench's current sensor reports now (lagged by sensor_lag; the terminal current otherwise).
  double measured_current_A() const;
  double coil_temperature_rise_K() const { return dT_; }
  double play_state_A() const { return im_; }  // residual_magnetism's play output (the core's memory)
  // The magnetic law with effects: dlambda/di, dlambda/dx and the force at current i and position x.
  using Magnetics = model::Magnetics;
  Magnetics MagneticsAt(double i, double x) const { return model::MagneticsAt(plant_, i, x); }
  // Everything pushing the spool at rest at x (magnetic + passive + disturbance), for a flux-equivalent
  // current j (= the magnetising current unless residual_magnetism).
  double NetForceAtRest_N(double j, double x, double t) const;
  double x_m() const { return x_; }
  double v_mps() const { return v_; }
  // The gate as commanded (driver_delay: the driver follows it delay_s later).
  int gate() const { return gate_; }
  Contact contact() const { return contact_; }
  const Plant& plant() const { return plant_; }
  const Conditions& conditions() const { return cond_; }
  // Work counters, for benchmarks.
  std::uint64_t ode_steps() const { return ode_steps_; }
  double v2_integral_V2s() const { return v2_int_; }
  double energy_J() const { return vi_int_; }
  std::uint64_t switches() const { return switches_; }
  std::uint64_t restarts() const { return restarts_; }

 private:
  // scaled: i [A] (the magnetising current: the terminal current unless eddy currents branch off),
  // (x - x_min)/x_scale, v/v_scale, two quadratures from the piece start (integral v_coil^2 dt and
  // integral v_coil i dt), the coil's temperature rise dT [K] (coil_heating) and the play operator's
  // output i_m [A] (residual_magnetism). The current sensor is not part of the plant: see sensor_.
  using State = std::array<double, 7>;
  enum class Play : std::uint8_t { kInside, kRising, kFalling };  // residual_magnetism's mode
  // The Dormand-Prince stepper with its dense output and the event locator's options (Boost.Odeint, Boost.Math)
  // live in simulator.cc: Odeint's headers cost about 3 s of compile time in each of the ~120 translation units
  // that include this header, directly or through hw/emulated_bench.h. Held by value semantics (a copy of the
  // simulator copies its stepper); allocated once at construction, never in AdvanceTo.
  struct Ode;
  class OdeHolder {
   public:
    explicit OdeHolder(const SolverOptions& options);
    OdeHolder(const OdeHolder& other);
    OdeHolder& operator=(const OdeHolder& other);
    OdeHolder(OdeHolder&& other) noexcept;
    OdeHolder& operator=(OdeHolder&& other) noexcept;
    ~OdeHolder();
    Ode* operator->() { return p_.get(); }
    const Ode* operator->() const { return p_.get(); }

   private:
    std::unique_ptr<Ode> p_;
  };

  // What the driver puts on the coil until the next driver event.
  using Segment = DriveSegment;
  enum class Ev : std::uint8_t {
    kNone, kUpper, kLower, kLeaveStop, kClamp, kLevel, kVelocityZero, kPlayUpper, kPlayLower, kPlayTurn
  };
  // Right-hand side of the integrated piece (also used by events that need di/dt).
  void Rhs(const Segment& seg, const State& y, State& dy, double t) const;
  // The flux-equivalent current (residual_magnetism; the magnetising current otherwise).
  double FluxCurrent(double i, double i_m) const { return model::FluxCurrent(plant_.params().effects, i, i_m); }
  // The coil's terminal quantities at t (the driver's voltage plus the disturbance; model/coil.h).
  Terminal TerminalAt(const Segment& seg, double t, double i_mag, double dT) const;

  // The supply's voltage as delivered (supply_voltage: gain x the declared).
  double SupplyV() const { return cond_.supply_V * plant_.params().effects.supply_gain; }
  // The driver's segment now; a blocked segment holds the current at 0 (unless an eddy branch carries it).
  Segment CurrentSegment();
  void AdvanceClosedForm(const Segment& seg, double t_stop, SimObserver* obs);
  void AdvanceOde(const Segment& seg, double t_stop, SimObserver* obs);
  void ApplyEvent(Ev ev, const Segment& seg, SimObserver* obs);
  void CheckStopRelease(SimObserver* obs);
  double EventFunction(Ev ev, const Segment& seg, double t, const State& y) const;
  State CurrentState() const;
  double DisturbanceVoltage(double t) const;
  double DisturbanceForce(double t) const;
  double SampleTime(std::int64_t k) const { return static_cast<double>(k) * sample_period_s_; }
  // i_meas: the terminal current the sensor measures; v_term: the terminal voltage. Advances the sensor.
  void EmitSample(double t, double i_meas, double v_term, double x, double v, double v2_int, double vi_int,
                  SimObserver* obs);
  State Scale(double i, double x, double v) const {
    return {i, (x - x_lo_) * inv_x_scale_, v * inv_v_scale_, 0.0, 0.0, dT_, im_};
  }
  void Unscale(const State& s, double* i, double* x, double* v) const {
    *i = s[0];
    *x = x_lo_ + s[1] * x_scale_;
    *v = s[2] * v_scale_;
  }

  Plant plant_;
  Driver driver_;
  Conditions cond_;
  SolverOptions opt_;
  Disturbance dist_;
  double x_lo_, x_hi_, x_scale_, inv_x_scale_, v_scale_, inv_v_scale_;

  double t_ = 0.0, i_ = 0.0, x_ = 0.0, v_ = 0.0;
  double v2_int_ = 0.0, vi_int_ = 0.0;   // running integrals up to t_
  double dT_ = 0.0;                       // coil temperature rise (coil_heating)
  CurrentSensor sensor_;                  // the measurement chain: fed at every sample
  bool general_ = false;                  // effects or disturbances: integrate every piece
  double free_dir_ = 1.0;                 // direction of motion in a free piece (kinetic friction's sign)
  double im_ = 0.0;                       // play operator output (residual_magnetism)
  Play play_ = Play::kInside;
  bool frozen_ = false;                   // the current integrated piece holds the spool
  std::uint64_t switches_ = 0;
  int gate_ = 0;                   // the command (SetGate); the driver's own gate lags it by driver_delay
  // driver_delay: commanded edges the driver has not seen yet, oldest first (a fixed ring: SetGate runs in the
  // control loop, which does not allocate).
  struct PendingEdge {
    double t_s;
    int gate;
  };
  std::array<PendingEdge, 64> pending_{};
  std::size_t pending_head_ = 0, pending_n_ = 0;
  void ApplyDueEdges();
  double gate_on_before_s_ = 0.0;  // the gate's on-time up to its last falling edge
  double gate_on_since_s_ = 0.0;   // its last rising edge
  double ode_piece_v2_ = 0.0, ode_piece_vi_ = 0.0;  // integrals at the ODE stepper's restart time
  Contact contact_ = Contact::kLower;

  double sample_period_s_ = 0.0;
  std::int64_t next_sample_ = 0;
  // Watchdog (SolverOptions): work since Reset/SetWatchdog, consecutive collapsed steps and stalled pieces.
  void Fail(const char* why);
  bool CheckWatchdog();  // false (and failed) when a limit is reached
  const char* failure_ = nullptr;
  double failure_t_s_ = 0.0;
  std::uint64_t work_ = 0;
  int tiny_steps_ = 0;
  int stalled_pieces_ = 0;

  OdeHolder ode_;
  bool stepper_valid_ = false;
  double dt_guess_s_ = 1e-6;
  std::uint64_t ode_steps_ = 0, restarts_ = 0;
};

}  // namespace vb::model
