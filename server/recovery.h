// What a server does at start before any worker claims (docs/lab.md, "The spool"; issue 39):
//   1. the host's spool (config spool_dir): what an earlier process left in it is uploaded (a run whose result
//      it holds is finished with that result, its trace complete), journals without a result are dropped;
//   2. this host's runs still marked running are interrupted (RecoverAfterCrash), dated with the time that
//      process stopped (the spool's last sign of life) rather than now, and re-queued.
// A spool whose leftovers cannot be uploaded (the store stays unavailable) is an error: the server exits 3 and
// systemd restarts it, the journals kept.
#pragma once

#include <memory>
#include <string>

#include "common/status.h"
#include "db/store.h"
#include "runs/spool.h"
#include "server/config.h"

namespace vb::server {

struct Recovery {
  std::unique_ptr<runs::Spool> spool;  // nullptr: no spool configured
  int interrupted = 0;
  double stopped_unix_s = 0.0;         // 0: unknown (no spool, or it never ran)
};

// host: the lab host ("" = one machine). The spool is open but its uploader not started (Spool::Start).
StatusOr<Recovery> RecoverAtStart(const Settings& settings, const std::string& host, db::Store* store);

}  // namespace vb::server
