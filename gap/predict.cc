#include "gap/predict.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <string>

namespace vb::gap {

namespace {

Phase PhaseOf(const model::Simulator& sim) {
  const bool on = sim.gate() != 0;
  switch (sim.contact()) {
    case model::Contact::kLower: return on ? Phase::kRise : Phase::kClosed;
    case model::Contact::kUpper: return on ? Phase::kOpen : Phase::kRelease;
    default: return sim.v_mps() >= 0.0 ? Phase::kOpening : Phase::kClosing;
  }
}

// Samples at arbitrary instants from rest: the gate is 0 before the first edge and toggles at each edge.
Status PredictSamples(const model::PlantParams& plant, const model::DriverParams& driver, const RunData& run,
                      const PredictOptions& opt, std::vector<double>* i_A, std::vector<Phase>* phase,
                      std::uint64_t* steps) {
  model::Plant p(plant);
  model::Simulator sim(p, driver, model::Conditions{run.supply_V, run.supply_pressure_Pa}, opt.solver);
  struct Count {  // the work, however the function returns
    const model::Simulator& sim;
    std::uint64_t* steps;
    ~Count() { *steps += sim.ode_steps(); }
  } count{sim, steps};
  std::size_t edge = 0;
  int gate = 0;
  for (double t : run.t_s) {
    while (edge < run.gate_edges_s.size() && run.gate_edges_s[edge] <= t) {
      sim.AdvanceTo(run.gate_edges_s[edge], nullptr);
      gate = 1 - gate;
      sim.SetGate(gate);
      ++edge;
    }
    sim.AdvanceTo(t, nullptr);
    if (sim.failed()) return SimulationFailed(sim);
    i_A->push_back(sim.measured_current_A());
    phase->push_back(PhaseOf(sim));
  }
  return Status::Ok();
}

// Periodic steady state by shooting on the current at the rising edge, then the readings of one period.
Status PredictPeriodic(const model::PlantParams& plant, const model::DriverParams& driver, const RunData& run,
                       const PredictOptions& opt, std::vector<double>* i_A, std::vector<Phase>* phase,
                       std::uint64_t* steps) {
  model::Plant p(plant);
  model::Simulator sim(p, driver, model::Conditions{run.supply_V, run.supply_pressure_Pa}, opt.solver);
  struct Count {
    const model::Simulator& sim;
    std::uint64_t* steps;
    ~Count() { *steps += sim.ode_steps(); }
  } count{sim, steps};
  const double T = 1.0 / run.pwm_Hz, on = run.on_time_s;
  const bool always_on = on >= T;
  double t = 0.0;
  auto one_period = [&]() {
    sim.SetGate(1);
    if (!always_on) {
      sim.AdvanceTo(t + on, nullptr);
      sim.SetGate(0);
    }
    t += T;
    sim.AdvanceTo(t, nullptr);
  };
  // g(i0) = P(i0) - i0 is affine in i0 for a linear coil in continuous conduction, so two periods and a secant
  // step land on the steady state; discontinuous conduction (the current returns to 0 every period) is steady
  // after the first period; nonlinear effects and slow states take a few more steps or plain periods.
  double x_prev = NAN, g_prev = NAN;
  bool steady = false;
  for (int k = 0; k < opt.max_periods && !steady; ++k) {
    const double x = sim.i_A();
    one_period();
    if (sim.failed()) return SimulationFailed(sim);
    const double g = sim.i_A() - x;
    if (std::abs(g) <= opt.periodic_tol_A + 1e-7 * std::abs(x)) {
      steady = true;
      break;
    }
    if (std::isfinite(x_prev) && g != g_prev) {
      const double next = x - g * (x - x_prev) / (g - g_prev);
      x_prev = x;
      g_prev = g;
      // Only a physical step (the low-side driver's current is never negative); plain periods otherwise.
      if (std::isfinite(next) && next >= 0.0) {
        sim.SetCoilCurrent(next);
        continue;
      }
    } else {
      x_prev = x;
      g_prev = g;
    }
  }
  if (!steady) {
    return Status::FailedPrecondition("no periodic steady state within " + std::to_string(opt.max_periods) +
                                      " PWM periods");
  }
  // The readings of one more period, in time order.
  std::vector<std::size_t> order(run.t_s.size());
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return run.t_s[a] < run.t_s[b]; });
  i_A->assign(run.t_s.size(), 0.0);
  phase->assign(run.t_s.size(), Phase::kRise);
  const double t0 = t;
  sim.SetGate(1);
  bool off = always_on;
  for (std::size_t k : order) {
    const double at = t0 + run.t_s[k];
    if (!off && run.t_s[k] >= on) {
      sim.AdvanceTo(t0 + on, nullptr);
      sim.SetGate(0);
      off = true;
    }
    sim.AdvanceTo(at, nullptr);
    if (sim.failed()) return SimulationFailed(sim);
    (*i_A)[k] = sim.measured_current_A();
    (*phase)[k] = PhaseOf(sim);
  }
  return Status::Ok();
}

