// One server per store (issue 27, point 5; docs/server.md "One server per store", docs/lab.md "Hosts").
//
// A second valvebench-server on the same store recovers the first one's running runs as "interrupted" at its
// start and then claims from the same queue: cancels get lost and a bench runs two runs at once. The lock a
// server takes before it touches the store keeps that from happening:
//
// - SQLite: a lock file beside the database (its real path, symlinks resolved, + ".lock"), held with flock(2)
//   for the server's lifetime. A lone server holds it exclusively. A lab host (several hosts sharing one file on
//   one machine) holds it shared, and holds "<db>.host-<host>.lock" exclusively: one process per host identity,
//   and no lone server beside a lab. The holder writes its pid, machine and host into the file it holds
//   exclusively, so a refused server names it. The kernel drops a flock when its holder dies, so a crashed or
//   SIGKILLed server never blocks the next one; a stale file's text is only read when the lock is really held.
// - PostgreSQL: session-level advisory locks on a connection kept open for the server's lifetime: the store-wide
//   key (a lone server exclusive, lab hosts shared) and the host's key (hashtext of the host identity). The
//   session's application_name names the holder, read back from pg_locks/pg_stat_activity on refusal.
//   PostgreSQL releases them when the session ends; the session asks for TCP keepalives so that a host that
//   vanished without closing its connection frees its identity within ~15 s.
//
// Clients of the store (benchctl --local, benchctl db, Python's local mode) take no lock: they may run beside
// a server as before. ":memory:" stores are the process's own and take none.
#pragma once

#include <memory>
#include <string>

#include "common/status.h"

namespace vb::server {

class InstanceLock {
 public:
  // location: the store (the config's database_path, resolved). host: the lab host identity, or "" for a server
  // that is not in a lab. FailedPrecondition naming the holder when another live process holds it; Unavailable
  // when the lock itself cannot be taken (an unwritable directory, an unreachable PostgreSQL).
  static StatusOr<std::unique_ptr<InstanceLock>> Acquire(const std::string& location, const std::string& host);

  ~InstanceLock();  // releases (process exit does too)
  InstanceLock(const InstanceLock&) = delete;
  InstanceLock& operator=(const InstanceLock&) = delete;

  // What the lock covers, for the log: "/var/lib/valvebench/runs.db.lock" or "postgresql advisory lock ...".
  const std::string& description() const { return description_; }

  // The lock file of a SQLite store at `db_path` (symlinks resolved), and a lab host's own; exposed for tests.
  static std::string StoreLockPath(const std::string& db_path);
  static std::string HostLockPath(const std::string& db_path, const std::string& host);

 private:
  InstanceLock() = default;
  std::string description_;
  int store_fd_ = -1;   // SQLite: the store's lock file
  int host_fd_ = -1;    // SQLite lab: the host's lock file
  void* pg_ = nullptr;  // PostgreSQL: the PGconn holding the advisory locks
};

}  // namespace vb::server
