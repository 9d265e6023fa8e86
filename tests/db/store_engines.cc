#include "tests/db/store_engines.h"

#include <unistd.h>

#include <cstdio>

#include "db/open_store.h"
#include "db/text.h"
#include "tests/db/pg_server.h"

namespace vb::db::testing {
namespace {

// SQLite files of this process, removed at exit.
class TempFiles : public ::testing::Environment {
 public:
  static std::vector<std::string>& Paths() {
    static std::vector<std::string> paths;
    return paths;
  }
  void TearDown() override {
    for (const std::string& p : Paths()) {
      for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::remove((p + suffix).c_str());
    }
  }
};
[[maybe_unused]] ::testing::Environment* const kTempFiles = ::testing::AddGlobalTestEnvironment(new TempFiles);

}  // namespace

std::vector<std::string> StoreEngines() { return {"sqlite", "postgresql"}; }

std::string EngineName(const ::testing::TestParamInfo<std::string>& info) { return info.param; }

StatusOr<std::unique_ptr<Store>> OpenFreshStore(const std::string& engine, std::string* location) {
  if (engine == "sqlite") {
    static int n = 0;
    const std::string path = Cat(::testing::TempDir(), "vb_engine_", getpid(), "_", ++n, ".db");
    for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::remove((path + suffix).c_str());
    TempFiles::Paths().push_back(path);
    if (location != nullptr) *location = path;
    return OpenStore(path);
  }
  if (engine == "postgresql") {
    PgServer* server = PgServer::Get();
    if (server == nullptr) return Status::Unavailable(Cat("PostgreSQL unavailable: ", PgServer::WhyUnavailable()));
    StatusOr<std::string> db = server->CreateDatabase();
    if (!db.ok()) return db.status();
    if (location != nullptr) *location = *db;
    return OpenStore(*db);
  }
  return Status::InvalidArgument(Cat("engine: unknown \"", engine, "\""));
}

void StoreEngineTest::SetUp() {
  if (postgres() && PgServer::Get() == nullptr) {
    GTEST_SKIP() << "PostgreSQL cannot start here, so the postgresql instance is skipped: "
                 << PgServer::WhyUnavailable();
  }
  auto s = OpenFreshStore(GetParam(), &location_);
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  store_ = std::move(s).value();
}

std::unique_ptr<Store> StoreEngineTest::OpenAnother() {
  auto s = OpenStore(location_);
  EXPECT_TRUE(s.ok()) << s.status().ToString();
  return s.ok() ? std::move(s).value() : nullptr;
}

}  // namespace vb::db::testing
