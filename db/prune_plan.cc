#include "db/prune_plan.h"

#include <algorithm>
#include <limits>
#include <set>
#include <string_view>

#include <nlohmann/json.hpp>

#include "common/format.h"
#include "db/text.h"

namespace vb::db {
namespace {

// The batch number at source[k...] (digits up to a non-digit), else 0.
std::int64_t BatchNumberAt(const std::string& source, std::size_t k) {
  if (k >= source.size() || source[k] < '0' || source[k] > '9') return 0;
  std::int64_t batch = 0;
  for (; k < source.size() && source[k] >= '0' && source[k] <= '9'; ++k) {
    if (batch > (std::numeric_limits<std::int64_t>::max() - 9) / 10) return 0;
    batch = batch * 10 + (source[k] - '0');
  }
  return batch;
}

}  // namespace

std::int64_t LocalBatchOfBaselineSource(const std::string& source) {
  // "local batch 12" (baseline set --batch 12 --local) or "suite ci (local batch 12, seed 1)" (--suite).
  constexpr std::string_view kMarker = "local batch ";
  const std::size_t at = source.find(kMarker);
  if (at == std::string::npos || (at > 0 && source[at - 1] != ' ' && source[at - 1] != '(')) return 0;
  return BatchNumberAt(source, at + kMarker.size());
}

std::int64_t ServerBatchOfBaselineSource(const std::string& source) {
  // "server lab:50051 batch 12" or "suite ci (server lab:50051 batch 12, seed 1)".
  const std::size_t server = source.find("server ");
  if (server == std::string::npos) return 0;
  constexpr std::string_view kMarker = " batch ";
  const std::size_t at = source.find(kMarker, server);
  if (at == std::string::npos) return 0;
  return BatchNumberAt(source, at + kMarker.size());
}

std::vector<std::int64_t> HealthBatchesOfNight(const std::string& result_json) {
  std::vector<std::int64_t> out;
  const auto j = nlohmann::json::parse(result_json, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object() || !j.contains("health") || !j["health"].is_array()) return out;
  for (const auto& h : j["health"])
    if (h.is_object() && h.contains("batch_id") && h["batch_id"].is_number_integer() &&
        h["batch_id"].get<std::int64_t>() > 0)
      out.push_back(h["batch_id"].get<std::int64_t>());
  return out;
}

PrunePlan PlanPrune(const PruneFacts& facts, const PruneRequest& request) {
  // What references batches: the caller's (first: its reason wins), regression results and nights, baselines
  // taken from local batches.
  std::map<std::int64_t, std::string> protected_batches;
  for (std::int64_t b : request.protected_batches)
    protected_batches.emplace(b, request.protected_why.empty() ? "protected by the caller" : request.protected_why);
  std::vector<const PruneFacts::Regression*> regressions;
  for (const auto& r : facts.regressions) regressions.push_back(&r);
  std::sort(regressions.begin(), regressions.end(), [](auto* a, auto* b) { return a->id < b->id; });
  for (const auto* r : regressions) {
    if (r->batch_id == 0) continue;
    protected_batches.emplace(r->batch_id, r->night.empty() ? Cat("regression result ", r->id, " (suite ", r->suite, ")")
                                                            : Cat("regression night ", r->night, " (result ", r->id, ")"));
    for (std::int64_t h : r->health_batches)
      protected_batches.emplace(h, Cat("the health check of regression night ", r->night, " (result ", r->id, ")"));
  }
  for (const auto& b : facts.baselines) {
    const std::int64_t batch = LocalBatchOfBaselineSource(b.source);
    if (batch != 0) protected_batches.emplace(batch, Cat("baseline '", b.name, "' v", b.version));
  }

  // Newest first, so that the first keep_last finished runs are the newest.
  std::vector<const PruneFacts::Run*> runs;
  runs.reserve(facts.runs.size());
  for (const auto& r : facts.runs) runs.push_back(&r);
  std::sort(runs.begin(), runs.end(), [](auto* a, auto* b) { return a->id > b->id; });

  PrunePlan plan;
  PruneResult& out = plan.result;
  std::map<std::int64_t, std::int64_t> left_in_batch;  // runs of each batch that stay
  std::set<std::int64_t> touched;
  std::int32_t finished_seen = 0;
  for (const auto* r : runs) {
    PruneDecision d;
    d.run_id = r->id;
    d.batch_id = r->batch_id;
    d.name = r->name;
    d.status = r->status;
    d.finished_unix_s = r->finished_unix_s;
    auto keep = [&](std::string why) {
      ++left_in_batch[r->batch_id];
      d.why = std::move(why);
      out.kept.push_back(std::move(d));
    };
    if (!Ended(r->status)) {
      keep(Cat(RunStatusName(r->status), ": only finished runs are pruned"));
      continue;
    }
    ++finished_seen;
    if (r->finished_unix_s >= request.finished_before_unix_s) {
      ++left_in_batch[r->batch_id];
      ++out.newer_kept;
      continue;
    }
    if (auto p = protected_batches.find(r->batch_id); p != protected_batches.end()) {
      keep(Cat(p->second, " references batch ", r->batch_id));
      continue;
    }
    if (finished_seen <= request.keep_last) {
      keep(Cat("one of the newest ", request.keep_last, " finished runs (--keep-last)"));
      continue;
    }
    d.why = Cat(RunStatusName(r->status), ", finished ", FormatUtc(r->finished_unix_s), ", before the cutoff ",
                FormatUtc(request.finished_before_unix_s));
    plan.doomed.push_back(r->id);
    touched.insert(r->batch_id);
    out.deleted.push_back(std::move(d));
  }
  for (std::int64_t b : touched)
    if (left_in_batch[b] == 0) plan.empty_batches.push_back(b);
  out.batches_deleted = static_cast<std::int64_t>(plan.empty_batches.size());
  return plan;
}

}  // namespace vb::db
