// A thin layer over libpq for the PostgreSQL store (db/pg_store.cc): a connection that runs parameterised
// statements (prepared once per SQL text and cached), results read in binary, transactions that roll back
// unless committed, and PostgreSQL errors as Status (docs/store.md, "PostgreSQL").
//
// Parameters and results travel in PostgreSQL's binary format: doubles go and come back bit-exact (NaN and
// infinities included), integers need no parsing and trace chunks (bytea) are neither hex-escaped nor copied.
//
// Internal to db/ (and its tests, the store copier).
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>
#include <vector>

#include "common/status.h"

struct pg_conn;
struct pg_result;


namespace vb::db::pg {

// True when `location` names a PostgreSQL database: a postgresql:// or postgres:// URI, or a libpq keyword
// string such as "host=/run/pg dbname=lab" (every key a libpq keyword). Anything else is a SQLite path.
bool IsPostgresLocation(const std::string& location);
// The location for messages: host, port, database and user, never the password.
std::string DescribeLocation(const std::string& location);

// Statement parameters, in order ($1, $2, ...). Bytes() keeps a pointer: the buffer must outlive the Exec.
class Params {
 public:
  Params& Int(std::int64_t v);
  Params& Double(double v);        // NaN and infinities stay what they are (binary float8)
  Params& DoubleOrNull(double v);  // NaN becomes NULL (SQLite's rule for metric values and t_start_s)
  Params& IntOrNull(std::optional<std::int64_t> v);  // nullopt becomes NULL
  Params& Bool(bool v);
  Params& Text(std::string_view v);
  Params& TextOrNull(std::optional<std::string_view> v);  // nullopt becomes NULL
  Params& Bytes(const void* data, std::size_t size);

  std::size_t size() const { return types_.size(); }
  // libpq's arrays, valid until the next change to this object.
  void Arrays(std::vector<const char*>* values, std::vector<int>* lengths, std::vector<int>* formats) const;
  const std::vector<unsigned>& types() const { return types_; }

 private:
  void Owned(unsigned type, std::string bytes);
  Params& Null(unsigned type);  // SQL NULL of the type
  std::vector<unsigned> types_;           // type OIDs
  std::vector<std::string> owned_;        // encoded values we own
  std::vector<std::ptrdiff_t> owned_at_;  // index into owned_, or -1: external (ext_)
  std::vector<const char*> ext_;
  std::vector<int> lengths_;
  std::vector<bool> null_;
};

// A query's rows, columns in binary format.
class Result {
 public:
  Result() = default;
  explicit Result(pg_result* r);
  int rows() const;
  int columns() const;
  bool IsNull(int row, int col) const;
  std::int64_t Int(int row, int col) const;        // int2, int4, int8 or bool columns; NULL reads 0
  double Double(int row, int col) const;           // float8 (or float4) columns; NULL reads NaN
  std::string Text(int row, int col) const;        // text columns (and anything else, as raw bytes)
  std::string_view Bytes(int row, int col) const;  // bytea: the bytes, valid while this Result lives
  std::int64_t affected() const;                   // rows an INSERT/UPDATE/DELETE touched

