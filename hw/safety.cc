#include "common/format.h"
#include "hw/safety.h"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace vb::hw {

namespace {

std::int64_t NowNs() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(std::chrono::steady_clock::now().time_since_epoch())
      .count();
}

constexpr double kCopperAlpha_per_K = 0.00393;

}  // namespace

Status SafetyLimits::Validate() const {
  auto bad = [](const char* field, const std::string& what) {
    return Status::InvalidArgument(std::string("safety.") + field + ": " + what);
  };
  if (!(max_current_A >= 0.0)) return bad("max_current_A", "must be >= 0, got " + FormatNumber(max_current_A));
  if (!(max_duty > 0.0 && max_duty <= 1.0)) return bad("max_duty", "must be in (0, 1], got " + FormatNumber(max_duty));
  if (!(max_on_time_s >= 0.0)) return bad("max_on_time_s", "must be >= 0, got " + FormatNumber(max_on_time_s));
  if (!(watchdog_s >= 0.0)) return bad("watchdog_s", "must be >= 0, got " + FormatNumber(watchdog_s));
  if (!(check_period_s > 0.0)) return bad("check_period_s", "must be > 0, got " + FormatNumber(check_period_s));
  if (!(max_coil_temp_C >= 0.0)) return bad("max_coil_temp_C", "must be >= 0, got " + FormatNumber(max_coil_temp_C));
  if (max_coil_temp_C > 0.0) {
    if (!(coil_R_ohm > 0.0)) return bad("coil_R_ohm", "must be > 0 for the temperature estimate");
    if (!(thermal_resistance_K_per_W > 0.0))
      return bad("thermal_resistance_K_per_W", "must be > 0 for the temperature estimate");
    if (!(thermal_time_constant_s > 0.0))
      return bad("thermal_time_constant_s", "must be > 0 for the temperature estimate");
    if (!(max_coil_temp_C > ambient_C)) return bad("max_coil_temp_C", "must be above ambient_C");
  }
  return Status::Ok();
}

SafetyBench::SafetyBench(Bench* inner, SafetyLimits limits) : inner_(inner), lim_(limits) {
  caps_ = inner_->capabilities();
  max_current_A_ = lim_.max_current_A > 0.0 ? lim_.max_current_A : caps_.max_current_A;
  if (caps_.max_current_A <= 0.0 || max_current_A_ < caps_.max_current_A) caps_.max_current_A = max_current_A_;
  guard_.self = this;
}

SafetyBench::~SafetyBench() {
  StopWatchdog();
}

bool SafetyBench::Claim(std::string reason) {
  bool expected = false;
  if (!claimed_.compare_exchange_strong(expected, true)) return false;
  reason_ = "safety: " + std::move(reason);
  tripped_.store(true, std::memory_order_release);
  return true;
}

Status SafetyBench::Tripped() const {
  while (!tripped_.load(std::memory_order_acquire)) {
  }  // a concurrent Claim() is writing the reason
  return Status::Aborted(reason_);
}

Status SafetyBench::Trip(std::string reason) {
  Claim(std::move(reason));
  {
    std::lock_guard<std::mutex> lock(inner_mu_);
    inner_->SafeState();
  }
  safe_after_trip_.store(true, std::memory_order_release);
  on_ = false;
  return Tripped();
}

Status SafetyBench::Configure(const RunConfig& config) {
  VB_RETURN_IF_ERROR(lim_.Validate());
  std::lock_guard<std::mutex> lock(inner_mu_);
  return inner_->Configure(config);
}

void SafetyBench::Beat() { last_beat_ns_.store(NowNs(), std::memory_order_relaxed); }

Status SafetyBench::Start(SampleSink* sink) {
  StopWatchdog();
  claimed_.store(false);
  tripped_.store(false);
  reason_.clear();
  t_s_ = 0.0;
  temp_C_ = lim_.ambient_C;
  last_i_A_ = 0.0;
  on_ = false;
  sample_trip_t_s_ = std::numeric_limits<double>::quiet_NaN();
  guard_.next = sink;
  {
    std::lock_guard<std::mutex> lock(inner_mu_);
    VB_RETURN_IF_ERROR(inner_->Start(&guard_));
  }
  running_ = true;
  Beat();
  if (lim_.watchdog_s > 0.0) {
    wd_stop_ = false;
    watchdog_ = std::thread([this] { WatchdogLoop(); });
  }
  return Status::Ok();
}

void SafetyBench::WatchdogLoop() {
  const auto period = std::chrono::duration<double>(lim_.watchdog_s / 4.0);
  std::unique_lock<std::mutex> lock(wd_mu_);
  while (!wd_stop_) {
    wd_cv_.wait_for(lock, period);
    if (wd_stop_) break;
    const double idle_s = (NowNs() - last_beat_ns_.load(std::memory_order_relaxed)) * 1e-9;
    if (idle_s <= lim_.watchdog_s) continue;
    // The loop is not calling: take the bench if it is free (try_lock: never make the loop wait on us).
    if (inner_mu_.try_lock()) {
      Claim("software watchdog: no call from the control loop for " + FormatNumber(idle_s) + " s (limit " +
            FormatNumber(lim_.watchdog_s) + " s)");
      inner_->SafeState();
      if (tripped_.load()) safe_after_trip_.store(true, std::memory_order_release);
      inner_mu_.unlock();
      if (tripped_.load()) break;
    }
  }
}

void SafetyBench::StopWatchdog() {
  {
    std::lock_guard<std::mutex> lock(wd_mu_);
    wd_stop_ = true;
  }
  wd_cv_.notify_all();
  if (watchdog_.joinable()) watchdog_.join();
}

