#include "benchctl/backend.h"

#include <cstdio>
#include <filesystem>

#include "benchctl/hw_commands.h"
#include "benchctl/local_run.h"
#include "db/store.h"
#include "proto/api_convert.h"
#include "runs/query.h"

namespace vb::benchctl {
namespace {

namespace v1 = valvebench::v1;

class Local final : public Backend {
 public:
  explicit Local(std::string path) : path_(std::move(path)) {}
  std::string Where() const override { return "local"; }
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
      RunView v{r.id, r.batch_id, r.key, r.controller, r.status, r.reason, {}, r.spec_json, r.submitted_unix_s,
                r.started_unix_s, r.finished_unix_s};
      auto m = (*store)->GetMetrics(r.id);
      if (!m.ok()) return m.status();
      for (const auto& x : *m) v.metrics[x.name] = x.value;
      out.push_back(std::move(v));
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

 private:
  // The store, opened once: the file, or with --no-store one in memory that lives as long as this backend
  // (what this invocation ran can still be compared; nothing is kept).
  StatusOr<db::Store*> Open() {
    if (store_ == nullptr) {
      if (const auto parent = std::filesystem::path(path_).parent_path(); !path_.empty() && !parent.empty()) {
        std::error_code ec;  // a first run on a fresh machine: ~/.local/share/valvebench/ may not exist yet
        std::filesystem::create_directories(parent, ec);
      }
      auto s = db::Store::Open(path_.empty() ? ":memory:" : path_);
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

  std::string StoreName() const { return path_.empty() ? "in-memory store (--no-store)" : "local store " + path_; }

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
    auto add = [&](const v1::Run& r) {
      RunView v{r.id(), r.batch_id(), api::FromProto(r.key()), r.controller(), api::FromProto(r.status()).value_or(RunStatus::kQueued), r.reason(), {},
                experiment::SpecToJson(r.spec(), false), r.submitted_unix_s(), r.started_unix_s(), r.finished_unix_s()};
      for (const auto& [k, x] : r.metrics()) v.metrics[k] = x;
      out.push_back(std::move(v));
    };
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
