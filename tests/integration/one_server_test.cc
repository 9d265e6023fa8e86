// One server per store and port (issue 27, point 5; server/instance_lock.h, docs/server.md "One server per
// store"): a second valvebench-server on a held gRPC or web port, on a SQLite store a running server holds, or
// with a lab host identity that is already running (SQLite and PostgreSQL) exits non-zero and says who holds
// it; a holder that died blocks nobody; benchctl --local still works on a store a server holds; different lab
// hosts still share one store.
#include <gtest/gtest.h>
#include <signal.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include "server/instance_lock.h"
#include "server_process.h"
#include "tests/common/run_command.h"
#include "tests/db/pg_server.h"

namespace vb {
namespace {

using testing::ServerProcess;

std::string ReadAll(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string Machine() {
  char name[256] = {};
  gethostname(name, sizeof name - 1);
  return name;
}

std::string Dir(const std::string& what) {
  const std::string dir = ::testing::TempDir() + "/vb-one-server-" +
                          ::testing::UnitTest::GetInstance()->current_test_info()->name() + "-" + what + "-" +
                          std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

// A server config in `dir` (written over ServerProcess's) with the given fields replaced.
void Rewrite(const std::string& dir, const std::string& from, const std::string& to) {
  std::string config = ReadAll(dir + "/server.json");
  const auto at = config.find(from);
  ASSERT_NE(at, std::string::npos) << config;
  config.replace(at, from.size(), to);
  std::ofstream(dir + "/server.json") << config;
}

// Runs a server to its exit (a refused one exits at once; `timeout` ends one that wrongly starts: 124).
testing::CommandResult RunToExit(const std::string& dir) {
  return testing::RunCommand("timeout 20 " VB_SERVER " --config " + dir + "/server.json");
}

// One emulated bench named after the process (bench names are unique in a lab).
std::string Benches(const std::string& name) {
  return R"([{"name": "emu-)" + name + R"(", "kind": "emulated", "model": {"preset": "taghizadeh2009"}}])";
}

int PortOf(const std::string& address) { return std::stoi(address.substr(address.rfind(':') + 1)); }

int WebPort(const ServerProcess& s) {
  const std::string key = "web dashboard on http://127.0.0.1:";
  for (int i = 0; i < 500; ++i) {
    const std::string log = s.Log();
    if (const auto at = log.find(key); at != std::string::npos) return std::stoi(log.substr(at + key.size()));
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return 0;
}

TEST(OneServer, ASecondServerOnAHeldSqliteStoreExitsNamingTheHolder) {
  ServerProcess first(Dir("a"));
  ASSERT_FALSE(first.Start().empty()) << first.Log();
  EXPECT_NE(first.Log().find("this server holds " + std::filesystem::canonical(first.dir()).string() + "/runs.db.lock"),
            std::string::npos)
      << first.Log();

  // Its own config, its own port; the same database through a symlink (the lock follows the real file).
  const std::string dir = Dir("b");
  ServerProcess second(dir);
  std::filesystem::create_symlink(first.db_path(), dir + "/runs.db");
  const auto refused = RunToExit(dir);
  EXPECT_EQ(refused.exit_code, 3) << refused.out;
  EXPECT_NE(refused.out.find("is in use by valvebench-server pid " + std::to_string(first.pid()) + " on machine " +
                             Machine()),
            std::string::npos)
      << refused.out;
  EXPECT_NE(refused.out.find("one server per store"), std::string::npos) << refused.out;
  EXPECT_EQ(refused.out.find("listening on"), std::string::npos) << refused.out;

  // benchctl --local is a client of the store, not a server: it runs on the held file as before.
  const auto local = testing::RunCommand(VB_BENCHCTL " run --local --db " + first.db_path() +
                                         " " VB_SOURCE_DIR "/examples/standard/e1.json");
  EXPECT_EQ(local.exit_code, 0) << local.out;

  // A holder that died blocks nobody: its lock went with it (its text stays in the file, unread).
  first.Kill(SIGKILL);
  ASSERT_FALSE(second.Start().empty()) << second.Log();
  EXPECT_NE(ReadAll(first.db_path() + ".lock").find("pid " + std::to_string(second.pid())), std::string::npos);
}

TEST(OneServer, ASecondServerOnAHeldGrpcPortExits) {
  ServerProcess first(Dir("a"));
  const std::string addr = first.Start();
  ASSERT_FALSE(addr.empty()) << first.Log();
  const std::string dir = Dir("b");  // its own database
  ServerProcess second(dir);
  Rewrite(dir, "127.0.0.1:0", "127.0.0.1:" + std::to_string(PortOf(addr)));
  const auto refused = RunToExit(dir);
  EXPECT_EQ(refused.exit_code, 3) << refused.out;
  EXPECT_NE(refused.out.find("cannot listen on 127.0.0.1:" + std::to_string(PortOf(addr))), std::string::npos)
      << refused.out;
}

TEST(OneServer, ASecondServerOnAHeldWebPortExits) {
  ServerProcess first(Dir("a"), R"("web": {"listen_address": "127.0.0.1:0"})");
  ASSERT_FALSE(first.Start().empty()) << first.Log();
  const int web = WebPort(first);
  ASSERT_GT(web, 0) << first.Log();
  const std::string dir = Dir("b");
  ServerProcess second(dir, R"("web": {"listen_address": "127.0.0.1:)" + std::to_string(web) + R"("})");
  const auto refused = RunToExit(dir);
  EXPECT_EQ(refused.exit_code, 3) << refused.out;
  EXPECT_NE(refused.out.find("web.listen_address: cannot listen on 127.0.0.1:" + std::to_string(web)),
            std::string::npos)
      << refused.out;
}

// Lab hosts on one SQLite file: different identities share it; a second "host-a", or a lone server, is refused.
TEST(OneServer, ALabHostIdentityRunsOnceOnASqliteStore) {
  const std::string root = Dir("lab");
  auto host = [&](const std::string& name, const std::string& identity) {
    const std::string dir = root + "/" + name;
    std::filesystem::create_directories(dir);
    if (name != "a") std::filesystem::create_symlink(root + "/a/runs.db", dir + "/runs.db");
    return std::make_unique<ServerProcess>(dir, R"("lab": {"host": ")" + identity + R"("})", Benches(name));
  };
  auto a = host("a", "host-a");
  auto b = host("b", "host-b");
  ASSERT_FALSE(a->Start().empty()) << a->Log();
  ASSERT_FALSE(b->Start().empty()) << b->Log();

  auto again = host("a2", "host-a");
  const auto refused = RunToExit(again->dir());
  EXPECT_EQ(refused.exit_code, 3) << refused.out;
  EXPECT_NE(refused.out.find("lab host 'host-a' already runs on database"), std::string::npos) << refused.out;
  EXPECT_NE(refused.out.find("pid " + std::to_string(a->pid()) + " on machine " + Machine()), std::string::npos)
      << refused.out;

  const std::string lone_dir = root + "/lone";
  ServerProcess lone(lone_dir);
  std::filesystem::create_symlink(root + "/a/runs.db", lone_dir + "/runs.db");
  const auto lone_refused = RunToExit(lone_dir);
  EXPECT_EQ(lone_refused.exit_code, 3) << lone_refused.out;
  EXPECT_NE(lone_refused.out.find("as lab host 'host-a'"), std::string::npos) << lone_refused.out;
  EXPECT_NE(lone_refused.out.find("as lab host 'host-b'"), std::string::npos) << lone_refused.out;

  a->Kill(SIGKILL);  // host-a restarts as soon as the old process is gone
  ASSERT_FALSE(again->Start().empty()) << again->Log();
}

// On PostgreSQL (a lab on several machines), the host identity is an advisory lock held by a session.
TEST(OneServer, ALabHostIdentityRunsOnceOnPostgres) {
  db::testing::PgServer* pg = db::testing::PgServer::Get();
  if (pg == nullptr) GTEST_SKIP() << "PostgreSQL cannot start here: " << db::testing::PgServer::WhyUnavailable();
  auto created = pg->CreateDatabase();
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const std::string root = Dir("pg");
  auto host = [&](const std::string& name, const std::string& identity) {
    auto s = std::make_unique<ServerProcess>(
        root + "/" + name, identity.empty() ? std::string() : R"("lab": {"host": ")" + identity + R"("})",
        Benches(name));
    Rewrite(s->dir(), R"("database_path": "runs.db")", R"("database_path": ")" + *created + "\"");
    return s;
  };
  auto a = host("a", "host-a");
  auto b = host("b", "host-b");
  ASSERT_FALSE(a->Start().empty()) << a->Log();
  ASSERT_FALSE(b->Start().empty()) << b->Log();
  EXPECT_NE(a->Log().find("this server holds PostgreSQL advisory lock (lab host 'host-a')"), std::string::npos)
      << a->Log();

  auto again = host("a2", "host-a");
  const auto refused = RunToExit(again->dir());
  EXPECT_EQ(refused.exit_code, 3) << refused.out;
  EXPECT_NE(refused.out.find("lab host 'host-a' already runs on database"), std::string::npos) << refused.out;
  EXPECT_NE(refused.out.find("valvebench-server pid " + std::to_string(a->pid()) + " on " + Machine()),
            std::string::npos)
      << refused.out;

  auto lone = host("lone", "");
  const auto lone_refused = RunToExit(lone->dir());
  EXPECT_EQ(lone_refused.exit_code, 3) << lone_refused.out;
  EXPECT_NE(lone_refused.out.find("one server per store"), std::string::npos) << lone_refused.out;

  a->Kill(SIGKILL);  // the session ends with the process; the identity is free again
  std::string addr;
  for (int i = 0; i < 50 && addr.empty(); ++i) {  // the database notices the closed socket at once, give it 5 s
    addr = again->Start();
    if (addr.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  EXPECT_FALSE(addr.empty()) << again->Log();
}

TEST(OneServer, LockPathsFollowSymlinksAndKeepOddHostNamesInOneFileName) {
  const std::string dir = Dir("paths");
  std::ofstream(dir + "/real.db") << "";
  std::filesystem::create_symlink(dir + "/real.db", dir + "/link.db");
  const std::string real = std::filesystem::canonical(dir + "/real.db").string();
  EXPECT_EQ(server::InstanceLock::StoreLockPath(dir + "/link.db"), real + ".lock");
  EXPECT_EQ(server::InstanceLock::HostLockPath(dir + "/link.db", "host-a"), real + ".host-host-a.lock");
  const std::string odd = server::InstanceLock::HostLockPath(dir + "/real.db", "../../etc/passwd");
  EXPECT_EQ(std::filesystem::path(odd).parent_path(), std::filesystem::path(real).parent_path());
  EXPECT_NE(odd, server::InstanceLock::HostLockPath(dir + "/real.db", "../../etc/shadow"));
}

}  // namespace
}  // namespace vb
