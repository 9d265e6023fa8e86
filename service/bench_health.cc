// BenchServiceImpl::GetBenchHealth and the bench twin's stored history (service/bench_health.h).
#include "service/bench_health.h"

#include <cmath>

#include "regress/compare.h"
#include "service/grpc_status.h"
#include "service/service.h"

namespace vb::server {

namespace v1 = valvebench::v1;

regress::Json StoredAnchorJson(const StoredAnchor& a) {
  regress::Json f = regress::Json::object();
  for (const auto& [k, v] : a.fitted) f[k] = v;
  return {{"anchor_night", a.anchor_night}, {"fitted", f}, {"effects", a.effects}, {"moves", a.moves}};
}

StatusOr<StoredAnchor> StoredAnchorFromJson(const regress::Json& j) {
  StoredAnchor a;
  if (!j.is_object()) return Status::InvalidArgument("anchor_refit: not an object");
  if (!j.contains("anchor_night") || !j["anchor_night"].is_string())
    return Status::InvalidArgument("anchor_refit.anchor_night: not a string");
  a.anchor_night = j["anchor_night"].get<std::string>();
  if (!j.contains("fitted") || !j["fitted"].is_object()) return Status::InvalidArgument("anchor_refit.fitted: not an object");
  for (const auto& [k, v] : j["fitted"].items()) {
    if (!v.is_number()) return Status::InvalidArgument("anchor_refit.fitted." + k + ": not a number");
    a.fitted[k] = v.get<double>();
  }
  if (j.contains("effects")) {
    if (!j["effects"].is_array()) return Status::InvalidArgument("anchor_refit.effects: not an array");
    for (const auto& e : j["effects"]) {
      if (!e.is_string()) return Status::InvalidArgument("anchor_refit.effects: not a string");
      a.effects.push_back(e.get<std::string>());
    }
  }
  if (j.contains("moves")) {
    if (!j["moves"].is_number_integer() || j["moves"].get<std::int64_t>() < 0 || j["moves"].get<std::int64_t>() > 1000)
      return Status::InvalidArgument("anchor_refit.moves: not a count from 0 to 1000");
    a.moves = static_cast<int>(j["moves"].get<std::int64_t>());
  }
  return a;
}

StatusOr<StoredHealth> LoadStoredHealth(db::Store* store, const std::string& before_date) {
  StoredHealth out;
  // bench -> (the night the anchor moved, the earlier nights' values identified again then)
  std::map<std::string, std::pair<std::string, std::map<std::string, gap::SessionValues>>> again;
  auto nights = store->ListRegressions(/*nights_only=*/true, 1000);
  if (!nights.ok()) return nights.status();
  for (const auto& brief : *nights) {
    if (brief.night.empty() || (!before_date.empty() && brief.night >= before_date)) continue;
    auto rec = store->GetRegression(brief.id);  // listings carry no result JSON
    if (!rec.ok()) return rec.status();
    const auto j = regress::Json::parse(rec->result_json, nullptr, false);
    if (!j.is_object()) continue;
    double started = 0.0;
    if (j.contains("started_unix_s") && j["started_unix_s"].is_number()) started = j["started_unix_s"].get<double>();
    if (!std::isfinite(started)) started = 0.0;
    if (brief.batch_id > 0) out.suites[brief.night] = {started, brief.batch_id};
    if (!j.contains("health") || !j["health"].is_array()) continue;
    for (const auto& h : j["health"]) {
      if (!h.is_object() || !h.contains("bench") || !h["bench"].is_string() || !h.contains("batch_id") ||
          !h["batch_id"].is_number_integer())
        continue;
      const std::string bench = h["bench"].get<std::string>();
      out.checks[bench][brief.night] = {started, h["batch_id"].get<std::int64_t>()};
      auto f = out.first_check.find(bench);
      if (f == out.first_check.end() || brief.night < f->second.first)
        out.first_check[bench] = {brief.night, h["batch_id"].get<std::int64_t>()};
      if (h.contains("anchor_refit") && h.contains("reidentified") && h["reidentified"].is_array()) {
        auto a = StoredAnchorFromJson(h["anchor_refit"]);
        auto& [night, values] = again[bench];
        if (a.ok() && brief.night > night) {
          a->night = brief.night;
          out.anchor[bench] = std::move(*a);
          night = brief.night;
          values.clear();
          for (const auto& e : h["reidentified"]) {
            auto v = gap::SessionValuesFromJson(e.dump());
            if (v.ok() && v->name < brief.night && v->error.empty()) values[v->name] = std::move(*v);
          }
        }
      }
      if (!h.contains("values")) continue;
      auto v = gap::SessionValuesFromJson(h["values"].dump());
      if (v.ok()) out.values[bench][brief.night] = std::move(*v);
    }
  }
  for (auto& [bench, moved] : again)
    for (auto& [night, v] : moved.second)
      if (out.checks[bench].count(night)) out.values[bench][night] = std::move(v);
  return out;
}

std::optional<std::pair<std::string, StoredCheck>> BaselineNight(const std::map<std::string, StoredCheck>& checks,
                                                                 double baseline_created_unix_s) {
  if (!(baseline_created_unix_s > 0.0)) return std::nullopt;
  std::optional<std::pair<std::string, StoredCheck>> last;
  for (const auto& [night, check] : checks)  // in date order
    if (check.night_started_unix_s > 0.0 && check.night_started_unix_s < baseline_created_unix_s) last = {night, check};
  return last;
}

v1::BenchHealth BenchHealthOf(const std::string& bench, const gap::Tracking& t) {
  v1::BenchHealth b;
  b.set_bench(bench);
  for (const auto& s : t.sessions) b.add_nights(s);
  for (double v : t.fit_rmse_A) b.add_fit_rmse_a(v);
  for (double v : t.noise_floor_A) b.add_noise_floor_a(v);
  for (const auto& p : t.parameters) {
    auto* q = b.add_parameters();
    q->set_name(p.name), q->set_unit(p.unit), q->set_meaning(p.meaning);
    for (const auto& v : p.sessions) q->add_value(v.value), q->add_sigma(v.sigma), q->add_z(v.z);
    q->set_center(p.center), q->set_lower_limit(p.lower_limit), q->set_upper_limit(p.upper_limit);
    if (p.flagged >= 0) q->set_flagged_night(t.sessions[p.flagged]);
    if (p.change_start >= 0 && p.change_start < static_cast<int>(t.sessions.size()))
      q->set_change_since(t.sessions[p.change_start]);
    q->set_drift_per_night(p.drift_per_session);
    q->set_smallest_detectable_step(p.smallest_step);
  }
  for (const auto& f : t.flags) {
    auto* g = b.add_flags();
    g->set_night(f.session), g->set_parameter(f.parameter), g->set_unit(f.unit), g->set_direction(f.direction);
    g->set_change(f.change), g->set_change_relative(f.change_relative), g->set_z(f.z), g->set_since(f.since);
    g->set_drift_per_night(f.drift_per_session), g->set_meaning(f.meaning);
  }
  for (const auto& n : t.notes) b.add_notes(n);
  b.set_k_sigma(t.k_sigma), b.set_h_sigma(t.h_sigma), b.set_target_arl0_nights(t.target_arl0_sessions);
  b.set_report(gap::TrackingReport(t));
  b.set_tracking_json(gap::TrackingJson(t));
  return b;
}

grpc::Status BenchServiceImpl::GetBenchHealth(grpc::ServerContext* ctx, const v1::GetBenchHealthRequest* req,
                                              v1::GetBenchHealthResponse* resp) {
  Principal who;
  if (auto st = gate_.Caller(ctx, &who); !st.ok()) return st;
  // A bench name is echoed in the NOT_FOUND message: a huge one would not fit the status's metadata.
  constexpr std::size_t kMaxBenchName = 256;
  if (req->bench().size() > kMaxBenchName)
    return ToGrpcStatus(Status::InvalidArgument("bench: " + std::to_string(req->bench().size()) +
                                                " bytes, longer than a bench name (" + std::to_string(kMaxBenchName) +
                                                ")"));
  auto store = pool_->Acquire();
  if (!store.ok()) return ToGrpcStatus(store.status());
  auto stored = LoadStoredHealth(store->get());
  if (!stored.ok()) return ToGrpcStatus(stored.status());
  if (!req->bench().empty() && !stored->first_check.count(req->bench()))
    return ToGrpcStatus(Status::NotFound("bench: no health check of bench '" + req->bench() +
                                         "' is stored in the nights (a bench's \"health\" block in the config)"));
  for (const auto& [bench, first] : stored->first_check) {
    if (!req->bench().empty() && bench != req->bench()) continue;
    std::vector<gap::SessionValues> nights;
    for (const auto& [date, v] : stored->values[bench]) nights.push_back(v);
    if (nights.size() < 2) {
      v1::BenchHealth* b = resp->add_benches();
      b->set_bench(bench);
      for (const auto& v : nights) b->add_nights(v.name);
      b->add_notes("tracking needs two identified nights; " + std::to_string(nights.size()) + " stored");
      continue;
    }
    auto t = gap::TrackValues(nights, gap::TrackOptions{});
    if (!t.ok()) {
      v1::BenchHealth* b = resp->add_benches();
      b->set_bench(bench);
      b->add_notes(t.status().message());
      continue;
    }
    *resp->add_benches() = BenchHealthOf(bench, *t);
  }
  return grpc::Status::OK;
}

}  // namespace vb::server
