// The run lifecycle's rules that both store engines apply (db/sqlite_store.cc, db/pg_store.cc): what an interrupted run
// becomes, when a write under a lease is stale and what the refusal says, how a stored status is read back, and
// a run row's columns mapped to a RunRecord. One copy, so the engines cannot drift apart in what they decide or
// say (they did: the lapsed-lease reason and the stale-write text differed). Internal to db/.
#pragma once

#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

#include "common/status.h"
#include "db/records.h"
#include "db/text.h"

namespace vb::db::rules {

inline constexpr const char* kRecoverReason = "server restarted while running";
// A run interrupted by a server stop this many times is failed, not re-queued again: whatever it does (a spec
// that exhausts memory, a bench that crashes the process) would take the server down at every start.
inline constexpr int kMaxInterruptions = 3;

// Why a run whose host stopped renewing its lease was interrupted.
std::string LapsedReason(const std::string& host);

// What an interrupted run becomes (after its 'interrupted' history entry): cancelled (a cancel was asked while it
// ran), failed (its kMaxInterruptions-th interruption: a poison run), queued again (requeue_on_interrupt), or it
// stays interrupted. `interruptions` counts the one just recorded.
struct AfterInterrupt {
  RunStatus status = RunStatus::kInterrupted;
  std::string reason;  // for the history entry and the run's reason
};
AfterInterrupt AfterInterruption(bool cancel_requested, const std::string& cancel_reason, bool requeue,
                                 std::int64_t interruptions, const std::string& interrupt_reason);

// The fencing check of every write under a lease (docs/lab.md, "Leases and fencing"): nullopt when the lease
// holds the run (it is running and its fence is the lease's), else the refusal's text, "stale write: ...". The
// engines log the refusal in stale_writes and return FailedPrecondition with this text.
std::optional<std::string> StaleWriteWhy(const Lease& lease, const std::string& what, RunStatus status,
                                         std::int64_t fence, const std::string& host);

Status RunNotFound(std::int64_t id);
// A status column read back: DataLoss naming `what` (e.g. "run 12") when it is no status.
StatusOr<RunStatus> StoredStatus(const std::string& text, std::string_view what);

// The columns of a run row (every engine selects them in this order: "id, batch_id, name, controller,
// bench_kind, bench_name, spec_json, submitter, priority, status, reason, requeue_on_interrupt, submitted,
// started, finished, progress, key_name, repeat_index, split, t_start_s, fence, host, lease_expires", then the
// execution's columns of schema v6 and its build of v7) into a RunRecord, sweep point and tags left to the
// engine. Row: Int(col), Text(col), Double(col), IsNull(col).
#define VB_DB_RUN_COLUMNS                                                                                     \
  "id, batch_id, name, controller, bench_kind, bench_name, spec_json, submitter, priority, status, reason, "  \
  "requeue_on_interrupt, submitted, started, finished, progress, key_name, repeat_index, split, t_start_s, " \
  "fence, host, lease_expires, exec_wall_s, exec_simulated_s, exec_samples, exec_control_ticks, "            \
  "exec_metrics_from_trajectory, loop_ticks, loop_overruns, loop_jitter_p50_s, loop_jitter_p99_s, "          \
  "loop_jitter_max_s, exec_build"
inline constexpr const char* kRunColumns = VB_DB_RUN_COLUMNS;
inline constexpr int kRunColumnCount = 34;


template <typename Row>
StatusOr<RunRecord> RunFromRow(const Row& row) {
  RunRecord r;
  r.id = row.Int(0);
  r.batch_id = row.Int(1);
  r.controller = row.Text(3);
  r.bench_kind = row.Text(4);
  r.bench_name = row.Text(5);
  r.spec_json = row.Text(6);
  r.submitter = row.Text(7);
  r.priority = static_cast<std::int32_t>(row.Int(8));
  StatusOr<RunStatus> status = StoredStatus(row.Text(9), Cat("run ", r.id));
  if (!status.ok()) return status.status();
  r.status = *status;
  r.reason = row.Text(10);
  r.requeue_on_interrupt = row.Int(11) != 0;
  r.submitted_unix_s = row.Double(12);
  r.started_unix_s = row.Double(13);
  r.finished_unix_s = row.Double(14);
  r.progress = row.Double(15);
  r.key.name = row.Text(16);
  r.key.repeat = static_cast<int>(row.Int(17));
  r.split = row.Text(18);
  if (!row.IsNull(19)) r.t_start_s = row.Double(19);
  r.fence = row.Int(20);
  r.host = row.Text(21);
  r.lease_expires_unix_s = row.Double(22);
  if (!row.IsNull(23)) {
    ExecutionRecord e;
    e.wall_s = row.Double(23);
    e.simulated_s = row.Double(24);
    e.samples = row.Int(25);
    e.control_ticks = row.Int(26);
    e.metrics_from_trajectory = row.Int(27) != 0;
    if (!row.IsNull(28)) {
      LoopRecord l;
      l.ticks = row.Int(28);
      l.overruns = row.Int(29);
      l.jitter_p50_s = row.Double(30);
      l.jitter_p99_s = row.Double(31);
      l.jitter_max_s = row.Double(32);
      e.loop = l;
    }
    if (!row.IsNull(33)) e.build = row.Text(33);
    r.execution = e;
  }
  return r;
}

}  // namespace vb::db::rules
