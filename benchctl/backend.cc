#include "benchctl/backend.h"

#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <thread>

#include "benchctl/hw_commands.h"
#include "benchctl/local_run.h"
#include "db/open_store.h"
#include "db/store.h"
#include "proto/api_convert.h"
#include "runs/query.h"

namespace vb::benchctl {
namespace {

namespace v1 = valvebench::v1;

std::string User() {
  const char* user = std::getenv("USER");
  return user != nullptr && *user != '\0' ? user : "local";
}

// A store row as commands see it; `spec`: with its spec; `history`: with the status history.
StatusOr<RunView> FromRecord(db::Store* store, const db::RunRecord& r, bool with_spec, bool with_history) {
  RunView v;
  v.id = r.id;
  v.batch_id = r.batch_id;
  v.key = r.key;
  v.controller = r.controller;
  v.status = r.status;
  v.reason = r.reason;
  v.bench = r.bench_name;
  v.host = r.host;
  if (const auto spec = nlohmann::json::parse(r.spec_json, nullptr, false); spec.is_object())
    if (auto d = spec.find("duration_s"); d != spec.end() && d->is_number()) v.duration_s = d->get<double>();
  v.submitter = r.submitter;
  v.priority = r.priority;
  v.progress = r.status == RunStatus::kDone ? 1.0 : r.progress;
  v.submitted_unix_s = r.submitted_unix_s;
  v.started_unix_s = r.started_unix_s;
  v.finished_unix_s = r.finished_unix_s;
  v.tags = r.tags;
  v.split = r.split;
  if (std::isfinite(r.t_start_s)) v.t_start_s = r.t_start_s;
  auto m = store->GetMetrics(r.id);
  if (!m.ok()) return m.status();
  for (const auto& x : *m) v.metrics[x.name] = x.value;
  if (with_spec) {
    v1::ExperimentSpec spec;
    google::protobuf::util::JsonParseOptions o;
    o.ignore_unknown_fields = true;
    if (google::protobuf::util::JsonStringToMessage(r.spec_json, &spec, o).ok()) v.spec = std::move(spec);
  }
  if (!with_history) return v;
  auto h = store->History(r.id);
  if (!h.ok()) return h.status();
  for (const auto& c : *h) v.history.push_back({c.status, c.at_unix_s, c.reason});
  return v;
}

RunView FromProto(const v1::Run& r) {
  RunView v;
  v.id = r.id();
  v.batch_id = r.batch_id();
  v.key = api::FromProto(r.key());
  v.controller = r.controller();
  v.status = api::FromProto(r.status()).value_or(RunStatus::kQueued);
  v.reason = r.reason();
  for (const auto& [k, x] : r.metrics()) v.metrics[k] = x;
  v.bench = r.bench();
  v.host = r.host();
  v.duration_s = r.duration_s();
  v.submitter = r.submitter();
  v.priority = r.priority();
  v.progress = r.progress();
  v.submitted_unix_s = r.submitted_unix_s();
  v.started_unix_s = r.started_unix_s();
  v.finished_unix_s = r.finished_unix_s();
  v.tags.assign(r.tags().begin(), r.tags().end());
  v.split = r.split();
  if (r.has_t_start_s()) v.t_start_s = r.t_start_s();
  if (r.has_spec()) v.spec = r.spec();
  for (const auto& c : r.history())
    v.history.push_back({api::FromProto(c.status()).value_or(RunStatus::kQueued), c.at_unix_s(), c.reason()});
  return v;
}

class Local final : public Backend {
 public:
  explicit Local(std::string path) : path_(std::move(path)) {}
  std::string Where() const override { return StoreName(); }
  bool serves_hardware() const override { return false; }

  StatusOr<std::int64_t> RunBatch(const std::vector<experiment::ExperimentSpec>& specs, const std::vector<RunKey>& keys,
                                  const std::string& batch_name, const std::string& batch_json) override {
    auto store = Open();
    if (!store.ok()) return store.status();
    auto results = RunLocal({specs, keys, batch_name, batch_json, false, false, path_}, *store);
    if (!results.ok()) return results.status();
    for (const auto& r : *results)
      std::fprintf(stderr, "  %s: %s\n", r.key.DisplayName().c_str(), r.summary.BriefReport().c_str());
    return results->empty() ? 0 : results->front().batch_id;
  }

