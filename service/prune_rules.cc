#include "service/prune_rules.h"

#include <fstream>
#include <sstream>

namespace vb::server {

namespace {

// The batch a baseline taken on a server names ("server lab:50051 batch 12", "suite ci (server lab:50051 batch
// 12, seed 1)"), else 0 (benchctl/regress_commands.cc writes these sources).
std::int64_t ServerBatchOfBaselineSource(const std::string& source) {
  const std::size_t server = source.find("server ");
  if (server == std::string::npos) return 0;
  const std::size_t at = source.find(" batch ", server);
  if (at == std::string::npos) return 0;
  std::int64_t batch = 0;
  std::size_t k = at + 7;
  if (k >= source.size() || source[k] < '0' || source[k] > '9') return 0;
  for (; k < source.size() && source[k] >= '0' && source[k] <= '9' && batch < (std::int64_t{1} << 56); ++k)
    batch = batch * 10 + (source[k] - '0');
  return batch;
}

}  // namespace

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
    if (const std::int64_t batch = ServerBatchOfBaselineSource(b->source); batch > 0) {
      req.protected_batches.push_back(batch);
      req.protected_why = "the nights' baseline file (" + b->name + ", source \"" + b->source + "\")";
    }
  }
  auto store = pool->Acquire();
  if (!store.ok()) return store.status();
  return (*store)->Prune(req);
}

}  // namespace vb::server
