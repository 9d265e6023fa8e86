// The store's engines for value-parameterised tests (docs/store.md, "Testing on PostgreSQL"): the same test
// runs on SQLite and on PostgreSQL (a throwaway server, tests/db/pg_server.h).
//
//   class MyTest : public StoreEngineTest {};
//   TEST_P(MyTest, Something) { Store& s = store(); ... }
//   INSTANTIATE_TEST_SUITE_P(Engines, MyTest, ::testing::ValuesIn(StoreEngines()), EngineName);
//
// Both engines are always listed; on a machine where PostgreSQL cannot start, the postgresql instances are
// skipped (GTEST_SKIP) with the reason, so a missing server is visible rather than silently untested.
#pragma once

#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "common/status.h"
#include "db/store.h"

namespace vb::db::testing {

std::vector<std::string> StoreEngines();  // {"sqlite", "postgresql"}
std::string EngineName(const ::testing::TestParamInfo<std::string>& info);

// A new, empty store on `engine`: a fresh SQLite file, or a fresh PostgreSQL database. *location says where
// (for a second connection: OpenStore(location)). Unavailable when PostgreSQL cannot start (*skip_reason set).
StatusOr<std::unique_ptr<Store>> OpenFreshStore(const std::string& engine, std::string* location);

// The fixture: store() is a fresh store of GetParam()'s engine, location() where it lives.
class StoreEngineTest : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override;
  Store& store() { return *store_; }
  const std::string& location() const { return location_; }
  bool postgres() const { return GetParam() == "postgresql"; }
  // Another connection to the same store (another thread or host).
  std::unique_ptr<Store> OpenAnother();
  // Raw SQL on the store's database, beside the Store API (checks it does not offer, injected faults). The SQL
  // must be valid on the engine at hand: most counting queries are the same on both.
  std::int64_t RawInt(const std::string& sql);
  std::string RawText(const std::string& sql);
  void RawExec(const std::string& sql);

  std::unique_ptr<Store> store_;
  std::string location_;
};

}  // namespace vb::db::testing
