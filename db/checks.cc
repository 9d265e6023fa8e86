#include "db/checks.h"

#include <cmath>
#include <set>
#include <string_view>
#include <unordered_set>
#include <utility>

#include "common/format.h"
#include "db/text.h"

namespace vb::db::checks {

// Output-only RunRecord fields (id, batch_id, status, reason, times, progress) are ignored on submit, as
// output-only fields of an API resource are; everything else is checked here.
Status ValidateBatch(const std::string& submitter, const std::vector<RunRecord>& runs) {
  if (submitter.empty()) return Status::InvalidArgument("submitter: must not be empty");
  if (runs.empty()) return Status::InvalidArgument("runs: a batch needs at least one run");
  for (std::size_t k = 0; k < runs.size(); ++k) {
    const RunRecord& r = runs[k];
    const std::string field = Cat("runs[", k, "]");
    if (r.key.name.empty()) return Status::InvalidArgument(field + ".key.name: must not be empty");
    if (r.key.repeat < -1) return Status::InvalidArgument(Cat(field, ".key.repeat: must be >= -1, got ", r.key.repeat));
    for (std::size_t a = 0; a < r.key.sweep.size(); ++a) {
      if (r.key.sweep[a].field.empty())
        return Status::InvalidArgument(Cat(field, ".key.sweep[", a, "].field: must not be empty"));
      if (!std::isfinite(r.key.sweep[a].value))
        return Status::InvalidArgument(Cat(field, ".key.sweep[", a, "].value: must be finite"));
    }
    if (!r.split.empty() && r.split != "fit" && r.split != "holdout")
      return Status::InvalidArgument(Cat(field, ".split: must be \"fit\", \"holdout\" or empty, got \"", r.split, "\""));
    if (r.spec_json.empty()) return Status::InvalidArgument(field + ".spec_json: must not be empty");
    if (!r.submitter.empty() && r.submitter != submitter) {
      return Status::InvalidArgument(
          Cat(field, ".submitter: \"", r.submitter, "\" differs from the batch's \"", submitter, "\""));
    }
    std::unordered_set<std::string_view> tags;
    for (std::size_t j = 0; j < r.tags.size(); ++j) {
      const std::string tag_field = Cat(field, ".tags[", j, "]");
      if (r.tags[j].empty()) return Status::InvalidArgument(tag_field + ": must not be empty");
      if (!tags.insert(r.tags[j]).second) {
        return Status::InvalidArgument(Cat(tag_field, ": duplicate tag \"", r.tags[j], "\""));
      }
    }
  }
  return Status::Ok();
}

Status ValidateFilter(const RunFilter& f) {
  if (f.limit < 1 || f.limit > kMaxListLimit) {
    return Status::InvalidArgument(Cat("filter.limit: must be in 1..", kMaxListLimit, ", got ", f.limit));
  }
  if (f.after_id < 0) return Status::InvalidArgument(Cat("filter.after_id: must be >= 0, got ", f.after_id));
  if (f.batch_id < 0) return Status::InvalidArgument(Cat("filter.batch_id: must be >= 0, got ", f.batch_id));
  if (f.after && (!std::isfinite(f.after->number) || f.after->id < 0))
    return Status::InvalidArgument("filter.after: the cursor's key must be finite and its id >= 0");
  if (!std::isfinite(f.submitted_after_unix_s) || f.submitted_after_unix_s < 0) {
    return Status::InvalidArgument(
        Cat("filter.submitted_after_unix_s: must be finite and >= 0, got ", FormatExact(f.submitted_after_unix_s)));
  }
  if (!std::isfinite(f.submitted_before_unix_s) || f.submitted_before_unix_s < 0) {
    return Status::InvalidArgument(
        Cat("filter.submitted_before_unix_s: must be finite and >= 0, got ", FormatExact(f.submitted_before_unix_s)));
  }
  return Status::Ok();
}

Status ValidateBaseline(const std::string& name, const std::vector<BaselineEntry>& entries) {
  if (name.empty()) return Status::InvalidArgument("baseline.name: must not be empty");
  for (char c : name)
    if (static_cast<unsigned char>(c) < 0x20)
      return Status::InvalidArgument("baseline.name: must not contain control characters");
  if (entries.empty()) return Status::InvalidArgument("baseline.entries: a baseline needs at least one metric value");
  std::set<std::pair<std::string, std::string>> seen;
  for (std::size_t k = 0; k < entries.size(); ++k) {
    const BaselineEntry& e = entries[k];
    const std::string where = Cat("baseline.entries[", k, "]");
    if (e.case_name.empty()) return Status::InvalidArgument(where + ".case_name: must not be empty");
    if (e.metric.empty()) return Status::InvalidArgument(where + ".metric: must not be empty");
    if (!std::isfinite(e.mean)) return Status::InvalidArgument(where + ".mean: must be finite");
    if (!std::isfinite(e.spread) || e.spread < 0) return Status::InvalidArgument(where + ".spread: must be finite and >= 0");
    if (e.n < 1) return Status::InvalidArgument(where + ".n: must be >= 1");
    if (!seen.insert({e.case_name, e.metric}).second)
      return Status::InvalidArgument(Cat(where, ": duplicate (", e.case_name, ", ", e.metric, ")"));
  }
  return Status::Ok();
}

Status CheckNightClaim(const std::string& night, const std::string& host) {
  bool date_like = night.size() == 10 && night[4] == '-' && night[7] == '-';
  for (std::size_t k : {0, 1, 2, 3, 5, 6, 8, 9}) date_like = date_like && night[k] >= '0' && night[k] <= '9';
  if (!date_like) return Status::InvalidArgument(Cat("night: must be YYYY-MM-DD, got \"", night, "\""));
  if (host.empty()) return Status::InvalidArgument("host: must not be empty");
  return Status::Ok();
}

Status CheckClaim(const ClaimRequest& request) {
  if (request.bench_name.empty()) return Status::InvalidArgument("bench_name: must name the bench that claims the run");
  if (!std::isfinite(request.lease_ttl_s) || request.lease_ttl_s < 0)
    return Status::InvalidArgument(Cat("lease_ttl_s: must be finite and >= 0, got ", FormatExact(request.lease_ttl_s)));
  if (!std::isfinite(request.aging_s) || request.aging_s < 0)
    return Status::InvalidArgument(Cat("aging_s: must be finite and >= 0, got ", FormatExact(request.aging_s)));
  return Status::Ok();
}

Status CheckProgress(double progress) {
  if (!(progress >= 0.0 && progress <= 1.0))
    return Status::InvalidArgument(Cat("progress: must be in [0, 1], got ", FormatExact(progress)));
  return Status::Ok();
}

Status CheckFinish(RunStatus final_status, const std::vector<Metric>& metrics) {
  if (final_status != RunStatus::kDone && final_status != RunStatus::kFailed && final_status != RunStatus::kCancelled) {
    return Status::InvalidArgument(
        Cat("final_status: must be done, failed or cancelled, got ", RunStatusName(final_status)));
  }
  std::unordered_set<std::string_view> names;
  for (std::size_t k = 0; k < metrics.size(); ++k) {
    const std::string field = Cat("metrics[", k, "].name");
    if (metrics[k].name.empty()) return Status::InvalidArgument(field + ": must not be empty");
    if (!names.insert(metrics[k].name).second)
      return Status::InvalidArgument(Cat(field, ": duplicate metric \"", metrics[k].name, "\""));
  }
  return Status::Ok();
}

Status CheckExecution(const ExecutionRecord& e) {
  auto at_least_0 = [](const char* field, double v) -> Status {
    if (!std::isfinite(v) || v < 0.0)
      return Status::InvalidArgument(Cat("execution.", field, ": must be finite and >= 0, got ", v));
    return Status::Ok();
  };
  VB_RETURN_IF_ERROR(at_least_0("wall_s", e.wall_s));
  VB_RETURN_IF_ERROR(at_least_0("simulated_s", e.simulated_s));
  VB_RETURN_IF_ERROR(at_least_0("samples", static_cast<double>(e.samples)));
  VB_RETURN_IF_ERROR(at_least_0("control_ticks", static_cast<double>(e.control_ticks)));
  if (e.loop) {
    VB_RETURN_IF_ERROR(at_least_0("loop.ticks", static_cast<double>(e.loop->ticks)));
    VB_RETURN_IF_ERROR(at_least_0("loop.overruns", static_cast<double>(e.loop->overruns)));
    for (const auto& [field, v] : {std::pair{"loop.jitter_p50_s", e.loop->jitter_p50_s},
                                   std::pair{"loop.jitter_p99_s", e.loop->jitter_p99_s},
                                   std::pair{"loop.jitter_max_s", e.loop->jitter_max_s}})
      if (!std::isfinite(v)) return Status::InvalidArgument(Cat("execution.", field, ": must be finite, got ", v));
  }
  // A build is a short printable name ("valvebench 0.1.0 sha256:<32 hex>"); 200 characters leave room for a
  // longer version string and keep a row's size bounded.
  if (e.build.size() > 200)
    return Status::InvalidArgument(Cat("execution.build: at most 200 characters, got ", e.build.size()));
  for (unsigned char c : e.build)
    if (c < 0x20 || c > 0x7e)
      return Status::InvalidArgument(Cat("execution.build: printable ASCII only, got byte ", static_cast<int>(c)));
  return Status::Ok();
}

Status CheckListLimit(std::int32_t limit) {
  if (limit < 1 || limit > kMaxListLimit)
    return Status::InvalidArgument(Cat("limit: must be in 1..", kMaxListLimit, ", got ", limit));
  return Status::Ok();
}

Status CheckPrune(const PruneRequest& request) {
  if (!std::isfinite(request.finished_before_unix_s) || request.finished_before_unix_s <= 0) {
    return Status::InvalidArgument(
        Cat("finished_before_unix_s: must be a finite time > 0, got ", FormatExact(request.finished_before_unix_s)));
  }
  if (request.keep_last < 0) return Status::InvalidArgument(Cat("keep_last: must be >= 0, got ", request.keep_last));
  for (std::size_t k = 0; k < request.protected_batches.size(); ++k) {
    if (request.protected_batches[k] <= 0) {
      return Status::InvalidArgument(
          Cat("protected_batches[", k, "]: must be a batch id > 0, got ", request.protected_batches[k]));
    }
  }
  return Status::Ok();
}

Status CheckRegression(const RegressionRecord& record) {
  if (record.suite.empty()) return Status::InvalidArgument("regression.suite: must not be empty");
  if (record.verdict.empty()) return Status::InvalidArgument("regression.verdict: must not be empty");
  return Status::Ok();
}

Status CheckHeartbeat(const HostRecord& host, double lease_ttl_s) {
  if (host.name.empty()) return Status::InvalidArgument("host.name: must not be empty");
  if (!std::isfinite(lease_ttl_s) || lease_ttl_s < 0)
    return Status::InvalidArgument(Cat("lease_ttl_s: must be finite and >= 0, got ", FormatExact(lease_ttl_s)));
  if (!std::isfinite(host.started_unix_s) || host.started_unix_s < 0) {
    return Status::InvalidArgument(
        Cat("host.started_unix_s: must be finite and >= 0, got ", FormatExact(host.started_unix_s)));
  }
  return Status::Ok();
}

}  // namespace vb::db::checks