  StatusOr<std::vector<RunView>> Runs(std::int64_t batch, const std::vector<std::int64_t>& run_ids) override {
    auto store = Open();
    if (!store.ok()) return store.status();
    auto recs = Records(*store, batch, run_ids);
    if (!recs.ok()) return recs.status();
    std::vector<RunView> out;
    for (const auto& r : *recs) {
      auto v = FromRecord(*store, r, /*with_spec=*/true, /*with_history=*/false);  // reports show the spec
      if (!v.ok()) return v.status();
      out.push_back(std::move(*v));
    }
    return out;
  }

  StatusOr<experiment::Comparison> Compare(std::int64_t batch, const std::vector<std::int64_t>& run_ids) override {
    auto store = Open();
    if (!store.ok()) return store.status();
    auto recs = Records(*store, batch, run_ids);
    if (!recs.ok()) return recs.status();
    return runs::CompareStored(*store, *recs);
  }

  StatusOr<Trace> GetTrace(std::int64_t run_id) override {
    auto store = Open();
    if (!store.ok()) return store.status();
    auto chunks = (*store)->ReadTrace(run_id);
    if (!chunks.ok()) return chunks.status();
    Trace t;
    if (chunks->empty()) return t;
    t.t0_s = chunks->front().t0_s;
    t.sample_period_s = chunks->front().sample_period_s;
    t.channels = chunks->front().channels;
    for (const auto& c : *chunks)
      for (std::size_t ch = 0; ch < c.channels.size(); ++ch) {
        auto& col = t.columns[c.channels[ch]];
        col.insert(col.end(), c.data.begin() + static_cast<std::ptrdiff_t>(ch * c.samples),
                   c.data.begin() + static_cast<std::ptrdiff_t>((ch + 1) * c.samples));
      }
    return t;
  }

  StatusOr<v1::ListBenchesResponse> Benches() override { return LocalBenches(); }

  bool keeps_runs() const override { return !path_.empty(); }

  StatusOr<Submitted> Submit(const experiment::ExperimentSpec& spec, bool realtime, bool keep_traces) override {
    auto store = Open();
    if (!store.ok()) return store.status();
    auto results = RunLocal({{spec}, {}, spec.name(), "", realtime, keep_traces, path_}, *store);
    if (!results.ok()) return results.status();
    Submitted out;
    for (const auto& r : *results) out.run_ids.push_back(r.run_id);
    out.batch_id = results->empty() ? 0 : results->front().batch_id;
    out.executed = std::move(*results);
    return out;
  }

  StatusOr<RunView> GetRun(std::int64_t run_id) override {
    auto store = Open();
    if (!store.ok()) return store.status();
    auto r = (*store)->GetRun(run_id);
    if (!r.ok()) return r.status().code() == StatusCode::kNotFound ? r.status().WithContext(StoreName()) : r.status();
    return FromRecord(*store, *r, true, true);
  }

  StatusOr<std::vector<RunView>> ListRuns(const RunFilter& filter, bool* more) override {
    auto store = Open();
    if (!store.ok()) return store.status();
    db::RunFilter f;
    f.status = filter.status;
    f.batch_id = filter.batch_id;
    f.tag = filter.tag;
    f.limit = std::min(1000, filter.limit + 1);  // one more than asked: whether there are more
    auto recs = (*store)->ListRuns(f);
    if (!recs.ok()) return recs.status();
    *more = static_cast<int>(recs->size()) > filter.limit;
    if (*more) recs->resize(static_cast<std::size_t>(filter.limit));
    std::vector<RunView> out;
    for (const auto& r : *recs) {
      auto v = FromRecord(*store, r, false, false);
      if (!v.ok()) return v.status();
      out.push_back(std::move(*v));
    }
    return out;
  }

  StatusOr<RunView> Cancel(std::int64_t run_id, const std::string& reason) override {
    auto store = Open();
    if (!store.ok()) return store.status();
    auto st = (*store)->RequestCancel(run_id, reason.empty() ? "cancelled by " + User() : reason);
    if (!st.ok()) return st.status().code() == StatusCode::kNotFound ? st.status().WithContext(StoreName()) : st.status();
    return GetRun(run_id);
  }

