#include "service/local_records.h"

#include <filesystem>

#include "db/open_store.h"
#include "db/store.h"

namespace vb::server {

namespace {

regress::Baseline FromRecord(const db::BaselineRecord& r) {
  regress::Baseline b;
  b.name = r.name;
  b.version = r.version;
  b.created_unix_s = r.created_unix_s;
  b.source = r.source;
  b.note = r.note;
  for (const auto& e : r.entries) b.cases[e.case_name][e.metric] = {e.mean, e.spread, e.n};
  return b;
}

}  // namespace

StatusOr<std::unique_ptr<LocalRecords>> LocalRecords::Open(const std::string& path) {
  if (path.empty())
    return Status::InvalidArgument("--no-store: baselines and regression results need the local store (--db FILE)");
  const std::string where = "local store " + db::DisplayLocation(path);
  if (const auto parent = std::filesystem::path(path).parent_path(); !parent.empty() && !db::IsPostgresLocation(path)) {
    std::error_code ec;  // a first baseline on a fresh machine: ~/.local/share/valvebench/ may not exist yet
    std::filesystem::create_directories(parent, ec);
  }
  auto s = db::OpenStore(path);
  if (!s.ok()) return s.status().WithContext(where);
  return std::unique_ptr<LocalRecords>(new LocalRecords(std::move(s.value()), where));
}

LocalRecords::LocalRecords(std::unique_ptr<db::Store> store, std::string where)
    : store_(std::move(store)), where_(std::move(where)) {}

LocalRecords::~LocalRecords() = default;

StatusOr<regress::Baseline> LocalRecords::SaveBaseline(const std::string& name, const std::string& source,
                                                       const std::string& note, const regress::CaseStats& stats) {
  std::vector<db::BaselineEntry> entries;
  for (const auto& [c, metrics] : stats)
    for (const auto& [metric, s] : metrics)
      if (s.n > 0) entries.push_back({c, metric, s.mean, s.spread, s.n});
  auto v = store_->SaveBaseline(name, source, note, entries);
  if (!v.ok()) return v.status();
  return GetBaseline(name, *v);
}

StatusOr<regress::Baseline> LocalRecords::GetBaseline(const std::string& name, int version) {
  auto rec = store_->GetBaseline(name, version);
  if (!rec.ok()) return rec.status();
  return FromRecord(*rec);
}

StatusOr<std::vector<regress::Baseline>> LocalRecords::ListBaselines() {
  auto list = store_->ListBaselines();
  if (!list.ok()) return list.status();
  std::vector<regress::Baseline> out;
  for (const auto& r : *list) out.push_back(FromRecord(r));
  return out;
}

StatusOr<std::int64_t> LocalRecords::SaveRegression(const regress::RegressResult& r, std::int64_t local_batch_id) {
  db::RegressionRecord rec;
  rec.suite = r.suite;
  rec.baseline_name = r.baseline_name;
  rec.baseline_version = r.baseline_version;
  rec.batch_id = local_batch_id;
  rec.created_unix_s = r.created_unix_s;
  rec.verdict = r.verdict();
  rec.result_json = regress::ResultToJson(r).dump();
  return store_->SaveRegression(rec);
}

StatusOr<StoredRegression> LocalRecords::GetRegression(std::int64_t id) {
  auto rec = store_->GetRegression(id);
  if (!rec.ok()) return rec.status();
  return StoredRegression{rec->id, rec->suite, rec->night, rec->result_json};
}

}  // namespace vb::server
