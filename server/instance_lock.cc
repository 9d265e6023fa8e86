#include "server/instance_lock.h"

#include <fcntl.h>
#include <libpq-fe.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <string>
#include <vector>

#include "db/open_store.h"

namespace vb::server {
namespace {

// PostgreSQL advisory lock keys (the two-int4 form, a key space apart from the single-bigint locks the store's
// migrations and nights take): the store-wide key, and the class of the per-host keys (hashtext of the host).
constexpr int kPgStoreClass = 1986150401;
constexpr int kPgHostClass = 1986150402;

std::string MachineName() {
  char name[256] = {};
  if (gethostname(name, sizeof name - 1) != 0 || name[0] == '\0') return "an unnamed machine";
  return name;
}

std::string NowUtc() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

// A host identity as a file name part: itself when it is short and plain, else a stable hash (FNV-1a 64).
std::string FileSafe(const std::string& host) {
  bool plain = !host.empty() && host.size() <= 64 && host[0] != '.';
  for (char c : host)
    plain = plain && ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '.' ||
                      c == '-' || c == '_');
  if (plain) return host;
  std::uint64_t h = 1469598103934665603ull;
  for (unsigned char c : host) h = (h ^ c) * 1099511628211ull;
  char buf[24];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

std::string ReadText(int fd) {
  std::string text;
  char buf[512];
  ssize_t n;
  off_t at = 0;
  while ((n = pread(fd, buf, sizeof buf, at)) > 0) {
    text.append(buf, static_cast<size_t>(n));
    at += n;
  }
  while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.pop_back();
  return text;
}

void WriteText(int fd, const std::string& text) {
  if (ftruncate(fd, 0) != 0) return;
  const std::string line = text + "\n";
  (void)!pwrite(fd, line.data(), line.size(), 0);
}

StatusOr<int> OpenLockFile(const std::string& path) {
  const int fd = open(path.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0)
    return Status::Unavailable("cannot open the lock file " + path + ": " + std::strerror(errno) +
                               " (the server needs to write in the database's directory)");
  return fd;
}

// The lab hosts holding their lock files beside `real` (a lone server was refused because of them).
std::string LabHolders(const std::string& real) {
  namespace fs = std::filesystem;
  const fs::path p(real);
  const std::string prefix = p.filename().string() + ".host-";
  std::vector<std::string> held;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(p.parent_path(), ec)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(prefix, 0) != 0 || name.size() < 5 || name.substr(name.size() - 5) != ".lock") continue;
    const int fd = open(e.path().c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) continue;
    if (flock(fd, LOCK_SH | LOCK_NB) != 0) held.push_back(ReadText(fd));
    close(fd);
  }
  if (held.empty()) return "another valvebench-server (starting: it has not written its pid yet)";
  std::string out;
  for (const auto& h : held) out += (out.empty() ? "" : "; ") + (h.empty() ? "a lab host" : h);
  return out;
}

std::string Holder(const std::string& text) {
  return text.empty() ? "another valvebench-server (it has not written its pid yet)" : text;
}

}  // namespace

std::string InstanceLock::StoreLockPath(const std::string& db_path) {
  std::error_code ec;
  std::filesystem::path real = std::filesystem::weakly_canonical(std::filesystem::absolute(db_path), ec);
  if (ec) real = std::filesystem::absolute(db_path);
  return real.string() + ".lock";
}

std::string InstanceLock::HostLockPath(const std::string& db_path, const std::string& host) {
  std::string store = StoreLockPath(db_path);
  store.resize(store.size() - 5);  // the database's real path
  return store + ".host-" + FileSafe(host) + ".lock";
}