  Status Watch(std::int64_t run_id, const std::function<bool(const RunView&)>& on_event) override {
    // The run executes in another process (a benchctl run --local), which writes its progress into the store:
    // poll the row.
    RunStatus last_status = RunStatus::kQueued;
    double last_progress = -1.0;
    for (;;) {
      auto r = GetRun(run_id);
      if (!r.ok()) return r.status();
      if (r->status != last_status || r->progress != last_progress) {
        last_status = r->status;
        last_progress = r->progress;
        if (!on_event(*r)) return Status::Ok();
      }
      if (r->ended()) return Status::Ok();
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
  }

  StatusOr<v1::SubmitRunResponse> Import(const v1::ImportRunsRequest& /*request*/) override {
    return Status::FailedPrecondition(
        "import: the local store does not take measured runs yet; diagnose the dataset directory itself "
        "(benchctl diagnose DIR), or import it to a server (--server ADDR or VALVEBENCH_SERVER)");
  }

 private:
  // The store, opened once: the file, or with --no-store one in memory that lives as long as this backend
  // (what this invocation ran can still be compared; nothing is kept).
  StatusOr<db::Store*> Open() {
    if (store_ == nullptr) {
      if (const auto parent = std::filesystem::path(path_).parent_path();
          !path_.empty() && !parent.empty() && !db::IsPostgresLocation(path_)) {
        std::error_code ec;  // a first run on a fresh machine: ~/.local/share/valvebench/ may not exist yet
        std::filesystem::create_directories(parent, ec);
      }
      auto s = db::OpenStore(path_.empty() ? ":memory:" : path_);
      if (!s.ok()) return s.status().WithContext(StoreName());
      store_ = std::move(s.value());
    }
    return store_.get();
  }
  StatusOr<std::vector<db::RunRecord>> Records(db::Store* store, std::int64_t batch, const std::vector<std::int64_t>& ids) {
    auto recs = batch != 0 ? runs::ListBatch(store, batch) : runs::GetRuns(store, ids);
    if (!recs.ok() && recs.status().code() == StatusCode::kNotFound) return recs.status().WithContext(StoreName());
    return recs;
  }

  std::string StoreName() const {
    return path_.empty() ? "in-memory store (--no-store)" : "local store " + db::DisplayLocation(path_);
  }

  std::string path_;
  std::unique_ptr<db::Store> store_;
};

class Remote final : public Backend {
 public:
  Remote(std::unique_ptr<client::Client> c, std::string address) : c_(std::move(c)), address_(std::move(address)) {}
  std::string Where() const override { return "server " + address_; }
  bool serves_hardware() const override { return true; }

  StatusOr<std::int64_t> RunBatch(const std::vector<experiment::ExperimentSpec>& specs, const std::vector<RunKey>& keys,
                                  const std::string& batch_name, const std::string& /*batch_json*/) override {
    std::vector<v1::RunKey> key_protos;
    for (const auto& k : keys) key_protos.push_back(api::ToProto(k));
    auto resp = c_->SubmitBatch(specs, batch_name, key_protos);
    if (!resp.ok()) return resp.status();
    std::fprintf(stderr, "%s: batch %lld, %d runs on %s\n", batch_name.c_str(), static_cast<long long>(resp->batch_id()),
                 resp->run_ids_size(), address_.c_str());
    for (auto id : resp->run_ids()) {
      auto st = c_->Watch(id, kRunDeadline_s, 0.0, [](const v1::RunEvent& ev) {
        const auto status = api::FromProto(ev.status());
        return !(status && Ended(*status));
      });
      if (!st.ok()) return st.WithContext("waiting for run " + std::to_string(id));
    }
    return resp->batch_id();
  }

  StatusOr<std::vector<RunView>> Runs(std::int64_t batch, const std::vector<std::int64_t>& run_ids) override {
    std::vector<RunView> out;
    auto add = [&](const v1::Run& r) { out.push_back(FromProto(r)); };
    if (batch == 0) {
      for (auto id : run_ids) {
        auto r = c_->GetRun(id);
        if (!r.ok()) return r.status();
        add(*r);
      }
      return out;
    }
    v1::ListRunsRequest req;
    req.set_batch_id(batch);
    req.set_page_size(1000);
    for (;;) {
      auto resp = c_->ListRuns(req);
      if (!resp.ok()) return resp.status();
      for (const auto& r : resp->runs()) add(r);
      if (resp->next_page_token().empty()) break;
      req.set_page_token(resp->next_page_token());
    }
    if (out.empty()) return Status::NotFound("batch " + std::to_string(batch) + " not found on the server");
    return out;
  }

  StatusOr<experiment::Comparison> Compare(std::int64_t batch, const std::vector<std::int64_t>& run_ids) override {
    return RemoteComparison(*c_, batch, run_ids);
  }

