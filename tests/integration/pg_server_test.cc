// valvebench-server on PostgreSQL (docs/store.md, "PostgreSQL"): "database_path" set to a PostgreSQL
// connection string; a run submitted with benchctl is queued, executed and stored (metrics, trace) in the
// database, survives a server restart, and the password in the location never reaches the server's log. The
// config keeps such a location as it is (never resolved against the config's directory).
#include "tests/db/pg_server.h"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "client/client.h"
#include "db/open_store.h"
#include "experiment/spec.h"
#include "server/config.h"
#include "server_process.h"

namespace vb {
namespace {

using testing::ServerProcess;
namespace v1 = valvebench::v1;

struct Ran {
  int code = -1;
  std::string out;
};

Ran Benchctl(const std::string& args) {
  Ran r;
  FILE* p = popen((std::string(VB_BENCHCTL) + " " + args + " 2>&1").c_str(), "r");
  if (p == nullptr) return r;
  std::array<char, 4096> buf{};
  while (fgets(buf.data(), buf.size(), p) != nullptr) r.out += buf.data();
  const int st = pclose(p);
  r.code = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

TEST(PgServerConfig, APostgresLocationIsTakenAsItIs) {
  valvebench::v1::ServerConfig c = testing::MinimalConfig();
  c.set_database_path("postgresql://lab@db.example/valvebench");
  auto url = server::SettingsFromConfig(c, "/etc/valvebench");
  ASSERT_TRUE(url.ok()) << url.status().message();
  EXPECT_EQ(url->database_path, "postgresql://lab@db.example/valvebench");
  c.set_database_path("host=/run/postgresql dbname=lab");
  auto keywords = server::SettingsFromConfig(c, "/etc/valvebench");
  ASSERT_TRUE(keywords.ok());
  EXPECT_EQ(keywords->database_path, "host=/run/postgresql dbname=lab");
  c.set_database_path("runs.db");
  auto file = server::SettingsFromConfig(c, "/etc/valvebench");
  ASSERT_TRUE(file.ok());
  EXPECT_EQ(file->database_path, "/etc/valvebench/runs.db");
}

TEST(PgServer, RunsAreQueuedExecutedAndStoredInPostgresAcrossARestart) {
  db::testing::PgServer* pg = db::testing::PgServer::Get();
  if (pg == nullptr) GTEST_SKIP() << "PostgreSQL cannot start here: " << db::testing::PgServer::WhyUnavailable();
  auto created = pg->CreateDatabase();
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const std::string location = *created + " password=hunter2-not-logged";  // trust auth: ignored, never shown

  const std::string dir = ::testing::TempDir() + "/vb-pg-server-" + std::to_string(getpid());
  std::filesystem::remove_all(dir);
  ServerProcess server(dir);
  {
    std::string config = ReadAll(dir + "/server.json");
    const std::string from = R"("database_path": "runs.db")";
    const auto at = config.find(from);
    ASSERT_NE(at, std::string::npos);
    config.replace(at, from.size(), std::string(R"("database_path": ")") + location + "\"");
    std::ofstream(dir + "/server.json") << config;
  }
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << ReadAll(dir + "/server-1.log");
  const std::string auth = " --server " + addr + " --token " + testing::kOperatorToken;
  Ran run = Benchctl("run " VB_SOURCE_DIR "/examples/standard/e1.json --wait --json" + auth);
  ASSERT_EQ(run.code, 0) << run.out;

  auto store = db::OpenStore(*created);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  auto runs = (*store)->ListRuns(db::RunFilter{});
  ASSERT_TRUE(runs.ok());
  ASSERT_EQ(runs->size(), 1u);
  EXPECT_EQ((*runs)[0].status, RunStatus::kDone);
  EXPECT_EQ((*runs)[0].fence, 1);
  auto metrics = (*store)->GetMetrics((*runs)[0].id);
  ASSERT_TRUE(metrics.ok());
  EXPECT_FALSE(metrics->empty());
  auto trace = (*store)->ReadTrace((*runs)[0].id);
  ASSERT_TRUE(trace.ok());
  EXPECT_FALSE(trace->empty());

  EXPECT_EQ(server.Kill(SIGTERM) == -1, false);
  const std::string addr2 = server.Start();
  ASSERT_FALSE(addr2.empty()) << ReadAll(dir + "/server-2.log");
  Ran show = Benchctl("show " + std::to_string((*runs)[0].id) + " --json --server " + addr2 + " --token " +
                      testing::kOperatorToken);
  EXPECT_EQ(show.code, 0) << show.out;
  EXPECT_NE(show.out.find("\"done\""), std::string::npos) << show.out;
  Ran exported = Benchctl("export " + std::to_string((*runs)[0].id) + " --csv --server " + addr2 + " --token " +
                          testing::kOperatorToken);
  EXPECT_EQ(exported.code, 0) << exported.out.substr(0, 500);
  EXPECT_GT(exported.out.size(), 100000u);  // 50 001 samples of the trace, from PostgreSQL

  const std::string log = ReadAll(dir + "/server-1.log") + ReadAll(dir + "/server-2.log");
  EXPECT_NE(log.find("database postgresql database"), std::string::npos) << log;
  EXPECT_EQ(log.find("hunter2"), std::string::npos) << log;
  server.Kill(SIGTERM);
  std::filesystem::remove_all(dir);
}

// The lab on PostgreSQL with three hosts (docs/lab.md): a run submitted through host a names host b's bench
// and executes there; host c follows it live while it runs (samples from the trace chunks b streams to the
// database), then shows, exports and compares it.
TEST(PgLab, ARunSubmittedOnOneHostAndExecutedOnAnotherIsFollowedFromAThird) {
  db::testing::PgServer* pg = db::testing::PgServer::Get();
  if (pg == nullptr) GTEST_SKIP() << "PostgreSQL cannot start here: " << db::testing::PgServer::WhyUnavailable();
  auto created = pg->CreateDatabase();
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const std::string root = ::testing::TempDir() + "/vb-pg-lab-" + std::to_string(getpid());
  std::filesystem::remove_all(root);
  std::vector<std::unique_ptr<ServerProcess>> hosts;
  std::vector<std::string> addr;
  for (const char* h : {"a", "b", "c"}) {
    const std::string dir = root + "/" + h;
    hosts.push_back(std::make_unique<ServerProcess>(
        dir, std::string(R"("lab": {"host": "host-)") + h + R"(", "lease_ttl_s": 2, "heartbeat_s": 0.5})",
        std::string(R"([{"name": ")") + h + R"(-emu", "kind": "emulated", "pace": "realtime",
                        "model": {"preset": "taghizadeh2009"}}])"));
    std::string config = ReadAll(dir + "/server.json");
    const std::string from = R"("database_path": "runs.db")";
    const auto at = config.find(from);
    ASSERT_NE(at, std::string::npos);
    config.replace(at, from.size(), std::string(R"("database_path": ")") + *created + "\"");
    std::ofstream(dir + "/server.json") << config;
    addr.push_back(hosts.back()->Start());
    ASSERT_FALSE(addr.back().empty()) << ReadAll(dir + "/server-1.log");
  }
  auto client = [&](int host) {
    client::ClientOptions o;
    o.address = addr[static_cast<size_t>(host)];
    o.token = testing::kOperatorToken;
    o.deadline_s = 20.0;
    return client::Client(o);
  };
  auto spec = experiment::ParseSpecJson(R"({"name": "lab3", "duration_s": 2.0,
      "bench": {"kind": "emulated", "name": "b-emu"},
      "conditions": {"supply_V": 24, "supply_pressure_Pa": 400000},
      "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 100, "duty": 0.5}]}},
      "recording": {"rate_Hz": 20000}})");
  ASSERT_TRUE(spec.ok()) << spec.status().message();
  auto a = client(0), c = client(2);
  auto sub = a.Submit(*spec);
  ASSERT_TRUE(sub.ok()) << sub.status().message();
  const std::int64_t id = sub->run_ids(0);

  // Host c follows it while it runs on b: live samples arrive before the run ends.
  int samples_while_running = 0;
  bool saw_running = false;
  v1::RunStatus last = v1::QUEUED;
  auto watched = c.Watch(id, 20.0, 200.0, [&](const v1::RunEvent& ev) {
    last = ev.status();
    if (ev.status() == v1::RUNNING) {
      saw_running = true;
      samples_while_running += ev.samples_size();
    }
    return true;
  });
  EXPECT_TRUE(watched.ok()) << watched.message();
  EXPECT_TRUE(saw_running);
  EXPECT_GT(samples_while_running, 0) << "no live sample reached host c while the run executed on host b";
  EXPECT_EQ(last, v1::DONE);

  auto shown = c.GetRun(id);
  ASSERT_TRUE(shown.ok()) << shown.status().message();
  EXPECT_EQ(shown->status(), v1::DONE);
  EXPECT_EQ(shown->host(), "host-b");
  auto trace = c.GetTrace(id);
  ASSERT_TRUE(trace.ok()) << trace.status().message();
  EXPECT_EQ(trace->samples(), 40'001u);
  auto compared = c.Compare(sub->batch_id(), {});
  ASSERT_TRUE(compared.ok()) << compared.status().message();
  EXPECT_GE(compared->ByteSizeLong(), 1u);
  for (auto& h : hosts) h->Kill(SIGTERM);
  std::filesystem::remove_all(root);
}

// Issue 30: the API's pooled store connections survive the database. The first calls after a PostgreSQL
// restart answer (they failed, exit 3, even 35 s later); with the database down a call says "store
// unavailable" (exit 3) without quoting SQL; back up, calls answer and the host's bench runs a run again, all
// without restarting the host.
TEST(PgServer, TheApiAnswersTheFirstCallAfterTheDatabaseRestartsAndSaysWhenItIsDown) {
  db::testing::PgServer* pg = db::testing::PgServer::Get();
  if (pg == nullptr) GTEST_SKIP() << "PostgreSQL cannot start here: " << db::testing::PgServer::WhyUnavailable();
  auto created = pg->CreateDatabase();
  ASSERT_TRUE(created.ok()) << created.status().ToString();
  const std::string dir = ::testing::TempDir() + "/vb-pg-restart-" + std::to_string(getpid());
  std::filesystem::remove_all(dir);
  ServerProcess server(dir);
  {
    std::string config = ReadAll(dir + "/server.json");
    const std::string from = R"("database_path": "runs.db")";
    const auto at = config.find(from);
    ASSERT_NE(at, std::string::npos);
    config.replace(at, from.size(), std::string(R"("database_path": ")") + *created + "\"");
    std::ofstream(dir + "/server.json") << config;
  }
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << ReadAll(dir + "/server-1.log");
  const std::string auth = " --server " + addr + " --token " + testing::kOperatorToken;
  ASSERT_EQ(Benchctl("queue" + auth).code, 0);
  ASSERT_EQ(Benchctl("benches" + auth).code, 0);

  ASSERT_TRUE(pg->Restart().ok());
  Ran queue = Benchctl("queue" + auth);
  EXPECT_EQ(queue.code, 0) << queue.out;
  Ran benches = Benchctl("benches" + auth);
  EXPECT_EQ(benches.code, 0) << benches.out;

  ASSERT_TRUE(pg->StopServer().ok());
  Ran down = Benchctl("queue" + auth);
  ASSERT_TRUE(pg->StartServer().ok());
  EXPECT_EQ(down.code, 3) << down.out;
  EXPECT_NE(down.out.find("store unavailable"), std::string::npos) << down.out;
  EXPECT_EQ(down.out.find("SELECT"), std::string::npos) << down.out;

  Ran back = Benchctl("queue" + auth);
  EXPECT_EQ(back.code, 0) << back.out;
  Ran run = Benchctl("run " VB_SOURCE_DIR "/examples/standard/e1.json --wait --json" + auth);
  EXPECT_EQ(run.code, 0) << run.out << ReadAll(dir + "/server-1.log");
}

}  // namespace
}  // namespace vb
