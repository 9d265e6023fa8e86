// EmulatedBench: the valve model behind the Bench interface. A first-class bench (ros2_control's mock
// hardware): the same experiments, controllers and safety paths run on it as on a USB bench.
//
// Its PWM peripheral works like a hardware timer: a carrier of period T starts at the command (or at a
// carrier restart); the gate is high for the first duty*T of each period; a new duty at the same frequency
// is latched at the next period start (shadow register). Edges are passed to the simulator exactly.
// Paced mode (RunConfig.realtime) integrates to each deadline, then sleeps until it on CLOCK_MONOTONIC
// (absolute deadlines, no drift) and records the wake-up lateness and overruns.
#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <random>
#include <string>

#include "hw/bench.h"
#include "model/simulator.h"

namespace vb::hw {

struct EmulatedBenchOptions {
  std::string name = "emulator";
  model::PlantParams plant;               // validated by the caller (model::Validate)
  model::DriverParams driver;
  model::SolverOptions solver;
  model::Disturbance disturbance;         // robustness runs (seed 002 IV.D)
  double max_supply_V = 1000.0;
  double max_current_A = 100.0;
  // White noise (1-sigma) added to each recorded current sample, as a sense chain adds it (0: the exact current).
  // Drawn from a generator seeded with noise_seed at each Start: no allocation in the loop.
  double current_noise_A = 0.0;
  std::uint64_t noise_seed = 1;
};

// Fixed-size log histogram of durations (100 ns .. 10 s): percentiles without allocation in the loop.
class LatencyHistogram {
 public:
  void Clear();
  void Add(double seconds);
  double Percentile(double q) const;  // upper edge of the bin holding the q-quantile
  double max() const { return max_s_; }
  std::uint64_t count() const { return n_; }

 private:
  static constexpr int kBins = 256;
  std::array<std::uint64_t, kBins> bins_{};
  std::uint64_t n_ = 0;
  double max_s_ = 0.0;
};

class EmulatedBench final : public Bench {
 public:
  explicit EmulatedBench(EmulatedBenchOptions options);

  const Capabilities& capabilities() const override { return caps_; }
  Status Configure(const RunConfig& config) override;
  Status Start(SampleSink* sink) override;
  Status Apply(const SwitchCommand& command) override;
  Status AdvanceTo(double t_s, Measurement* m) override;
  Status Stop() override;
  void SafeState() noexcept override;
  LoopStats loop_stats() const override;
  void set_cancel_flag(const std::atomic<bool>* cancel) override { cancel_ = cancel; }
  bool set_trajectory_sink(TrajectorySink* sink) override {
    forwarder_.pieces = sink;
    forwarder_.has_position = caps_.measures_position;
    return true;
  }

  const model::Simulator& simulator() const { return sim_; }

 private:
  class Forwarder final : public model::SimObserver {
   public:
    SampleSink* sink = nullptr;
    TrajectorySink* pieces = nullptr;
    bool has_position = false;
    bool wants_pieces() const override { return pieces != nullptr; }
    void OnPiece(double t0_s, double t1_s, const model::PieceView& piece) override {
      class Adapter final : public TrajectoryPiece {
       public:
        Adapter(const model::PieceView* p, bool has_x) : p_(p), has_x_(has_x) {}
        void At(double t_s, double* i_A, double* x_m) const override {
          p_->At(t_s, i_A, x_m);
          if (!has_x_) *x_m = kNotMeasured;
        }

       private:
        const model::PieceView* p_;
        bool has_x_;
      };
      pieces->OnPiece(t0_s, t1_s, Adapter(&piece, has_position));
    }
    double noise_A = 0.0;
    std::mt19937_64 rng;
    std::normal_distribution<double> normal{0.0, 1.0};
    void OnSample(const model::PlantSample& s) override {
      const double i_A = noise_A > 0.0 ? s.i_A + noise_A * normal(rng) : s.i_A;
      if (sink)
        sink->OnSample(BenchSample{s.t_s, s.gate, s.v_coil_V, i_A, s.x_m, s.v_mps, s.v2_integral_V2s, s.energy_J,
                                   static_cast<double>(s.switches), s.gate_on_s});
    }
  };
  void RunPwmTo(double t_s);
  bool CancelSet() const { return cancel_ != nullptr && cancel_->load(std::memory_order_relaxed); }

  EmulatedBenchOptions opt_;
  Capabilities caps_;
  model::Plant plant_;
  model::Simulator sim_;
  RunConfig config_;
  Forwarder forwarder_;
  bool running_ = false;
  const std::atomic<bool>* cancel_ = nullptr;

  // PWM peripheral
  bool pwm_mode_ = false;
  double period_s_ = 0.0;
  double origin_s_ = 0.0;        // carrier start
  std::int64_t period_index_ = 0;
  double duty_ = 0.0;
  double pending_duty_ = 0.0;

  // pacing
  std::chrono::steady_clock::time_point wall_start_;
  LatencyHistogram lateness_;
  std::uint64_t ticks_ = 0, overruns_ = 0;
};

}  // namespace vb::hw
