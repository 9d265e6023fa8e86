#include "gap/replay.h"

#include <algorithm>
#include <cmath>

namespace vb::gap {

std::string_view PhaseName(Phase p) {
  switch (p) {
    case Phase::kRise: return "rise";
    case Phase::kOpening: return "opening";
    case Phase::kOpen: return "open";
    case Phase::kRelease: return "release";
    case Phase::kClosing: return "closing";
    case Phase::kClosed: return "closed";
  }
  return "?";
}

namespace {

class Collector final : public model::SimObserver {
 public:
  Collector(Replay* out, const model::PlantParams& p) : out_(out), x_lo_(p.x_min_m), x_hi_(p.x_max_m) {}
  void OnSample(const model::PlantSample& s) override {
    out_->i_A.push_back(s.i_A);
    out_->x_m.push_back(s.x_m);
    out_->v_mps.push_back(s.v_mps);
    const bool on = s.gate != 0;
    const bool at_low = s.x_m <= x_lo_ && s.v_mps == 0.0;
    const bool at_high = s.x_m >= x_hi_ && s.v_mps == 0.0;
    Phase ph;
    if (at_low) {
      ph = on ? Phase::kRise : Phase::kClosed;
    } else if (at_high) {
      ph = on ? Phase::kOpen : Phase::kRelease;
    } else {
      ph = s.v_mps >= 0.0 ? Phase::kOpening : Phase::kClosing;
    }
    out_->phase.push_back(ph);
  }

 private:
  Replay* out_;
  double x_lo_, x_hi_;
};

}  // namespace

Status SimulationFailed(const model::Simulator& sim) {
  return Status::Aborted("the simulation stopped at t = " + std::to_string(sim.failure_t_s()) + " s: " + sim.failure());
}

StatusOr<Replay> ReplayRun(const model::PlantParams& plant, const model::DriverParams& driver,
                           const ReplayInput& in, const model::SolverOptions& solver) {
  if (!(in.sample_period_s > 0.0)) return Status::InvalidArgument("sample_period_s: must be > 0");
  if (in.gate.empty()) return Status::InvalidArgument("gate: no samples");
  if (!(in.supply_V > 0.0)) return Status::InvalidArgument("supply_V: must be > 0");
  model::Plant p(plant);
  model::Simulator sim(p, driver, model::Conditions{in.supply_V, in.supply_pressure_Pa}, solver);
  sim.SetSamplePeriod(in.sample_period_s);
  if (in.initial_i_A > 0.0) sim.SetCoilCurrent(in.initial_i_A);
  Replay out;
  const size_t n = in.gate.size();
  out.i_A.reserve(n);
  out.x_m.reserve(n);
  out.v_mps.reserve(n);
  out.phase.reserve(n);
  Collector col(&out, plant);
  for (size_t k = 0; k < n; ++k) {
    const int g = in.gate[k];
    if (g != 0 && g != 1) return Status::InvalidArgument("gate[" + std::to_string(k) + "]: must be 0 or 1");
    const double t = static_cast<double>(k) * in.sample_period_s;
    sim.AdvanceTo(t, &col);  // emits the samples before t
    if (sim.failed()) return SimulationFailed(sim);
    sim.SetGate(g);          // the gate of sample k holds from t
  }
  sim.AdvanceTo(static_cast<double>(n - 1) * in.sample_period_s, &col);
  if (sim.failed()) return SimulationFailed(sim);
  sim.EmitPendingSample(&col);
  out.final_dT_K = sim.coil_temperature_rise_K();
  out.final_im_A = sim.play_state_A();
  out.ode_steps = sim.ode_steps();
  if (out.i_A.size() != n)
    return Status::Internal("replay produced " + std::to_string(out.i_A.size()) + " samples for " +
                            std::to_string(n));
  return out;
}

StatusOr<std::vector<Replay>> ReplaySession(const model::PlantParams& plant, const model::DriverParams& driver,
                                            const std::vector<SessionRun>& runs, const model::SolverOptions& solver) {
  std::vector<Replay> out;
  out.reserve(runs.size());
  model::PlantParams p = plant;
  const model::Effects& fx = plant.effects;
  const double tau_th = fx.heating_R_th_K_per_W * fx.heating_C_th_J_per_K;
  for (std::size_t r = 0; r < runs.size(); ++r) {
    if (r > 0) {
      const double end_prev = runs[r - 1].t_start_s +
                              static_cast<double>(runs[r - 1].gate->size() - 1) * runs[r - 1].sample_period_s;
      const double idle = std::max(0.0, runs[r].t_start_s - end_prev);
      if (fx.heating) p.effects.heating_dT0_K = out.back().final_dT_K * std::exp(-idle / tau_th);
      // The coil's current decays to zero during the idle time: the play follows it onto its band [-w, w].
      if (fx.residual_w_A > 0.0)
        p.effects.residual_im0_A = std::clamp(out.back().final_im_A, -fx.residual_w_A, fx.residual_w_A);
    }
    ReplayInput in;
    in.supply_V = runs[r].supply_V;
    in.supply_pressure_Pa = runs[r].supply_pressure_Pa;
    in.sample_period_s = runs[r].sample_period_s;
    in.gate = *runs[r].gate;
    auto rep = ReplayRun(p, driver, in, solver);
    if (!rep.ok()) return rep.status().WithContext("run " + std::to_string(r));
    out.push_back(std::move(rep.value()));
  }
  return out;
}

}  // namespace vb::gap