 private:
  struct Clear {
    void operator()(pg_result* r) const;
  };
  std::unique_ptr<pg_result, Clear> r_;
};

// Defaults every connection gets unless its location sets the same libpq keyword (docs/lab.md, "When the
// database fails"): a database that does not answer is seen, not waited for.
//   connect_timeout=5; keepalives=1, keepalives_idle=10, keepalives_interval=5, keepalives_count=3 (a peer
//   gone without closing the connection is noticed in ~25 s even on an idle connection);
//   options="-c statement_timeout=10s -c lock_timeout=5s" (the server ends a statement running or waiting for a
//   lock longer than that).
// A statement also has a deadline on this side, statement_timeout + 3 s: a server that is there but does not
// answer at all (stopped, SIGSTOP, a cut network) cannot enforce its own timeout. A statement_timeout of 0 set
// by the location means no deadline.
inline constexpr const char* kDefaultConnInfo[][2] = {
    {"connect_timeout", "5"},      {"keepalives", "1"},        {"keepalives_idle", "10"},
    {"keepalives_interval", "5"},  {"keepalives_count", "3"},
    {"options", "-c statement_timeout=10s -c lock_timeout=5s"}};
inline constexpr double kDeadlineMargin_s = 3.0;

class Connection {
 public:
  // Connects (Unavailable naming the location, without its password, if it cannot), with kDefaultConnInfo
  // under the location's own keywords. Notices are dropped.
  static StatusOr<std::unique_ptr<Connection>> Open(const std::string& location);
  ~Connection();
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  // One statement with parameters; prepared on first use of this SQL text on this connection. Errors are
  // Status codes by kind, never to be told apart by their text: the database cannot be reached or did not
  // answer (connection lost or refused, server shutting down or starting, statement timeout, too many
  // connections, no answer by the deadline): Unavailable, message starting "store unavailable: ", without the
  // statement; serialization failure, deadlock, lock timeout: Aborted (retry); unique: AlreadyExists; other
  // constraints and bad data: InvalidArgument; disk/memory: ResourceExhausted; else Internal (these name the
  // statement by its first 60 characters). Outside a transaction, a query (SELECT ...) whose connection is
  // found lost as it is sent is run once more on a new connection.
  StatusOr<Result> Exec(const std::string& sql, const Params& params = Params());
  // Several statements without parameters (migrations, BEGIN/COMMIT).
  Status Script(const std::string& sql);
  // The first column of the first row as an integer (Internal if there is no row).
  StatusOr<std::int64_t> QueryInt(const std::string& sql, const Params& params = Params());

  // Re-connects if the connection was lost (a restarted server, a terminated session, a statement past its
  // deadline); prepared statements are prepared again. An idle connection is checked first without a round
  // trip: a server that closed it (restart, pg_terminate_backend) left an error and EOF on the socket, so the
  // first call after the database returns runs on a new connection instead of failing.
  Status EnsureConnected();
  // The deadline of one statement on this side (0: none), from the session's statement_timeout.
  double deadline_s() const { return deadline_s_; }
  const std::string& location() const { return location_; }  // as described by DescribeLocation
  bool in_transaction() const;
  // False once the connection is known lost (until EnsureConnected re-makes it).
  bool connected() const;
  // True when the last statement passed its deadline (the server did not answer; the connection is dropped).
  bool timed_out() const { return broken_; }
  // Set by Transaction: inside one, a lost connection is an error (the transaction is gone), never re-made.
  void set_in_transaction_block(bool open) { txn_ = open; }
  pg_conn* raw() { return conn_; }

 private:
  Connection(pg_conn* conn, std::string location) : conn_(conn), location_(std::move(location)) {}
  Status Error(pg_result* r, std::string_view sql) const;
  // After a connect or reconnect: session settings, and the deadline from the session's statement_timeout.
  Status Setup();
  // Waits (up to the deadline) for the results of the command just sent: the first failed one, or the last.
  // nullptr with *timed_out when the deadline passed (the connection is then dropped: broken_).
  pg_result* Collect(bool* timed_out);
  StatusOr<Result> ExecOnce(const std::string& sql, const Params& params);
  // Sends with `send` (a PQsend* call) and collects; the error names `sql`.
  StatusOr<pg_result*> Run(const std::string& sql, const std::function<int()>& send);
  pg_conn* conn_;
  std::string location_;
  std::unordered_map<std::string, std::string> prepared_;  // SQL text -> statement name
  bool txn_ = false;
  bool broken_ = false;     // a statement passed its deadline: the connection is unusable until re-made
  bool in_setup_ = false;   // inside Setup()
  double deadline_s_ = 0;
};

// BEGIN ... COMMIT; the destructor rolls back a transaction that was begun and not committed.
class Transaction {
 public:
  enum class Kind { kWrite, kRead };  // kRead: REPEATABLE READ READ ONLY (one snapshot for every query)
  explicit Transaction(Connection* conn) : conn_(conn) {}
  ~Transaction();
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;
  Status Begin(Kind kind = Kind::kWrite);
  Status Commit();
  Status Rollback();

 private:
  Connection* conn_;
  bool open_ = false;
};

}  // namespace vb::db::pg
