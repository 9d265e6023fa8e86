// BenchServiceImpl::ListNights: the scheduled regression nights (server/nights.h) from the regressions table.
#include <algorithm>
#include <cstdio>
#include <string>

#include "regress/compare.h"
#include "service/grpc_status.h"
#include "service/service.h"

namespace vb::server {

namespace v1 = valvebench::v1;

namespace {

// One line for people: the counts, then the first regression or failed run.
std::string Summary(const regress::Json& j, const std::string& verdict) {
  if (verdict == "error") return j.value("error", std::string("error"));
  const auto c = j.value("counts", regress::Json::object());
  std::string s = std::to_string(c.value("regressed", 0)) + " regressed, " + std::to_string(c.value("unchanged", 0)) +
                  " unchanged, " + std::to_string(c.value("improved", 0)) + " improved, " +
                  std::to_string(c.value("new", 0)) + " new";
  if (const int failed = c.value("failed_cases", 0); failed > 0)
    s += ", " + std::to_string(failed) + " case(s) with failed runs";
  if (j.contains("findings") && j["findings"].is_array())
    for (const auto& f : j["findings"])
      if (f.value("verdict", "") == "regressed") return s + "; first: " + f.value("message", std::string());
  if (j.contains("failures") && j["failures"].is_object())
    for (const auto& [c_name, list] : j["failures"].items())
      if (list.is_array() && !list.empty()) return s + "; first: " + c_name + ": " + list[0].get<std::string>();
  return s;
}

}  // namespace

grpc::Status BenchServiceImpl::ListNights(grpc::ServerContext* ctx, const v1::ListNightsRequest* req,
                                          v1::ListNightsResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  if (req->limit() < 0 || req->limit() > 1000)
    return ToGrpcStatus(Status::InvalidArgument("limit: " + std::to_string(req->limit()) + " is outside 0-1000"));
  const int limit = req->limit() == 0 ? 30 : req->limit();
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto list = (*store)->ListRegressions(true, limit);
  if (!list.ok()) return ToGrpcStatus(list.status());
  for (const auto& brief : *list) {
    auto rec = (*store)->GetRegression(brief.id);  // listings carry no result JSON
    if (!rec.ok()) return ToGrpcStatus(rec.status());
    const auto j = regress::Json::parse(rec->result_json, nullptr, false);
    const auto obj = j.is_object() ? j : regress::Json::object();
    v1::Night* n = resp->add_nights();
    n->set_date(rec->night);
    n->set_batch_id(rec->batch_id);
    n->set_verdict(rec->verdict);
    const auto counts = obj.value("counts", regress::Json::object());
    n->set_regressed_count(counts.value("regressed", 0));
    n->set_unchanged(counts.value("unchanged", 0));
    n->set_improved(counts.value("improved", 0));
    n->set_started_unix_s(obj.value("started_unix_s", rec->created_unix_s));
    n->set_finished_unix_s(rec->created_unix_s);
    n->set_summary(Summary(obj, rec->verdict));
    if (obj.contains("findings") && obj["findings"].is_array())  // each case once, in the result's order
      for (const auto& f : obj["findings"]) {
        const std::string c = f.value("case", std::string());
        if (f.value("verdict", "") != "regressed" || c.empty()) continue;
        if (std::find(n->regressed_cases().begin(), n->regressed_cases().end(), c) == n->regressed_cases().end())
          n->add_regressed_cases(c);
      }
    if (obj.contains("health") && obj["health"].is_array())
      for (const auto& h : obj["health"]) {
        if (!h.is_object() || !h.contains("flags") || !h["flags"].is_array()) continue;
        for (const auto& f : h["flags"]) {
          const double rel = f.value("change_relative", 0.0);
          char pct[32];
          std::snprintf(pct, sizeof pct, "%+.1f %%", 100.0 * rel);
          n->add_valve_changes(h.value("bench", std::string()) + ": " + f.value("parameter", std::string()) + " " +
                               f.value("direction", std::string()) + " " + pct + " since " +
                               f.value("since", std::string()) + ", flagged " + f.value("session", std::string()));
        }
      }
    if (obj.contains("cause") && obj["cause"].is_object()) {
      n->set_cause(obj["cause"].value("verdict", std::string()));
      n->set_cause_reason(obj["cause"].value("reason", std::string()));
    }
    n->set_regression_id(rec->id);
    n->set_suite(rec->suite);
    n->set_baseline(rec->baseline_name.empty() ? ""
                                               : rec->baseline_name + " v" + std::to_string(rec->baseline_version));
  }
  return grpc::Status::OK;
}

}  // namespace vb::server
