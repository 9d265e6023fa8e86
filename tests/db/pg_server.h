// A throwaway PostgreSQL server for tests (docs/store.md, "Testing on PostgreSQL"): a copy of a template cluster
// (initdb'd once) started with pg_ctl in a temporary directory, listening only on a Unix socket in that
// directory (no TCP), fsync off. As root it runs as `nobody` (PostgreSQL refuses to run as root). One server per
// test process, started on first use and stopped at exit; every test gets a database of its own.
//
// VB_TEST_PG_URL=<libpq keyword string>: use that server instead (a database per test is created on it; the
// role needs CREATEDB).
#pragma once

#include <string>

#include "common/status.h"

namespace vb::db::testing {

class PgServer {
 public:
  // The process's server, started on first call; nullptr if it cannot start (WhyUnavailable() says why).
  static PgServer* Get();
  static const std::string& WhyUnavailable();

  // Creates a new, empty database and returns a libpq connection string for it.
  StatusOr<std::string> CreateDatabase();
  // The connection string of the maintenance database ("postgres").
  const std::string& admin_location() const { return admin_; }

  void Stop();  // idempotent; also at process exit

  // Database faults for the tests of a store that survives them (docs/lab.md, "When the database fails"). Only
  // on the server this process started (FailedPrecondition with VB_TEST_PG_URL). They affect every database of
  // the process's server: use them in a test binary of their own.
  Status Restart();        // pg_ctl restart -m fast: every session is ended, the server is back when it returns
  Status StopServer();     // pg_ctl stop -m fast: an outage, until StartServer()
  Status StartServer();
  // pg_terminate_backend of every session on `dbname` but the caller's own; returns how many.
  StatusOr<int> TerminateSessions(const std::string& dbname);

 private:
  PgServer() = default;
  bool Start(std::string* why);
  // A stopped cluster with an empty database "fresh", made by initdb once per machine, user and PostgreSQL
  // build (/tmp/vbpg-template-UID-HASH, kept between runs: initdb takes 1-4 s, a copy 0.1 s).
  bool EnsureTemplate(std::string* tpl, std::string* why);
  bool StartIn(const std::string& dir, std::string* why);  // pg_ctl start on dir/data, socket in dir
  std::string Location(const std::string& dbname) const;

  std::string dir_;  // temporary directory (data/, socket, log); empty when external
  std::string bindir_;
  std::string run_as_;  // "runuser -u nobody -- " when running as root
  std::string admin_;
  std::string base_;  // connection string without dbname
  bool running_ = false;
  bool fresh_ = false;  // "fresh" not handed out yet
  int databases_ = 0;
};

}  // namespace vb::db::testing
