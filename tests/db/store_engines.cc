#include "tests/db/store_engines.h"

#include <sqlite3.h>
#include <unistd.h>

#include <cstdio>

#include "db/open_store.h"
#include "db/pg_conn.h"
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

namespace {

// One raw query: the first column of the first row as text (SQLite) or as the engine's binary value (PostgreSQL).
struct RawRow {
  bool ok = false;
  std::int64_t i = 0;
  std::string text;
};

RawRow RawQuery(bool postgres, const std::string& location, const std::string& sql, bool script = false) {
  RawRow out;
  if (postgres) {
    auto c = pg::Connection::Open(location);
    EXPECT_TRUE(c.ok()) << c.status().ToString();
    if (!c.ok()) return out;
    if (script) {
      const Status st = (*c)->Script(sql);
      EXPECT_TRUE(st.ok()) << st.ToString();
      out.ok = st.ok();
      return out;
    }
    auto r = (*c)->Exec(sql);
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    if (!r.ok()) return out;
    out.ok = true;
    if (r->rows() > 0 && r->columns() > 0) {
      out.i = r->Int(0, 0);
      out.text = r->Text(0, 0);
    }
    return out;
  }
  sqlite3* db = nullptr;
  EXPECT_EQ(sqlite3_open(location.c_str(), &db), SQLITE_OK);
  char* err = nullptr;
  struct Sink {
    RawRow* row;
    bool first = true;
  } sink{&out};
  const int rc = sqlite3_exec(
      db, sql.c_str(),
      [](void* p, int n, char** values, char**) {
        auto* s = static_cast<Sink*>(p);
        if (s->first && n > 0 && values[0] != nullptr) {
          s->row->text = values[0];
          s->row->i = std::strtoll(values[0], nullptr, 10);
        }
        s->first = false;
        return 0;
      },
      &sink, &err);
  EXPECT_EQ(rc, SQLITE_OK) << (err != nullptr ? err : "") << " in " << sql;
  sqlite3_free(err);
  sqlite3_close(db);
  out.ok = rc == SQLITE_OK;
  return out;
}

}  // namespace

std::int64_t StoreEngineTest::RawInt(const std::string& sql) { return RawQuery(postgres(), location_, sql).i; }
std::string StoreEngineTest::RawText(const std::string& sql) { return RawQuery(postgres(), location_, sql).text; }
void StoreEngineTest::RawExec(const std::string& sql) { RawQuery(postgres(), location_, sql, true); }

}  // namespace vb::db::testing
