// Baselines and regression results in the store (schema v2): versions are never overwritten, bad input names
// the field and leaves what is stored alone, and a v1 file migrates keeping its runs.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "db/schema.h"
#include "db/sqlite_conn.h"
#include "db/sqlite_store.h"
#include "db/store.h"
#include "db/text.h"
#include "tests/db/store_engines.h"

namespace vb::db {
namespace {

// On both engines (tests/db/store_engines.h), except AVersion1FileMigratesKeepingItsData (SQLite's migrations).
class BaselineStoreTest : public testing::StoreEngineTest {};
INSTANTIATE_TEST_SUITE_P(Engines, BaselineStoreTest, ::testing::ValuesIn(testing::StoreEngines()), testing::EngineName);

std::vector<BaselineEntry> Entries(double rmse) {
  return {{"pi", "rmse", rmse, 1e-5, 3}, {"pi", "effort_l2", 3.67, 0.01, 3}, {"fuzzy", "rmse", 5e-4, 0.0, 1}};
}

TEST_P(BaselineStoreTest, SavingUnderAnExistingNameAddsAVersionAndKeepsTheOld) {
  Store* store = &this->store();
  ASSERT_NE(store, nullptr);
  auto v1 = store->SaveBaseline("main", "local batch 1", "first", Entries(1e-3));
  ASSERT_TRUE(v1.ok()) << v1.status().ToString();
  EXPECT_EQ(*v1, 1);
  auto v2 = store->SaveBaseline("main", "local batch 2", "", Entries(2e-3));
  ASSERT_TRUE(v2.ok());
  EXPECT_EQ(*v2, 2);
  auto other = store->SaveBaseline("other", "x", "", Entries(9.0));
  ASSERT_TRUE(other.ok());
  EXPECT_EQ(*other, 1);

  auto newest = store->GetBaseline("main", 0);
  ASSERT_TRUE(newest.ok());
  EXPECT_EQ(newest->version, 2);
  EXPECT_EQ(newest->source, "local batch 2");
  ASSERT_EQ(newest->entries.size(), 3u);
  auto old = store->GetBaseline("main", 1);
  ASSERT_TRUE(old.ok());
  EXPECT_EQ(old->note, "first");
  // Sorted by case then metric: fuzzy/rmse, pi/effort_l2, pi/rmse.
  EXPECT_EQ(old->entries[2].case_name, "pi");
  EXPECT_EQ(old->entries[2].metric, "rmse");
  EXPECT_DOUBLE_EQ(old->entries[2].mean, 1e-3);
  EXPECT_DOUBLE_EQ(old->entries[2].spread, 1e-5);
  EXPECT_EQ(old->entries[2].n, 3);

  auto list = store->ListBaselines();
  ASSERT_TRUE(list.ok());
  ASSERT_EQ(list->size(), 3u);
  EXPECT_EQ((*list)[0].name, "main");
  EXPECT_EQ((*list)[1].version, 2);
  EXPECT_EQ((*list)[2].name, "other");
  EXPECT_TRUE((*list)[0].entries.empty());
}

TEST_P(BaselineStoreTest, UnknownNamesAndVersionsAreNotFound) {
  Store* store = &this->store();
  ASSERT_NE(store, nullptr);
  auto none = store->GetBaseline("nope", 0);
  ASSERT_FALSE(none.ok());
  EXPECT_EQ(none.status().code(), StatusCode::kNotFound);
  EXPECT_NE(none.status().message().find("'nope'"), std::string::npos);
  ASSERT_TRUE(store->SaveBaseline("main", "", "", Entries(1.0)).ok());
  auto v9 = store->GetBaseline("main", 9);
  ASSERT_FALSE(v9.ok());
  EXPECT_EQ(v9.status().code(), StatusCode::kNotFound);
  EXPECT_NE(v9.status().message().find("no version 9"), std::string::npos) << v9.status().message();
}

TEST_P(BaselineStoreTest, BadEntriesNameTheFieldAndStoreNothing) {
  Store* store = &this->store();
  ASSERT_NE(store, nullptr);
  ASSERT_TRUE(store->SaveBaseline("main", "", "", Entries(1.0)).ok());
  struct Case {
    std::vector<BaselineEntry> entries;
    const char* field;
  } cases[] = {
      {{{"pi", "rmse", std::nan(""), 0, 1}}, "entries[0].mean"},
      {{{"pi", "rmse", 1, -1, 1}}, "entries[0].spread"},
      {{{"pi", "rmse", 1, 0, 0}}, "entries[0].n"},
      {{{"", "rmse", 1, 0, 1}}, "entries[0].case_name"},
      {{{"pi", "rmse", 1, 0, 1}, {"pi", "rmse", 2, 0, 1}}, "entries[1]: duplicate"},
      {{}, "baseline.entries"},
  };
  for (const auto& c : cases) {
    auto v = store->SaveBaseline("main", "", "", c.entries);
    ASSERT_FALSE(v.ok()) << c.field;
    EXPECT_EQ(v.status().code(), StatusCode::kInvalidArgument);
    EXPECT_NE(v.status().message().find(c.field), std::string::npos) << v.status().message();
  }
  auto empty_name = store->SaveBaseline("", "", "", Entries(1.0));
  ASSERT_FALSE(empty_name.ok());
  EXPECT_NE(empty_name.status().message().find("baseline.name"), std::string::npos);
  auto list = store->ListBaselines();
  ASSERT_TRUE(list.ok());
  ASSERT_EQ(list->size(), 1u);  // only the good one; still version 1
  EXPECT_EQ((*list)[0].version, 1);
}

TEST_P(BaselineStoreTest, RegressionsRoundTripAndNightsFilter) {
  Store* store = &this->store();
  ASSERT_NE(store, nullptr);
  RegressionRecord a{0, "ci", "main", 1, 4, "", 0, "passed", R"({"x":1})"};
  RegressionRecord b{0, "nightly", "main", 2, 5, "2026-11-20", 0, "regressed", R"({"y":2})"};
  auto ia = store->SaveRegression(a);
  auto ib = store->SaveRegression(b);
  ASSERT_TRUE(ia.ok() && ib.ok());
  EXPECT_LT(*ia, *ib);
  auto got = store->GetRegression(*ib);
  ASSERT_TRUE(got.ok());
  EXPECT_EQ(got->night, "2026-11-20");
  EXPECT_EQ(got->verdict, "regressed");
  EXPECT_EQ(got->result_json, R"({"y":2})");
  EXPECT_GT(got->created_unix_s, 0);
  auto all = store->ListRegressions(false, 10);
  ASSERT_TRUE(all.ok());
  ASSERT_EQ(all->size(), 2u);
  EXPECT_EQ((*all)[0].id, *ib);  // newest first
  auto nights = store->ListRegressions(true, 10);
  ASSERT_TRUE(nights.ok());
  ASSERT_EQ(nights->size(), 1u);
  EXPECT_EQ((*nights)[0].suite, "nightly");
  EXPECT_FALSE(store->ListRegressions(false, 0).ok());
  auto missing = store->GetRegression(999);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  RegressionRecord bad = a;
  bad.suite.clear();
  auto refused = store->SaveRegression(bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("regression.suite"), std::string::npos);
}

TEST(BaselineSchemaTest, AVersion1FileMigratesKeepingItsData) {
  const std::string path = Cat(::testing::TempDir(), "vb_baseline_v1_", getpid(), ".db");
  std::remove(path.c_str());
  {
    // A v1 database, as the previous build left it, with one batch in it.
    auto conn = sql::Connection::Open(path);
    ASSERT_TRUE(conn.ok());
    auto v = schema::Migrate(&*conn, schema::Migrations().first(1), path);
    ASSERT_TRUE(v.ok());
    ASSERT_EQ(*v, 1);
    ASSERT_TRUE(conn->Exec("INSERT INTO batches (submitter, name, spec_json, created) VALUES ('u', 'old', '{}', 1)").ok());
  }
  {
    auto store = OpenSqliteStore(path);
    ASSERT_TRUE(store.ok()) << store.status().ToString();
    EXPECT_EQ((*store)->schema_version(), schema::CurrentVersion());
    ASSERT_TRUE((*store)->SaveBaseline("main", "", "", Entries(1.0)).ok());
  }
  auto conn = sql::Connection::Open(path);
  ASSERT_TRUE(conn.ok());
  auto name = conn->QueryText("SELECT name FROM batches");
  ASSERT_TRUE(name.ok());
  EXPECT_EQ(*name, "old");
  auto n = conn->QueryInt("SELECT count(*) FROM baseline_metrics");
  ASSERT_TRUE(n.ok());
  EXPECT_EQ(*n, 3);
  std::remove(path.c_str());
  std::remove((path + "-wal").c_str());
  std::remove((path + "-shm").c_str());
}

}  // namespace
}  // namespace vb::db