void SafetyBench::Guard::OnSample(const BenchSample& s) {
  if (std::isnan(self->sample_trip_t_s_) && !(std::abs(s.i_A) <= self->max_current_A_) && !std::isnan(s.i_A)) {
    self->sample_trip_t_s_ = s.t_s;
    self->sample_trip_i_A_ = s.i_A;
  }
  if (next != nullptr) next->OnSample(s);
}

Status SafetyBench::Check(const Measurement& m, double t_s) {
  if (!std::isnan(sample_trip_t_s_))
    return Trip("coil current " + FormatNumber(sample_trip_i_A_) + " A exceeds the limit of " + FormatNumber(max_current_A_) +
                " A at t = " + FormatNumber(sample_trip_t_s_) + " s");
  if (std::isnan(m.current_A)) return Trip("the current measurement at t = " + FormatNumber(t_s) + " s is not a number");
  if (!(std::abs(m.current_A) <= max_current_A_))
    return Trip("coil current " + FormatNumber(m.current_A) + " A exceeds the limit of " + FormatNumber(max_current_A_) +
                " A at t = " + FormatNumber(t_s) + " s");
  if (m.t_s < t_s - 1e-9)
    return Trip("stale measurement: it is from t = " + FormatNumber(m.t_s) + " s at the tick t = " + FormatNumber(t_s) + " s");
  const double dt = t_s - t_s_;
  if (lim_.max_coil_temp_C > 0.0 && dt > 0.0) {
    const double R = lim_.coil_R_ohm * (1.0 + kCopperAlpha_per_K * (temp_C_ - 20.0));
    const double i = 0.5 * (std::abs(last_i_A_) + std::abs(m.current_A));
    const double t_inf = lim_.ambient_C + i * i * R * lim_.thermal_resistance_K_per_W;
    temp_C_ = t_inf + (temp_C_ - t_inf) * std::exp(-dt / lim_.thermal_time_constant_s);
    if (temp_C_ > lim_.max_coil_temp_C)
      return Trip("estimated coil temperature " + FormatNumber(temp_C_) + " C exceeds the limit of " +
                  FormatNumber(lim_.max_coil_temp_C) + " C at t = " + FormatNumber(t_s) + " s");
  }
  last_i_A_ = m.current_A;
  t_s_ = std::max(t_s_, t_s);
  if (on_ && lim_.max_on_time_s > 0.0 && t_s - on_since_s_ > lim_.max_on_time_s)
    return Trip("the gate was held high for " + FormatNumber(t_s - on_since_s_) + " s, over the continuous on-time limit of " +
                FormatNumber(lim_.max_on_time_s) + " s (t = " + FormatNumber(t_s) + " s)");
  return Status::Ok();
}

Status SafetyBench::AdvanceTo(double t_s, Measurement* m) {
  Beat();
  if (tripped_.load(std::memory_order_acquire)) return Tripped();
  Measurement local;
  Measurement* out = m != nullptr ? m : &local;
  // In pieces of at most check_period_s, so a trip stops the coil within that much bench time.
  double t = t_s_;
  do {
    if (cancel_ != nullptr && cancel_->load(std::memory_order_relaxed)) {
      SafeState();
      return Status::Aborted("cancelled at t = " + FormatNumber(t) + " s");
    }
    t = std::min(t_s, t + lim_.check_period_s);
    if (t_s - t < 1e-12) t = t_s;
    Status st;
    {
      std::lock_guard<std::mutex> lock(inner_mu_);
      st = inner_->AdvanceTo(t, out);
    }
    if (!st.ok()) return Trip("bench error at t = " + FormatNumber(t) + " s: " + st.message());
    VB_RETURN_IF_ERROR(Check(*out, t));
    Beat();  // a paced bench may take many watchdog periods of wall time for one long step
  } while (t < t_s);
  Beat();
  return Status::Ok();
}

Status SafetyBench::Apply(const SwitchCommand& c) {
  Beat();
  if (tripped_.load(std::memory_order_acquire)) return Tripped();
  if (c.mode == SwitchCommand::Mode::kPwm && c.duty > lim_.max_duty)
    return Trip("duty " + FormatNumber(c.duty) + " exceeds the limit of " + FormatNumber(lim_.max_duty) + " at t = " + FormatNumber(t_s_) + " s");
  const bool on = c.mode == SwitchCommand::Mode::kGate ? c.gate != 0 : c.duty >= 1.0;
  if (on && !on_) on_since_s_ = t_s_;
  on_ = on;
  Status st;
  {
    std::lock_guard<std::mutex> lock(inner_mu_);
    st = inner_->Apply(c);
  }
  if (!st.ok() && st.code() != StatusCode::kFailedPrecondition && st.code() != StatusCode::kInvalidArgument)
    return Trip("bench error at t = " + FormatNumber(t_s_) + " s: " + st.message());
  return st;  // a command the bench cannot realise is the caller's error, not a trip (the Runner fails the run)
}

Status SafetyBench::Stop() {
  StopWatchdog();
  running_ = false;
  std::lock_guard<std::mutex> lock(inner_mu_);
  Status st = inner_->Stop();
  inner_->SafeState();
  if (tripped_.load(std::memory_order_acquire)) return Tripped();
  return st;
}

void SafetyBench::SafeState() noexcept {
  std::lock_guard<std::mutex> lock(inner_mu_);
  inner_->SafeState();
  on_ = false;
}

}  // namespace vb::hw
