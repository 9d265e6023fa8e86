#include "hw/emulated_bench.h"

#include <sys/prctl.h>
#include <time.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <sstream>

namespace vb::hw {

void LatencyHistogram::Clear() {
  bins_.fill(0);
  n_ = 0;
  max_s_ = 0.0;
}

// Bin b covers [1e-7 * 10^(b/32), 1e-7 * 10^((b+1)/32)): 32 bins per decade, 8 decades.
void LatencyHistogram::Add(double seconds) {
  seconds = std::max(seconds, 0.0);
  int b = seconds <= 1e-7 ? 0 : static_cast<int>(std::floor(32.0 * std::log10(seconds / 1e-7)));
  b = std::clamp(b, 0, kBins - 1);
  ++bins_[b];
  ++n_;
  max_s_ = std::max(max_s_, seconds);
}

double LatencyHistogram::Percentile(double q) const {
  if (n_ == 0) return 0.0;
  const auto target = static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(n_)));
  std::uint64_t acc = 0;
  for (int b = 0; b < kBins; ++b) {
    acc += bins_[b];
    if (acc >= target && acc > 0) return std::min(1e-7 * std::pow(10.0, (b + 1) / 32.0), max_s_);
  }
  return max_s_;
}

EmulatedBench::EmulatedBench(EmulatedBenchOptions options)
    : opt_(std::move(options)), plant_(opt_.plant), sim_(plant_, opt_.driver, model::Conditions{}, opt_.solver) {
  caps_.kind = "emulated";
  caps_.driver = std::string(model::DriverKindName(opt_.driver.kind));
  caps_.max_supply_V = opt_.max_supply_V;
  caps_.min_carrier_Hz = 0.01;
  caps_.max_carrier_Hz = 1e6;
  caps_.max_sample_rate_Hz = 10e6;
  caps_.max_control_rate_Hz = 10e6;
  caps_.measures_position = opt_.plant.has_moving_part;
  caps_.measures_velocity = opt_.plant.has_moving_part;
  caps_.max_current_A = opt_.max_current_A;
}

Status EmulatedBench::Configure(const RunConfig& config) {
  if (!(config.supply_V > 0.0) || config.supply_V > caps_.max_supply_V) {
    std::ostringstream os;
    os << "supply_V: " << config.supply_V << " V is outside (0, " << caps_.max_supply_V << "] for bench "
       << opt_.name;
    return Status::FailedPrecondition(os.str());
  }
  if (config.supply_pressure_Pa < 0.0) return Status::InvalidArgument("supply_pressure_Pa: must be >= 0");
  if (config.sample_rate_Hz < 0.0 || config.sample_rate_Hz > caps_.max_sample_rate_Hz)
    return Status::FailedPrecondition("sample_rate_Hz: outside what this bench records");
  config_ = config;
  return Status::Ok();
}

Status EmulatedBench::Start(SampleSink* sink) {
  forwarder_.sink = sink;
  forwarder_.noise_A = opt_.current_noise_A;
  forwarder_.rng.seed(opt_.noise_seed);
  forwarder_.normal.reset();
  sim_.SetConditions(model::Conditions{config_.supply_V, config_.supply_pressure_Pa});
  sim_.SetDisturbance(opt_.disturbance);
  sim_.Reset();
  sim_.SetSamplePeriod(config_.sample_rate_Hz > 0.0 ? 1.0 / config_.sample_rate_Hz : 0.0);
  pwm_mode_ = false;
  period_s_ = 0.0;
  origin_s_ = 0.0;
  period_index_ = 0;
  duty_ = pending_duty_ = 0.0;
  lateness_.Clear();
  ticks_ = overruns_ = 0;
  if (config_.realtime) {
    // Linux delays timer wake-ups by the thread's timer slack (50 us by default) to batch them: that alone
    // would make every tick of a 20 kHz loop late. A paced bench asks for 1 ns.
    prctl(PR_SET_TIMERSLACK, 1UL, 0UL, 0UL, 0UL);
  }
  wall_start_ = std::chrono::steady_clock::now();
  running_ = true;
  return Status::Ok();
}

