#include "runs/store_faults.h"

#include <algorithm>
#include <cmath>
#include <thread>

#include <spdlog/spdlog.h>

#include "common/format.h"

namespace vb::runs {

void FaultLog::Failed(const Status& st, Clock::time_point call_began) {
  if (failures_++ == 0) {
    began_ = call_began;
    spdlog::warn("{}: store unavailable, retrying (logged again when it is back): {}", who_, st.message());
  }
}

void FaultLog::Recovered() {
  if (failures_ == 0) return;
  spdlog::info("{}: store reachable again after {} s ({} call(s) failed meanwhile)", who_,
               FormatNumber(std::round(fault_s() * 10) / 10), failures_);
  failures_ = 0;
}

double FaultLog::fault_s() const {
  if (failures_ == 0) return 0.0;
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - began_).count();
}

Status RetryWrite(const std::function<Status()>& write, const RetryPolicy& policy, FaultLog* log) {
  using Clock = std::chrono::steady_clock;
  const Clock::time_point start = Clock::now();
  double wait_s = policy.first_wait_s;
  while (true) {
    const Clock::time_point call_began = Clock::now();
    Status st = write();
    if (db::ClassifyWrite(st) != db::WriteFault::kTransient) {
      if (log != nullptr && st.ok()) log->Recovered();
      return st;
    }
    if (log != nullptr) log->Failed(st, call_began);
    const double waited_s = std::chrono::duration<double>(Clock::now() - start).count();
    if (waited_s >= policy.give_up_s || (policy.stop != nullptr && policy.stop->load())) return st;
    // Sleep in short steps so a stop is seen at once.
    const Clock::time_point until =
        Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(wait_s));
    while (Clock::now() < until && !(policy.stop != nullptr && policy.stop->load()))
      std::this_thread::sleep_for(std::min<Clock::duration>(until - Clock::now(), std::chrono::milliseconds(20)));
    wait_s = std::min(policy.max_wait_s, wait_s * 2);
  }
}

}  // namespace vb::runs
