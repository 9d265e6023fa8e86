#include "tests/db/pg_server.h"

#include <glob.h>
#include <pwd.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <iterator>
#include <memory>
#include <mutex>

#include "db/pg_conn.h"
#include "db/text.h"

namespace vb::db::testing {
namespace {

bool IsExecutable(const std::string& path) { return access(path.c_str(), X_OK) == 0; }

// pg_config --bindir, else the newest /usr/lib/postgresql/*/bin (Debian's layout), else $PATH.
std::string FindBindir() {
  if (const char* env = std::getenv("VB_PG_BINDIR"); env != nullptr && *env != '\0') return env;
  if (FILE* p = popen("pg_config --bindir 2>/dev/null", "r"); p != nullptr) {
    char buf[512] = {};
    std::string out = fgets(buf, sizeof buf, p) != nullptr ? buf : "";
    pclose(p);
    while (!out.empty() && (out.back() == '\n' || out.back() == ' ')) out.pop_back();
    if (!out.empty() && IsExecutable(out + "/initdb")) return out;
  }
  glob_t g;
  std::string found;
  if (glob("/usr/lib/postgresql/*/bin/initdb", 0, nullptr, &g) == 0 && g.gl_pathc > 0) {
    found = g.gl_pathv[g.gl_pathc - 1];
    found.resize(found.size() - std::string("/initdb").size());
  }
  globfree(&g);
  return found;
}

std::string ReadAll(const std::string& path) {
  std::ifstream in(path);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

std::string Tail(const std::string& text, std::size_t n) {
  return text.size() <= n ? text : "..." + text.substr(text.size() - n);
}

std::mutex mu;
PgServer* server = nullptr;
std::string* why_unavailable = nullptr;

void StopAtExit() {
  if (server != nullptr) server->Stop();
}

}  // namespace

PgServer* PgServer::Get() {
  std::lock_guard<std::mutex> lock(mu);
  if (server != nullptr || why_unavailable != nullptr) return server;
  auto s = std::unique_ptr<PgServer>(new PgServer());
  std::string why;
  if (!s->Start(&why)) {
    s->Stop();
    why_unavailable = new std::string(why);
    return nullptr;
  }
  server = s.release();
  std::atexit(StopAtExit);
  return server;
}

const std::string& PgServer::WhyUnavailable() {
  static const std::string none;
  return why_unavailable != nullptr ? *why_unavailable : none;
}

std::string PgServer::Location(const std::string& dbname) const { return Cat(base_, " dbname=", dbname); }

bool PgServer::Start(std::string* why) {
  if (const char* url = std::getenv("VB_TEST_PG_URL"); url != nullptr && *url != '\0') {
    admin_ = url;
    base_ = url;  // a keyword string: a later dbname= overrides its own
    if (!db::pg::IsPostgresLocation(admin_) || admin_.find("://") != std::string::npos) {
      *why = "VB_TEST_PG_URL must be a libpq keyword string (\"host=... user=...\"), not a URI";
      return false;
    }
    auto c = db::pg::Connection::Open(admin_);
    if (!c.ok()) {
      *why = Cat("VB_TEST_PG_URL: ", c.status().message());
      return false;
    }
    running_ = true;
    return true;
  }
  bindir_ = FindBindir();
  if (bindir_.empty()) {
    *why =
        "no PostgreSQL server binaries (initdb) found: install Debian's `postgresql` package "
        "(scripts/setup.sh does), or set VB_PG_BINDIR";
    return false;
  }
  char tmpl[] = "/tmp/vbpg.XXXXXX";  // short: the socket path must stay under 108 bytes
  if (mkdtemp(tmpl) == nullptr) {
    *why = "cannot create a temporary directory under /tmp";
    return false;
  }
  dir_ = tmpl;
  if (geteuid() == 0) {
    // PostgreSQL refuses to run as root: initdb and the server run as `nobody`, who owns the directory.
    const passwd* pw = getpwnam("nobody");
    if (pw == nullptr || chown(dir_.c_str(), pw->pw_uid, pw->pw_gid) != 0) {
      *why = "running as root, and cannot hand a temporary directory to user `nobody`";
      return false;
    }
    run_as_ = IsExecutable("/usr/sbin/runuser") ? "/usr/sbin/runuser -u nobody -- "
                                                : "setpriv --reuid=nobody --regid=nogroup --clear-groups -- ";
  }
  std::string tpl;
  if (!EnsureTemplate(&tpl, why)) return false;
  // cp -a keeps the owner (nobody) and the data directory's 0700 mode PostgreSQL insists on.
  if (std::system(Cat("cp -a ", tpl, "/data ", dir_, "/data").c_str()) != 0) {
    *why = Cat("cannot copy the template cluster ", tpl, " into ", dir_);
    return false;
  }
  running_ = true;  // from here on Stop() has something to stop
  if (!StartIn(dir_, why)) return false;
  base_ = Cat("host=", dir_, " port=5432 user=postgres");
  admin_ = Location("postgres");
  fresh_ = true;
  return true;
}

bool PgServer::StartIn(const std::string& dir, std::string* why) {
  const std::string log = dir + "/log";
  const std::string start =
      Cat(run_as_, bindir_, "/pg_ctl -D ", dir, "/data -l ", log, " -w -t 60 -s -o \"-c listen_addresses='' -k ", dir,
          " -c fsync=off -c synchronous_commit=off -c full_page_writes=off -c max_connections=60 "
          "-c shared_buffers=32MB\" start > /dev/null 2>&1");
  if (std::system(start.c_str()) != 0) {
    *why = Cat("the PostgreSQL server did not start: ", Tail(ReadAll(log), 600));
    return false;
  }
  return true;
}

bool PgServer::EnsureTemplate(std::string* tpl, std::string* why) {
  // 1 MB WAL segments: the copy each process makes is 26 MB instead of 41.
  *tpl = Cat("/tmp/vbpg-template2-", geteuid(), "-", std::hash<std::string>{}(bindir_) % 1000000007u);
  if (access((*tpl + "/ready").c_str(), F_OK) == 0) return true;
  char tmpl[] = "/tmp/vbpg-build.XXXXXX";
  if (mkdtemp(tmpl) == nullptr) {
    *why = "cannot create a temporary directory under /tmp";
    return false;
  }
  const std::string build = tmpl;
  auto fail = [&](std::string message) {
    (void)std::system(
        Cat(run_as_, bindir_, "/pg_ctl -D ", build, "/data -m immediate -w -s stop > /dev/null 2>&1").c_str());
    (void)std::system(Cat("rm -rf ", build).c_str());
    *why = std::move(message);
    return false;
  };
  if (geteuid() == 0) {
    const passwd* pw = getpwnam("nobody");
    if (pw == nullptr || chown(build.c_str(), pw->pw_uid, pw->pw_gid) != 0) {
      return fail("running as root, and cannot hand a temporary directory to user `nobody`");
    }
  }
  const std::string initdb = Cat(run_as_, bindir_, "/initdb -D ", build,
                                 "/data -A trust -U postgres -E UTF8 "
                                 "--locale=C --no-sync --no-instructions --wal-segsize=1 > ",
                                 build, "/initdb.log 2>&1");
  if (std::system(initdb.c_str()) != 0) return fail(Cat("initdb failed: ", Tail(ReadAll(build + "/initdb.log"), 600)));
  if (!StartIn(build, why)) return fail(*why);
  {
    auto c = db::pg::Connection::Open(Cat("host=", build, " port=5432 user=postgres dbname=postgres"));
    if (!c.ok()) return fail(c.status().message());
    const Status made = (*c)->Script(
        "CREATE DATABASE fresh TEMPLATE template0 LC_COLLATE 'C' LC_CTYPE 'C' "
        "ENCODING 'UTF8'");
    if (!made.ok()) return fail(made.message());
  }
  if (std::system(Cat(run_as_, bindir_, "/pg_ctl -D ", build, "/data -m fast -w -s stop > /dev/null 2>&1").c_str()) !=
      0) {
    return fail("the template cluster did not stop cleanly");
  }
  std::ofstream(build + "/ready")
      << "a stopped PostgreSQL cluster with an empty database 'fresh' (tests/db/pg_server.cc)\n";
  // Another test process may have built it meanwhile: then its copy is used and ours removed.
  if (rename(build.c_str(), tpl->c_str()) != 0) (void)std::system(Cat("rm -rf ", build).c_str());
  if (access((*tpl + "/ready").c_str(), F_OK) != 0) {
    *why = Cat("no template cluster at ", *tpl);
    return false;
  }
  return true;
}

StatusOr<std::string> PgServer::CreateDatabase() {
  auto c = db::pg::Connection::Open(admin_);
  if (!c.ok()) return c.status();
  if (fresh_) {  // the copied cluster's own empty database, for the process's first test
    fresh_ = false;
    return Location("fresh");
  }
  const std::string name = Cat("vbtest_", getpid(), "_", ++databases_);
  // Separate statements: DROP/CREATE DATABASE refuse to run in the implicit transaction of a multi-statement.
  VB_RETURN_IF_ERROR((*c)->Script(Cat("DROP DATABASE IF EXISTS ", name)));
  VB_RETURN_IF_ERROR(
      (*c)->Script(Cat("CREATE DATABASE ", name, " TEMPLATE template0 LC_COLLATE 'C' LC_CTYPE 'C' ENCODING 'UTF8'")));
  return Location(name);
}

void PgServer::Stop() {
  if (running_ && !dir_.empty()) {
    const std::string stop =
        Cat(run_as_, bindir_, "/pg_ctl -D ", dir_, "/data -m immediate -w -s stop > /dev/null 2>&1");
    (void)std::system(stop.c_str());
  }
  running_ = false;
  if (!dir_.empty()) (void)std::system(Cat("rm -rf ", dir_).c_str());
  dir_.clear();
}

Status PgServer::Restart() {
  if (dir_.empty() || !running_) return Status::FailedPrecondition("not a server this process started");
  const std::string cmd = Cat(run_as_, bindir_, "/pg_ctl -D ", dir_, "/data -m fast -w -t 60 -s restart > /dev/null 2>&1");
  if (std::system(cmd.c_str()) != 0) return Status::Unavailable(Cat("pg_ctl restart failed: ", Tail(ReadAll(dir_ + "/log"), 600)));
  return Status::Ok();
}

Status PgServer::StopServer() {
  if (dir_.empty() || !running_) return Status::FailedPrecondition("not a server this process started");
  const std::string cmd = Cat(run_as_, bindir_, "/pg_ctl -D ", dir_, "/data -m fast -w -t 60 -s stop > /dev/null 2>&1");
  if (std::system(cmd.c_str()) != 0) return Status::Unavailable("pg_ctl stop failed");
  return Status::Ok();
}

Status PgServer::StartServer() {
  if (dir_.empty() || !running_) return Status::FailedPrecondition("not a server this process started");
  std::string why;
  if (!StartIn(dir_, &why)) return Status::Unavailable(why);
  return Status::Ok();
}

StatusOr<int> PgServer::TerminateSessions(const std::string& dbname) {
  auto c = pg::Connection::Open(admin_);
  if (!c.ok()) return c.status();
  auto n = (*c)->QueryInt(
      "SELECT count(pg_terminate_backend(pid))::int8 FROM pg_stat_activity WHERE datname = $1 AND pid <> "
      "pg_backend_pid()",
      pg::Params().Text(dbname));
  if (!n.ok()) return n.status();
  return static_cast<int>(*n);
}

}  // namespace vb::db::testing