  StatusOr<Trace> GetTrace(std::int64_t run_id) override { return c_->GetTrace(run_id); }
  StatusOr<v1::ListBenchesResponse> Benches() override { return c_->Benches(); }

  bool keeps_runs() const override { return true; }

  StatusOr<Submitted> Submit(const experiment::ExperimentSpec& spec, bool /*realtime*/, bool /*keep_traces*/) override {
    auto resp = c_->Submit(spec);
    if (!resp.ok()) return resp.status();
    Submitted out;
    out.batch_id = resp->batch_id();
    out.run_ids.assign(resp->run_ids().begin(), resp->run_ids().end());
    return out;
  }

  StatusOr<RunView> GetRun(std::int64_t run_id) override {
    auto r = c_->GetRun(run_id);
    if (!r.ok()) return r.status();
    return FromProto(*r);
  }

  StatusOr<std::vector<RunView>> ListRuns(const RunFilter& filter, bool* more) override {
    v1::ListRunsRequest req;
    if (filter.status) req.set_status(api::ToProto(*filter.status));
    req.set_batch_id(filter.batch_id);
    req.set_tag(filter.tag);
    req.set_page_size(filter.limit);
    auto resp = c_->ListRuns(req);
    if (!resp.ok()) return resp.status();
    *more = !resp->next_page_token().empty();
    std::vector<RunView> out;
    for (const auto& r : resp->runs()) out.push_back(FromProto(r));
    return out;
  }

  StatusOr<RunView> Cancel(std::int64_t run_id, const std::string& reason) override {
    auto r = c_->Cancel(run_id, reason);
    if (!r.ok()) return r.status();
    return FromProto(*r);
  }

  Status Watch(std::int64_t run_id, const std::function<bool(const RunView&)>& on_event) override {
    return c_->Watch(run_id, kRunDeadline_s, -1.0, [&](const v1::RunEvent& ev) {
      RunView v;
      v.id = run_id;
      v.status = api::FromProto(ev.status()).value_or(RunStatus::kQueued);
      v.progress = ev.progress();
      v.reason = ev.reason();
      return on_event(v) && !v.ended();
    });
  }

  StatusOr<v1::SubmitRunResponse> Import(const v1::ImportRunsRequest& request) override {
    return c_->ImportRuns(request);
  }

 private:
  static constexpr double kRunDeadline_s = 6 * 3600.0;  // one run of a batch, waited for
  std::unique_ptr<client::Client> c_;
  std::string address_;
};

}  // namespace

StatusOr<experiment::Comparison> RemoteComparison(client::Client& client, std::int64_t batch,
                                                  const std::vector<std::int64_t>& run_ids) {
  auto cmp = client.Compare(batch, run_ids);
  if (!cmp.ok()) return cmp.status();
  experiment::Comparison c;
  c.rank_metric = cmp->rank_metric();
  c.effort_metric = cmp->effort_metric();
  c.columns.assign(cmp->columns().begin(), cmp->columns().end());
  for (const auto& r : cmp->rows()) {
    experiment::CompareRow row;
    // The case's identity as fields; a row from a server older than CompareRow.key is only its name.
    row.key = r.has_key() ? api::FromProto(r.key()) : NamedRun(r.name());
    row.run_ids.assign(r.run_ids().begin(), r.run_ids().end());
    row.name = r.name();
    row.controller = r.controller();
    row.runs = r.runs();
    row.failed = r.failed();
    row.rank = r.rank();
    row.pareto = r.pareto();
    for (const auto& col : c.columns) {
      experiment::MetricStat st;
      auto it = r.metrics().find(col);
      if (it != r.metrics().end()) st = {it->second.mean(), it->second.spread(), it->second.n()};
      row.metrics[col] = st;
    }
    c.rows.push_back(std::move(row));
  }
  return c;
}

std::unique_ptr<Backend> LocalBackend(std::string store_path) { return std::make_unique<Local>(std::move(store_path)); }
std::unique_ptr<Backend> RemoteBackend(std::unique_ptr<client::Client> client, std::string address) {
  return std::make_unique<Remote>(std::move(client), std::move(address));
}
std::unique_ptr<Backend> ChooseBackend(const std::string& server, const std::string& store_path,
                                       const std::function<std::unique_ptr<client::Client>()>& make_client) {
  return server.empty() ? LocalBackend(store_path) : RemoteBackend(make_client(), server);
}

}  // namespace vb::benchctl
