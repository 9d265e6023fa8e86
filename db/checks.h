// What every store engine checks before it touches its database, with the field-named messages callers see
// (db/store.h). One copy for SQLite (db/sqlite_store.cc) and PostgreSQL (db/pg_store.cc), so the engines cannot drift
// apart in what they accept or in what they say. Internal to db/.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/status.h"
#include "db/records.h"

namespace vb::db::checks {

inline constexpr std::int32_t kMaxListLimit = 1000;  // RunFilter::limit and the other list limits

// A batch to submit: identities, splits, specs, tags (output-only RunRecord fields are ignored).
Status ValidateBatch(const std::string& submitter, const std::vector<RunRecord>& runs);
Status ValidateFilter(const RunFilter& f);
Status ValidateBaseline(const std::string& name, const std::vector<BaselineEntry>& entries);
Status CheckClaim(const ClaimRequest& request);
Status CheckProgress(double progress);
Status CheckFinish(RunStatus final_status, const std::vector<Metric>& metrics);
// An execution record's numbers: finite, none negative (jitter may be negative: a wake-up before the deadline).
Status CheckExecution(const ExecutionRecord& execution);
Status CheckListLimit(std::int32_t limit);
Status CheckPrune(const PruneRequest& request);
Status CheckRegression(const RegressionRecord& record);
// ClaimNight's arguments: a YYYY-MM-DD night and a host name.
Status CheckNightClaim(const std::string& night, const std::string& host);
// Heartbeat's arguments: a named host, a finite lease TTL and start time >= 0.
Status CheckHeartbeat(const HostRecord& host, double lease_ttl_s);

}  // namespace vb::db::checks
