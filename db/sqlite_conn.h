// A thin RAII layer over the SQLite C API for the store: one connection with a cache of prepared statements,
// a statement handle that resets itself when it goes out of scope (so no read transaction is ever left open
// by a half-stepped SELECT), and a transaction guard that rolls back unless committed.
//
// Internal to db/. Not thread-safe: a Connection belongs to one Store, which is used by one thread at a time.
#pragma once

#include <sqlite3.h>

#include <cstdint>
#include <string>
#include <string_view>
#include <unordered_map>

#include "common/status.h"

namespace vb::db::sql {

// Maps an SQLite result code to a Status: BUSY/LOCKED/CANTOPEN/IOERR/READONLY -> Unavailable, FULL ->
// ResourceExhausted, CORRUPT/NOTADB -> DataLoss, anything else -> Internal. The message is
// "<context>: <sqlite message> (sqlite code <n>)".
Status Error(sqlite3* db, int rc, std::string_view context);

// A cached prepared statement in use. Binding errors are remembered and reported by the next Step()/Run().
// Column accessors are valid after Step() returned true. Move-only; the destructor resets the statement and
// clears its bindings (it stays in the connection's cache) and marks it free again.
class Stmt {
 public:
  Stmt(sqlite3* db, sqlite3_stmt* stmt, bool* in_use) : db_(db), stmt_(stmt), in_use_(in_use) {}
  Stmt(Stmt&& other) noexcept;
  Stmt& operator=(Stmt&&) = delete;
  Stmt(const Stmt&) = delete;
  Stmt& operator=(const Stmt&) = delete;
  ~Stmt();

  // Parameters are numbered from 1, as in SQLite. Text is copied by SQLite (SQLITE_TRANSIENT).
  void Bind(int i, std::int64_t v);
  void Bind(int i, int v) { Bind(i, static_cast<std::int64_t>(v)); }
  void Bind(int i, bool v) { Bind(i, static_cast<std::int64_t>(v ? 1 : 0)); }
  void Bind(int i, double v);  // NaN is stored as NULL (SQLite's own rule)
  void Bind(int i, std::string_view v);
  void Bind(int i, const char* v) { Bind(i, std::string_view(v)); }
  void Bind(int i, const std::string& v) { Bind(i, std::string_view(v)); }
  // Binds without copying: `data` must stay valid until this Stmt is stepped to completion or destroyed.
  void BindBlobNoCopy(int i, const void* data, std::size_t size);
  // Named parameter (":name"); does nothing when the statement has no such parameter.
  template <typename T>
  void BindNamed(const char* name, const T& v) {
    const int i = sqlite3_bind_parameter_index(stmt_, name);
    if (i > 0) Bind(i, v);
  }

  // Advances: true when a row is available, false when done.
  StatusOr<bool> Step();
  // Steps a statement that returns no rows (INSERT/UPDATE/DELETE/BEGIN/...).
  Status Run();
  // Back to the start (bindings kept), to bind and step again after reading fewer rows than it has.
  void Reset() { sqlite3_reset(stmt_); }

  std::int64_t Int(int col) const { return sqlite3_column_int64(stmt_, col); }
  double Double(int col) const { return sqlite3_column_double(stmt_, col); }
  bool IsNull(int col) const { return sqlite3_column_type(stmt_, col) == SQLITE_NULL; }
  std::string Text(int col) const;

 private:
  sqlite3* db_;
  sqlite3_stmt* stmt_;
  bool* in_use_;  // the cache entry's flag: one cached statement cannot serve two Stmt at once
  int bind_rc_ = SQLITE_OK;
  int bind_index_ = 0;
};

class Connection {
 public:
  // Opens (creating if needed) without any pragma; the caller configures it.
  static StatusOr<Connection> Open(const std::string& path);
  Connection(Connection&& other) noexcept;
  Connection& operator=(Connection&&) = delete;
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;
  ~Connection();

  sqlite3* raw() const { return db_; }

  // A statement from the cache, prepared on first use (SQLITE_PREPARE_PERSISTENT). Internal error if the same
  // SQL text is still in use by a live Stmt (a bug: stepping one would reset the other).
  StatusOr<Stmt> Prepare(const std::string& sql);
  // Runs one or more statements without caching them (pragmas, DDL).
  Status Exec(const std::string& sql);
  // The first column of the first row of a one-off query, as an integer or text.
  StatusOr<std::int64_t> QueryInt(const std::string& sql);
  StatusOr<std::string> QueryText(const std::string& sql);

 private:
  explicit Connection(sqlite3* db) : db_(db) {}
  sqlite3* db_;
  struct Cached {
    sqlite3_stmt* stmt;
    bool in_use;
  };
  std::unordered_map<std::string, Cached> cache_;  // node-based: &Cached::in_use stays valid
};

// Incremental BLOB I/O: copies a stored BLOB straight into the caller's buffer (one copy, no temporary the
// size of the BLOB as sqlite3_column_blob() would make). One handle is re-pointed from row to row.
class BlobReader {
 public:
  BlobReader(sqlite3* db, const char* table, const char* column) : db_(db), table_(table), column_(column) {}
  BlobReader(const BlobReader&) = delete;
  BlobReader& operator=(const BlobReader&) = delete;
  ~BlobReader();

  // The size in bytes of the value in row `rowid`; call before Read() for that row.
  StatusOr<std::size_t> Open(std::int64_t rowid);
  // Reads `size` bytes (at most the value's size) of the row last opened into `dst`.
  Status Read(void* dst, std::size_t size);

 private:
  sqlite3* db_;
  const char* table_;
  const char* column_;
  sqlite3_blob* blob_ = nullptr;
};

// BEGIN IMMEDIATE (write: takes the write lock at once, waiting up to the busy timeout, so a transaction never
// fails half-way for want of an upgrade) or BEGIN (read: one consistent snapshot). Rolls back on destruction
// unless Commit() succeeded.
class Transaction {
 public:
  enum class Kind { kRead, kWrite };
  explicit Transaction(Connection* conn) : conn_(conn) {}
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;
  ~Transaction();

  Status Begin(Kind kind);
  Status Commit();

 private:
  Connection* conn_;
  bool open_ = false;
};

}  // namespace vb::db::sql

