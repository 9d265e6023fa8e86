// A recorded run: uniformly sampled channels, stored as columns. The Recorder fills a Trace from bench
// samples without allocating (capacity is reserved before the run; samples beyond it are counted, not kept).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "experiment/reference.h"
#include "hw/bench.h"
#include "model/flow.h"
#include "model/params.h"

namespace vb::experiment {

struct Trace {
  double sample_period_s = 0.0;
  std::vector<double> t_s;
  std::vector<std::int8_t> gate;
  std::vector<double> v_coil_V, i_A, x_m, v_mps;
  std::vector<double> ref;              // reference of the controlled variable (NaN if none)
  std::vector<double> x_avg_m;          // moving average of x over one PWM period (seed 000 section 5)
  std::vector<double> flow_kg_per_s;    // eq. (12) from x_avg_m
  std::vector<double> v2_int_V2s;       // exact running integral of v_coil^2 (NaN if the bench has none)
  std::vector<double> energy_int_J;     // exact running integral of v_coil i
  std::vector<double> switch_count;     // gate transitions so far
  std::uint64_t dropped = 0;            // samples that did not fit the reserved capacity

  // Memory one sample takes in every channel: 11 doubles and the gate byte (admission budgets runs by it).
  static constexpr std::size_t kBytesPerSample = 11 * sizeof(double) + sizeof(std::int8_t);
  size_t size() const { return t_s.size(); }
  void Reserve(size_t n);
  void Clear();
  // Channel names in CSV order.
  static const std::vector<std::string>& ChannelNames();
  double Value(size_t channel, size_t k) const;
};

class TraceStream;

class Recorder final : public hw::SampleSink {
 public:
  // plant may be null (no flow channel). average_window_s: the moving-average window (one PWM period).
  Recorder(Trace* trace, const ReferenceProfile* reference, const model::PlantParams* plant,
           double supply_pressure_Pa, double sample_period_s, double average_window_s);
  void OnSample(const hw::BenchSample& s) override;
  // Record into `stream`'s blocks from now on: a full block is handed over and recording goes on in the next
  // (experiment/trace_stream.h) instead of dropping samples.
  void StreamTo(TraceStream* stream);
  // The block being recorded into (the trace given at construction when not streaming).
  Trace* current() const { return trace_; }

 private:
  Trace* trace_;
  TraceStream* stream_ = nullptr;
  const ReferenceProfile* reference_;
  const model::PlantParams* plant_;
  double pressure_Pa_;
  double flow_per_m_ = 0.0;  // eq. (12) is linear in xbar: flow = flow_per_m_ * xbar (one evaluation per run)
  std::vector<double> window_buf_;
  model::MovingAverage avg_;
};

}  // namespace vb::experiment
