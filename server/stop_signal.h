// The sleeps of a server's background thread (the nights, retention) that Stop() cuts short: until a wall-clock
// instant, re-reading the clock at least each minute (it may be set meanwhile), or for a while.
#pragma once

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <functional>
#include <mutex>
#include <utility>

namespace vb::server {

class StopSignal {
 public:
  using ClockFn = std::function<double()>;  // wall clock, unix seconds
  explicit StopSignal(ClockFn clock) : clock_(std::move(clock)) {}

  void Stop() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      stop_ = true;
    }
    cv_.notify_all();
  }
  bool stopped() {
    std::lock_guard<std::mutex> lock(mu_);
    return stop_;
  }
  // False when stopped before t_unix_s.
  bool SleepUntil(double t_unix_s) {
    std::unique_lock<std::mutex> lock(mu_);
    for (;;) {
      if (stop_) return false;
      const double left_s = t_unix_s - clock_();
      if (left_s <= 0.0) return true;
      cv_.wait_for(lock, std::chrono::duration<double>(std::min(left_s, 60.0)), [this] { return stop_; });
    }
  }
  // False when stopped.
  bool SleepFor(double s) {
    std::unique_lock<std::mutex> lock(mu_);
    return !cv_.wait_for(lock, std::chrono::duration<double>(s), [this] { return stop_; });
  }

 private:
  ClockFn clock_;
  std::mutex mu_;
  std::condition_variable cv_;
  bool stop_ = false;
};

}  // namespace vb::server
