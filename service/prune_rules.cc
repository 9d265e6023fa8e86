#include "service/prune_rules.h"

#include <fstream>
#include <sstream>

#include "db/store.h"

namespace vb::server {


StatusOr<regress::Baseline> LoadBaselineFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::NotFound(path + ": cannot read '" + path + "'");
  std::stringstream text;
  text << in.rdbuf();
  regress::Json j;
  try {
    j = regress::Json::parse(text.str());
  } catch (const regress::Json::exception& e) {
    return Status::InvalidArgument(path + ": not JSON: " + e.what());
  }
  auto b = regress::BaselineFromJson(j);
  if (!b.ok()) return b.status().WithContext(path);
  return b;
}

StatusOr<db::PruneResult> PruneWithServerRules(StorePool* pool, const NightsSetup& nights, db::PruneRequest req) {
  if (!nights.baseline_path.empty()) {
    auto b = LoadBaselineFile(nights.baseline_path);
    if (!b.ok()) {
      // Without the file nobody can tell which batch it came from: refuse rather than risk deleting it.
      return Status::FailedPrecondition("nights.baseline_file " + nights.baseline_path +
                                        " cannot be read, so the runs it references cannot be protected: " +
                                        b.status().message());
    }
    if (const std::int64_t batch = db::ServerBatchOfBaselineSource(b->source); batch > 0) {
      req.protected_batches.push_back(batch);
      req.protected_why = "the nights' baseline file (" + b->name + ", source \"" + b->source + "\")";
    }
  }
  auto store = pool->Acquire();
  if (!store.ok()) return store.status();
  return (*store)->Prune(req);
}

}  // namespace vb::server
