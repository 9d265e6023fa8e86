#include "experiment/trace.h"

#include "experiment/trace_stream.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace vb::experiment {

void Trace::Reserve(size_t n) {
  t_s.reserve(n);
  gate.reserve(n);
  v_coil_V.reserve(n);
  i_A.reserve(n);
  x_m.reserve(n);
  v_mps.reserve(n);
  ref.reserve(n);
  x_avg_m.reserve(n);
  flow_kg_per_s.reserve(n);
  v2_int_V2s.reserve(n);
  energy_int_J.reserve(n);
  switch_count.reserve(n);
}

void Trace::Clear() {
  t_s.clear();
  gate.clear();
  v_coil_V.clear();
  i_A.clear();
  x_m.clear();
  v_mps.clear();
  ref.clear();
  x_avg_m.clear();
  flow_kg_per_s.clear();
  v2_int_V2s.clear();
  energy_int_J.clear();
  switch_count.clear();
  dropped = 0;
}

const std::vector<std::string>& Trace::ChannelNames() {
  static const std::vector<std::string> names = {"t_s", "gate", "v_coil_V", "i_A",           "x_m",
                                                 "v_mps", "ref", "x_avg_m", "flow_kg_per_s",
                                                 "v2_int_V2s", "energy_int_J", "switch_count"};
  return names;
}

double Trace::Value(size_t channel, size_t k) const {
  switch (channel) {
    case 0: return t_s[k];
    case 1: return gate[k];
    case 2: return v_coil_V[k];
    case 3: return i_A[k];
    case 4: return x_m[k];
    case 5: return v_mps[k];
    case 6: return ref[k];
    case 7: return x_avg_m[k];
    case 8: return flow_kg_per_s[k];
    case 9: return v2_int_V2s[k];
    case 10: return energy_int_J[k];
    case 11: return switch_count[k];
  }
  return std::numeric_limits<double>::quiet_NaN();
}

Recorder::Recorder(Trace* trace, const ReferenceProfile* reference, const model::PlantParams* plant,
                   double supply_pressure_Pa, double sample_period_s, double average_window_s)
    : trace_(trace), reference_(reference), plant_(plant), pressure_Pa_(supply_pressure_Pa) {
  trace_->sample_period_s = sample_period_s;
  int window = 1;
  if (sample_period_s > 0.0 && average_window_s > 0.0)
    window = std::max(1, static_cast<int>(std::lround(average_window_s / sample_period_s)));
  window_buf_.assign(static_cast<size_t>(window), 0.0);
  if (plant_ != nullptr) flow_per_m_ = model::MassFlow_kg_per_s(*plant_, 1.0, pressure_Pa_);
  avg_.Reset(window_buf_.data(), window);
}

void Recorder::StreamTo(TraceStream* stream) {
  stream_ = stream;
  trace_ = stream->first();
}

void Recorder::OnSample(const hw::BenchSample& s) {
  if (trace_->t_s.size() == trace_->t_s.capacity()) {  // never reallocate inside the loop
    if (stream_ == nullptr) {
      ++trace_->dropped;
      return;
    }
    trace_ = stream_->Rotate(trace_);
  }
  constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  trace_->t_s.push_back(s.t_s);
  trace_->gate.push_back(s.gate);
  trace_->v_coil_V.push_back(s.v_coil_V);
  trace_->i_A.push_back(s.i_A);
  trace_->x_m.push_back(s.x_m);
  trace_->v_mps.push_back(s.v_mps);
  trace_->ref.push_back(reference_ != nullptr && reference_->has_reference() ? reference_->At(s.t_s).value : kNaN);
  const double xbar = std::isnan(s.x_m) ? kNaN : avg_.Push(s.x_m);
  trace_->x_avg_m.push_back(xbar);
  trace_->flow_kg_per_s.push_back(plant_ != nullptr && !std::isnan(xbar) ? flow_per_m_ * std::max(xbar, 0.0) : kNaN);
  trace_->v2_int_V2s.push_back(s.v2_integral_V2s);
  trace_->energy_int_J.push_back(s.energy_J);
  trace_->switch_count.push_back(s.switches);
}

}  // namespace vb::experiment
