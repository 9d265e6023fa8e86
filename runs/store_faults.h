// Living with a store that fails for a while (docs/lab.md, "When the database fails"): a restarted PostgreSQL, a
// terminated session, a database that does not answer. Errors are told apart by db::ClassifyWrite (their code):
// transient ones are retried with a bounded backoff, a fenced (stale) write stops, anything else is an error.
//   - FaultLog: a fault is logged once when it begins and once when it ends, with its duration and the number of
//     calls that failed meanwhile (an outage wrote ~455 lines per host in 10 s: issue 30);
//   - RetryWrite: one write retried until it is done, fenced, permanently refused, or the caller gives up.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

#include "common/status.h"
#include "db/records.h"

namespace vb::runs {

class FaultLog {
 public:
  // `who` names the caller in the log lines: "bench emu-1", "lab".
  explicit FaultLog(std::string who) : who_(std::move(who)) {}
  using Clock = std::chrono::steady_clock;
  // A transient failure of a call that began at `call_began`: logged (warning) only when it begins a fault
  // (which then began when that call did: a call that waited 13 s for a stopped server counts them); later
  // ones are counted.
  void Failed(const Status& st, Clock::time_point call_began = Clock::now());
  // A call that worked: if a fault was in progress, logs its end with its duration and count.
  void Recovered();
  bool in_fault() const { return failures_ > 0; }
  // Seconds since the fault began (0 when none).
  double fault_s() const;

 private:
  std::string who_;
  std::int64_t failures_ = 0;
  std::chrono::steady_clock::time_point began_;
};

struct RetryPolicy {
  double first_wait_s = 0.05;             // the first retry's wait; doubled after each failure
  double max_wait_s = 1.0;                // bound on one wait
  double give_up_s = 120.0;               // stop retrying this long after the first failure
  const std::atomic<bool>* stop = nullptr;  // stop retrying at once (server shutdown)
};

// Calls `write` until it is not a transient failure (db::WriteFault::kTransient), waiting between tries per
// `policy`; returns its last status (a transient one when the policy gave up). Failures and the recovery go to
// `log` (may be nullptr).
Status RetryWrite(const std::function<Status()>& write, const RetryPolicy& policy, FaultLog* log);

}  // namespace vb::runs
