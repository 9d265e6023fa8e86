#include "gap/replay.h"

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

StatusOr<Replay> ReplayRun(const model::PlantParams& plant, const model::DriverParams& driver,
                           const ReplayInput& in, const model::SolverOptions& solver) {
  if (!(in.sample_period_s > 0.0)) return Status::InvalidArgument("sample_period_s: must be > 0");
  if (in.gate.empty()) return Status::InvalidArgument("gate: no samples");
  if (!(in.supply_V > 0.0)) return Status::InvalidArgument("supply_V: must be > 0");
  model::Plant p(plant);
  model::Simulator sim(p, driver, model::Conditions{in.supply_V, in.supply_pressure_Pa}, solver);
  sim.SetSamplePeriod(in.sample_period_s);
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
    sim.SetGate(g);          // the gate of sample k holds from t
  }
  sim.AdvanceTo(static_cast<double>(n - 1) * in.sample_period_s, &col);
  sim.EmitPendingSample(&col);
  if (out.i_A.size() != n)
    return Status::Internal("replay produced " + std::to_string(out.i_A.size()) + " samples for " +
                            std::to_string(n));
  return out;
}

}  // namespace vb::gap