StatusOr<std::unique_ptr<InstanceLock>> InstanceLock::Acquire(const std::string& location, const std::string& host) {
  std::unique_ptr<InstanceLock> lock(new InstanceLock());
  const std::string me = "valvebench-server pid " + std::to_string(getpid()) + " on machine " + MachineName();
  const std::string where = db::DisplayLocation(location);

  if (location.empty() || location == ":memory:") {
    lock->description_ = "none (an in-memory store)";
    return lock;
  }

  if (!db::IsPostgresLocation(location)) {
    const std::string store_path = StoreLockPath(location);
    auto fd = OpenLockFile(store_path);
    if (!fd.ok()) return fd.status();
    lock->store_fd_ = *fd;
    if (host.empty()) {
      if (flock(lock->store_fd_, LOCK_EX | LOCK_NB) != 0) {
        const std::string text = ReadText(lock->store_fd_);
        return Status::FailedPrecondition(
            "database " + where + " is in use by " +
            (text.empty() ? LabHolders(store_path.substr(0, store_path.size() - 5)) : text) + " (lock " + store_path +
            "): one server per store; stop that server first, or give this one another "
            "database_path");
      }
      WriteText(lock->store_fd_, me + " (not in a lab), since " + NowUtc());
      lock->description_ = store_path;
      return lock;
    }
    // A lab host: the store shared with the other hosts, this host's identity alone.
    if (flock(lock->store_fd_, LOCK_SH | LOCK_NB) != 0)
      return Status::FailedPrecondition("database " + where + " is in use by " + Holder(ReadText(lock->store_fd_)) +
                                        ", a server that is not in a lab (lock " + store_path +
                                        "): lab hosts cannot share its store; stop it first");
    WriteText(lock->store_fd_, "");  // a text here would name a lone server: there is none while a host holds it
    const std::string host_path = HostLockPath(location, host);
    auto hfd = OpenLockFile(host_path);
    if (!hfd.ok()) return hfd.status();
    lock->host_fd_ = *hfd;
    if (flock(lock->host_fd_, LOCK_EX | LOCK_NB) != 0)
      return Status::FailedPrecondition("lab host '" + host + "' already runs on database " + where + ": " +
                                        Holder(ReadText(lock->host_fd_)) + " (lock " + host_path +
                                        "): one process per host identity; stop it first, or give this one "
                                        "another lab.host");
    WriteText(lock->host_fd_, me + " as lab host '" + host + "', since " + NowUtc());
    lock->description_ = host_path;
    return lock;
  }

  // PostgreSQL: a session of our own that holds advisory locks until it ends.
  std::string app = "valvebench-server pid " + std::to_string(getpid()) + " on " + MachineName();
  if (app.size() > 63) app.resize(63);  // NAMEDATALEN - 1
  const char* keys[] = {"dbname", "application_name", nullptr};
  const char* values[] = {location.c_str(), app.c_str(), nullptr};
  PGconn* conn = PQconnectdbParams(keys, values, 1);
  lock->pg_ = conn;
  if (conn == nullptr || PQstatus(conn) != CONNECTION_OK) {
    std::string msg = conn ? PQerrorMessage(conn) : "out of memory";
    while (!msg.empty() && (msg.back() == '\n' || msg.back() == ' ')) msg.pop_back();
    return Status::Unavailable(where + ": cannot connect to take the server's lock: " + msg);
  }
  // A host that vanishes without closing its connection (power cut, network gone) must not keep its identity
  // for the kernel's default two hours: the database probes the connection after 5 s idle and drops it after
  // ~11 s of silence. Ignored on Unix sockets.
  PQclear(PQexec(conn,
                 "SET tcp_keepalives_idle = 5; SET tcp_keepalives_interval = 2; SET tcp_keepalives_count = 3; "
                 "SET tcp_user_timeout = 10000"));
  auto query = [conn](const std::string& sql, const std::string& param, std::string* value) -> Status {
    const char* p[] = {param.c_str()};
    PGresult* r = PQexecParams(conn, sql.c_str(), param.empty() ? 0 : 1, nullptr, param.empty() ? nullptr : p, nullptr,
                               nullptr, 0);
    if (PQresultStatus(r) != PGRES_TUPLES_OK) {
      std::string msg = PQresultErrorMessage(r);
      while (!msg.empty() && msg.back() == '\n') msg.pop_back();
      PQclear(r);
      return Status::Unavailable("taking the server's lock: " + msg);
    }
    *value = PQntuples(r) > 0 && !PQgetisnull(r, 0, 0) ? PQgetvalue(r, 0, 0) : "";
    PQclear(r);
    return Status::Ok();
  };
  // Who holds a key (class, objid expression), from pg_locks and the holders' application_name.
  auto holders = [&](int key_class, const std::string& objid, const std::string& param) {
    std::string text;
    const std::string sql =
        "SELECT string_agg(coalesce(nullif(a.application_name, ''), 'pid ' || a.pid || ' on the database') || "
        "' (connected from ' || coalesce(host(a.client_addr), 'a local socket') || ')', '; ') "
        "FROM pg_locks l JOIN pg_stat_activity a ON a.pid = l.pid WHERE l.locktype = 'advisory' AND l.granted "
        "AND l.objsubid = 2 AND l.classid = " +
        std::to_string(key_class) + "::oid AND l.objid = (" + objid + ")::oid AND a.pid <> pg_backend_pid()";
    if (!query(sql, param, &text).ok() || text.empty())
      return std::string("another process (not visible to this role)");
    return text;
  };
  const std::string store_key = std::to_string(kPgStoreClass) + ", 0";
  std::string got;
  if (host.empty()) {
    VB_RETURN_IF_ERROR(query("SELECT pg_try_advisory_lock(" + store_key + ")", "", &got));
    if (got != "t")
      return Status::FailedPrecondition("database " + where + " is in use by " + holders(kPgStoreClass, "0", "") +
                                        ": one server per store (a lab's hosts each need a \"lab\" block); stop "
                                        "that server first, or give this one another database_path");
    lock->description_ = "PostgreSQL advisory lock (store) on " + where;
    return lock;
  }
  VB_RETURN_IF_ERROR(query("SELECT pg_try_advisory_lock_shared(" + store_key + ")", "", &got));
  if (got != "t")
    return Status::FailedPrecondition("database " + where + " is in use by " + holders(kPgStoreClass, "0", "") +
                                      ", a server that is not in a lab: lab hosts cannot share its store; stop it "
                                      "first");
  VB_RETURN_IF_ERROR(
      query("SELECT pg_try_advisory_lock(" + std::to_string(kPgHostClass) + ", hashtext($1))", host, &got));
  if (got != "t")
    return Status::FailedPrecondition("lab host '" + host + "' already runs on database " + where + ": " +
                                      holders(kPgHostClass, "hashtext($1)", host) +
                                      " holds its identity: one process per host identity; stop it first, or give "
                                      "this one another lab.host");
  lock->description_ = "PostgreSQL advisory lock (lab host '" + host + "') on " + where;
  return lock;
}

InstanceLock::~InstanceLock() {
  if (host_fd_ >= 0) close(host_fd_);
  if (store_fd_ >= 0) close(store_fd_);
  if (pg_ != nullptr) PQfinish(static_cast<PGconn*>(pg_));
}

}  // namespace vb::server