bool HasSlowStates(const model::PlantParams& p) { return p.effects.heating || p.effects.residual_w_A > 0.0; }

}  // namespace

StatusOr<model::PlantParams> PlantForRun(const Dataset& ds, const RunData& run, const model::PlantParams& plant) {
  auto p = model::AtState(plant, model::HeldState{run.stroke_m, run.temperature_C()});
  if (!p.ok()) return p.status();
  if (ds.sensor.shunt_in_switch_path) p->effects.supply_R_ohm += ds.sensor.shunt_ohm;
  return p;
}

bool HasWaveforms(const Dataset& ds) {
  return std::any_of(ds.runs.begin(), ds.runs.end(), [](const RunData& r) { return r.kind == RunKind::kWaveform; });
}

bool CanShowMotion(const Dataset& ds, const model::PlantParams& plant) {
  if (!plant.has_moving_part) return false;
  return std::any_of(ds.runs.begin(), ds.runs.end(),
                     [](const RunData& r) { return r.kind != RunKind::kPeriodic && !std::isfinite(r.stroke_m); });
}

StatusOr<Predicted> Predict(const Dataset& ds, const model::PlantParams& plant, const PredictOptions& opt,
                            const std::vector<bool>& need) {
  const std::size_t n = ds.runs.size();
  auto needed = [&](std::size_t r) { return need.empty() || need[r]; };
  std::size_t last = 0;
  bool any = false;
  for (std::size_t r = 0; r < n; ++r)
    if (needed(r)) {
      last = r;
      any = true;
    }
  Predicted out;
  out.i_A.resize(n);
  out.phase.resize(n);
  if (!any) return out;
  const bool slow = HasSlowStates(plant);
  const model::Effects& fx = plant.effects;
  const double tau_th = fx.heating_R_th_K_per_W * fx.heating_C_th_J_per_K;
  // Slow states of the last waveform run replayed, carried into the next one (gap/replay.h ReplaySession).
  bool have_prev = false;
  double prev_end_s = 0.0, prev_dT_K = 0.0, prev_im_A = 0.0;
  const model::DriverParams& driver = opt.driver != nullptr ? *opt.driver : ds.driver;
  for (std::size_t r = 0; r <= last; ++r) {
    const RunData& run = ds.runs[r];
    const bool chain = run.kind == RunKind::kWaveform && slow && std::isfinite(run.t_start_s);
    if (!needed(r) && !chain) continue;
    auto p = PlantForRun(ds, run, plant);
    if (!p.ok()) return p.status().WithContext("run " + run.id);
    std::vector<double>& i_A = out.i_A[r];
    std::vector<Phase>& ph = out.phase[r];
    Status st;
    switch (run.kind) {
      case RunKind::kWaveform: {
        if (chain && have_prev) {
          const double idle = std::max(0.0, run.t_start_s - prev_end_s);
          if (fx.heating) p->effects.heating_dT0_K = prev_dT_K * std::exp(-idle / tau_th);
          // The coil's current decays to zero during the idle time: the play follows it onto its band [-w, w].
          if (fx.residual_w_A > 0.0) p->effects.residual_im0_A = std::clamp(prev_im_A, -fx.residual_w_A, fx.residual_w_A);
        }
        ReplayInput in;
        in.supply_V = run.supply_V;
        in.supply_pressure_Pa = run.supply_pressure_Pa;
        in.sample_period_s = run.sample_period_s;
        in.gate = run.gate;
        if (!run.from_rest && !run.i_A.empty()) {
          const std::size_t m = std::min<std::size_t>(5, run.i_A.size());
          double first = 0.0;
          for (std::size_t k = 0; k < m; ++k) first += run.i_A[k] / static_cast<double>(m);
          in.initial_i_A = std::max(0.0, (first - ds.sensor.offset_A - p->effects.sensor_offset_A) / p->effects.sensor_gain);
        }
        auto rep = ReplayRun(*p, driver, in, opt.solver);
        if (!rep.ok()) return rep.status().WithContext("run " + run.id);
        out.ode_steps += rep->ode_steps;
        if (chain) {
          have_prev = true;
          prev_end_s = run.t_start_s + static_cast<double>(run.gate.size() - 1) * run.sample_period_s;
          prev_dT_K = rep->final_dT_K;
          prev_im_A = rep->final_im_A;
        }
        i_A = std::move(rep->i_A);
        ph = std::move(rep->phase);
        break;
      }
      case RunKind::kSamples: st = PredictSamples(*p, driver, run, opt, &i_A, &ph, &out.ode_steps); break;
      case RunKind::kPeriodic: st = PredictPeriodic(*p, driver, run, opt, &i_A, &ph, &out.ode_steps); break;
    }
    if (!st.ok()) return st.WithContext("run " + run.id);
    if (ds.sensor.offset_A != 0.0)
      for (double& v : i_A) v += ds.sensor.offset_A;
    if (!needed(r)) {
      i_A.clear();
      ph.clear();
    }
  }
  return out;
}

}  // namespace vb::gap
