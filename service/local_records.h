// The records benchctl keeps in the local store besides runs (docs/regress.md): named, versioned baselines
// (benchctl baseline set/list/show, regress --baseline NAME) and regression results (regress, report
// --regress). The BenchService has no RPC for them (baselines are the user's own, kept next to their local
// runs whichever service ran the suite), so benchctl reaches them here, in the service library, in regress's
// terms: benchctl holds no store code (issue 27).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/status.h"
#include "regress/compare.h"

namespace vb::db {
class Store;
}

namespace vb::server {

// A stored regression result: what `report --regress ID` renders.
struct StoredRegression {
  std::int64_t id = 0;
  std::string suite;
  std::string night;        // YYYY-MM-DD for a scheduled night, "" otherwise
  std::string result_json;  // regress::ResultToJson
};

class LocalRecords {
 public:
  // The store at `store` (a SQLite file, its directory created, or postgresql://...). Errors name it
  // ("local store PATH: ..."); "" (--no-store) is refused: records need a store that is kept.
  static StatusOr<std::unique_ptr<LocalRecords>> Open(const std::string& store);
  ~LocalRecords();
  LocalRecords(const LocalRecords&) = delete;
  LocalRecords& operator=(const LocalRecords&) = delete;

  // For messages: "local store PATH".
  const std::string& where() const { return where_; }
  // Saves the cases' statistics (cases with n > 0) under `name` as its next version; returns it as stored.
  StatusOr<regress::Baseline> SaveBaseline(const std::string& name, const std::string& source, const std::string& note,
                                           const regress::CaseStats& stats);
  // version 0 = the newest.
  StatusOr<regress::Baseline> GetBaseline(const std::string& name, int version);
  // Every version of every baseline, without their cases.
  StatusOr<std::vector<regress::Baseline>> ListBaselines();
  // Keeps a regression result; local_batch_id: its runs' batch in this store (0: they are on a server).
  StatusOr<std::int64_t> SaveRegression(const regress::RegressResult& result, std::int64_t local_batch_id);
  StatusOr<StoredRegression> GetRegression(std::int64_t id);

 private:
  LocalRecords(std::unique_ptr<db::Store> store, std::string where);
  std::unique_ptr<db::Store> store_;
  std::string where_;
};

}  // namespace vb::server