Status EmulatedBench::Apply(const SwitchCommand& command) {
  if (!running_) return Status::FailedPrecondition("bench " + opt_.name + " is not running");
  if (command.mode == SwitchCommand::Mode::kGate) {
    if (!model::AcceptsGate(opt_.driver.kind, command.gate))
      return Status::FailedPrecondition("gate " + std::to_string(command.gate) + " needs an H-bridge; bench " +
                                        opt_.name + " has " + caps_.driver);
    pwm_mode_ = false;
    sim_.SetGate(command.gate);
    return Status::Ok();
  }
  if (!(command.carrier_Hz >= caps_.min_carrier_Hz && command.carrier_Hz <= caps_.max_carrier_Hz))
    return Status::FailedPrecondition("carrier_Hz outside the bench's PWM range");
  const double duty = std::clamp(command.duty, 0.0, 1.0);
  const double period = 1.0 / command.carrier_Hz;
  if (!pwm_mode_ || period != period_s_ || command.restart_carrier) {
    pwm_mode_ = true;
    period_s_ = period;
    origin_s_ = sim_.t_s();
    period_index_ = 0;
    duty_ = pending_duty_ = duty;
    sim_.SetGate(duty > 0.0 ? 1 : 0);
  } else {
    pending_duty_ = duty;  // latched at the next period start
  }
  return Status::Ok();
}

void EmulatedBench::RunPwmTo(double t_s) {
  // A cancel lands within one PWM edge, or one slice of a constant gate (an open-loop segment of minutes is
  // one step for the Runner): docs/server.md, "Cancel".
  constexpr double kCancelSlice_s = 0.01;
  while (sim_.t_s() < t_s && !sim_.failed()) {
    if (CancelSet()) return;
    if (!pwm_mode_) {
      if (cancel_ == nullptr) {
        sim_.AdvanceTo(t_s, &forwarder_);
        return;
      }
      sim_.AdvanceTo(std::min(t_s, sim_.t_s() + kCancelSlice_s), &forwarder_);
      continue;
    }
    const double t_period = origin_s_ + static_cast<double>(period_index_) * period_s_;
    const double t_fall = t_period + duty_ * period_s_;
    const double t_next = origin_s_ + static_cast<double>(period_index_ + 1) * period_s_;
    const bool falling = sim_.gate() == 1 && duty_ < 1.0 && sim_.t_s() < t_fall;
    const double edge = falling ? t_fall : t_next;
    if (edge > t_s) {
      sim_.AdvanceTo(t_s, &forwarder_);
      return;
    }
    sim_.AdvanceTo(edge, &forwarder_);
    if (falling) {
      sim_.SetGate(0);
    } else {
      ++period_index_;
      duty_ = pending_duty_;
      sim_.SetGate(duty_ > 0.0 ? 1 : 0);
    }
  }
}

Status EmulatedBench::AdvanceTo(double t_s, Measurement* m) {
  if (!running_) return Status::FailedPrecondition("bench " + opt_.name + " is not running");
  RunPwmTo(t_s);
  if (sim_.t_s() < t_s && CancelSet() && !sim_.failed())
    return Status::Aborted("cancelled at t = " + std::to_string(sim_.t_s()) + " s");
  if (sim_.failed()) {
    // The emulator's watchdog stopped the plant (docs/model.md): the run fails with the reason, as a real
    // bench's fault would; nothing hangs.
    return Status::Aborted("emulator stopped at t = " + std::to_string(sim_.failure_t_s()) + " s: " + sim_.failure());
  }
  if (config_.realtime) {
    const auto deadline = wall_start_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                            std::chrono::duration<double>(t_s));
    ++ticks_;
    if (std::chrono::steady_clock::now() > deadline) ++overruns_;
    // Absolute deadline on the monotonic clock (steady_clock is CLOCK_MONOTONIC on Linux): no drift.
    const auto ns = std::chrono::duration_cast<std::chrono::nanoseconds>(deadline.time_since_epoch()).count();
    timespec ts{static_cast<time_t>(ns / 1'000'000'000), static_cast<long>(ns % 1'000'000'000)};
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr) == EINTR) {
    }
    lateness_.Add(std::chrono::duration<double>(std::chrono::steady_clock::now() - deadline).count());
  }
  if (m != nullptr) {
    m->t_s = sim_.t_s();
    m->current_A = sim_.measured_current_A();  // what the current sensor reports (sensor_lag)
    m->position_m = caps_.measures_position ? sim_.x_m() : kNotMeasured;
    m->velocity_mps = caps_.measures_velocity ? sim_.v_mps() : kNotMeasured;
    m->supply_V = config_.supply_V;
  }
  return Status::Ok();
}

Status EmulatedBench::Stop() {
  if (!running_) return Status::Ok();
  sim_.EmitPendingSample(&forwarder_);
  SafeState();
  running_ = false;
  return Status::Ok();
}

void EmulatedBench::SafeState() noexcept {
  pwm_mode_ = false;
  sim_.SetGate(0);
}

LoopStats EmulatedBench::loop_stats() const {
  LoopStats s;
  s.ticks = ticks_;
  s.overruns = overruns_;
  s.jitter_p50_s = lateness_.Percentile(0.5);
  s.jitter_p99_s = lateness_.Percentile(0.99);
  s.jitter_max_s = lateness_.max();
  return s;
}

}  // namespace vb::hw
