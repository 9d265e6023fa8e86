#include "db/sqlite_conn.h"

#include <utility>

#include "db/text.h"

namespace vb::db::sql {

Status Error(sqlite3* db, int rc, std::string_view context) {
  std::string msg(context);
  msg += ": ";
  // The connection's message describes the last failing call; sqlite3_errstr() only knows the code.
  msg += db != nullptr && (sqlite3_errcode(db) & 0xff) == (rc & 0xff) ? sqlite3_errmsg(db) : sqlite3_errstr(rc);
  msg += Cat(" (sqlite code ", rc, ")");
  switch (rc & 0xff) {
    case SQLITE_BUSY:
    case SQLITE_LOCKED:
    case SQLITE_CANTOPEN:
    case SQLITE_IOERR:
    case SQLITE_READONLY:
    case SQLITE_PERM:
    case SQLITE_PROTOCOL:
      return Status::Unavailable(std::move(msg));
    case SQLITE_FULL:
    case SQLITE_NOMEM:
    case SQLITE_TOOBIG:
      return Status::ResourceExhausted(std::move(msg));
    case SQLITE_CORRUPT:
    case SQLITE_NOTADB:
      return Status::DataLoss(std::move(msg));
    default:
      return Status::Internal(std::move(msg));
  }
}

// ---- Stmt ----

Stmt::Stmt(Stmt&& other) noexcept
    : db_(other.db_), stmt_(std::exchange(other.stmt_, nullptr)), in_use_(std::exchange(other.in_use_, nullptr)),
      bind_rc_(other.bind_rc_), bind_index_(other.bind_index_) {}

Stmt::~Stmt() {
  if (stmt_ == nullptr) return;
  sqlite3_reset(stmt_);
  sqlite3_clear_bindings(stmt_);
  if (in_use_ != nullptr) *in_use_ = false;
}

namespace {
inline void Remember(int rc, int i, int* bind_rc, int* bind_index) {
  if (rc != SQLITE_OK && *bind_rc == SQLITE_OK) {
    *bind_rc = rc;
    *bind_index = i;
  }
}
}  // namespace

void Stmt::Bind(int i, std::int64_t v) { Remember(sqlite3_bind_int64(stmt_, i, v), i, &bind_rc_, &bind_index_); }
void Stmt::Bind(int i, double v) { Remember(sqlite3_bind_double(stmt_, i, v), i, &bind_rc_, &bind_index_); }
void Stmt::Bind(int i, std::string_view v) {
  Remember(sqlite3_bind_text64(stmt_, i, v.data(), v.size(), SQLITE_TRANSIENT, SQLITE_UTF8), i, &bind_rc_,
           &bind_index_);
}
void Stmt::BindBlobNoCopy(int i, const void* data, std::size_t size) {
  // A zero-length blob must not be bound as NULL: SQLite treats a null pointer as NULL, so point at something.
  static const char kEmpty = 0;
  Remember(sqlite3_bind_blob64(stmt_, i, size == 0 ? &kEmpty : data, size, SQLITE_STATIC), i, &bind_rc_,
           &bind_index_);
}

StatusOr<bool> Stmt::Step() {
  if (bind_rc_ != SQLITE_OK) {
    return Error(db_, bind_rc_, Cat("binding parameter ", bind_index_, " of \"", sqlite3_sql(stmt_), "\""));
  }
  const int rc = sqlite3_step(stmt_);
  if (rc == SQLITE_ROW) return true;
  if (rc == SQLITE_DONE) return false;
  return Error(db_, rc, Cat("executing \"", sqlite3_sql(stmt_), "\""));
}

Status Stmt::Run() {
  StatusOr<bool> row = Step();
  if (!row.ok()) return row.status();
  if (*row) return Status::Internal(Cat("\"", sqlite3_sql(stmt_), "\" returned a row"));
  return Status::Ok();
}

std::string Stmt::Text(int col) const {
  const unsigned char* p = sqlite3_column_text(stmt_, col);
  const int n = sqlite3_column_bytes(stmt_, col);
  if (p == nullptr) return std::string();
  return std::string(reinterpret_cast<const char*>(p), static_cast<std::size_t>(n));
}

// ---- Connection ----

StatusOr<Connection> Connection::Open(const std::string& path) {
  sqlite3* db = nullptr;
  // NOMUTEX: the connection is never used by two threads at once (one Store per thread), so SQLite's
  // per-connection mutex would only cost time.
  const int rc = sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX,
                                 nullptr);
  if (rc != SQLITE_OK) {
    Status s = Error(db, rc, Cat("opening database '", path, "'"));
    sqlite3_close_v2(db);  // harmless on nullptr
    return s;
  }
  return Connection(db);
}

Connection::Connection(Connection&& other) noexcept
    : db_(std::exchange(other.db_, nullptr)), cache_(std::move(other.cache_)) {
  other.cache_.clear();
}

Connection::~Connection() {
  for (auto& [sql, cached] : cache_) sqlite3_finalize(cached.stmt);
  if (db_ != nullptr) sqlite3_close_v2(db_);
}

StatusOr<Stmt> Connection::Prepare(const std::string& sql) {
  auto it = cache_.find(sql);
  if (it == cache_.end()) {
    sqlite3_stmt* stmt = nullptr;
    const int rc = sqlite3_prepare_v3(db_, sql.c_str(), static_cast<int>(sql.size() + 1), SQLITE_PREPARE_PERSISTENT,
                                      &stmt, nullptr);
    if (rc != SQLITE_OK) return Error(db_, rc, Cat("preparing \"", sql, "\""));
    it = cache_.emplace(sql, Cached{stmt, false}).first;
  }
  if (it->second.in_use) return Status::Internal(Cat("statement already in use: \"", sql, "\""));
  it->second.in_use = true;
  return Stmt(db_, it->second.stmt, &it->second.in_use);
}

Status Connection::Exec(const std::string& sql) {
  char* err = nullptr;
  const int rc = sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, &err);
  if (rc == SQLITE_OK) return Status::Ok();
  // Long scripts (migrations) are cut in the message; the caller's context names them.
  std::string context = sql.size() > 120 ? Cat("executing \"", std::string_view(sql).substr(0, 117), "...\"")
                                         : Cat("executing \"", sql, "\"");
  sqlite3_free(err);
  return Error(db_, rc, context);
}

namespace {
// Runs a one-off query and hands its first row to `read` (not cached: used for pragmas at open time).
template <typename Read>
Status QueryFirst(sqlite3* db, const std::string& sql, Read read) {
  sqlite3_stmt* stmt = nullptr;
  int rc = sqlite3_prepare_v2(db, sql.c_str(), -1, &stmt, nullptr);
  if (rc != SQLITE_OK) return Error(db, rc, Cat("preparing \"", sql, "\""));
  rc = sqlite3_step(stmt);
  Status s;
  if (rc == SQLITE_ROW) {
    read(stmt);
  } else if (rc == SQLITE_DONE) {
    s = Status::Internal(Cat("\"", sql, "\" returned no row"));
  } else {
    s = Error(db, rc, Cat("executing \"", sql, "\""));
  }
  sqlite3_finalize(stmt);
  return s;
}
}  // namespace

StatusOr<std::int64_t> Connection::QueryInt(const std::string& sql) {
  std::int64_t v = 0;
  VB_RETURN_IF_ERROR(QueryFirst(db_, sql, [&](sqlite3_stmt* s) { v = sqlite3_column_int64(s, 0); }));
  return v;
}

StatusOr<std::string> Connection::QueryText(const std::string& sql) {
  std::string v;
  VB_RETURN_IF_ERROR(QueryFirst(db_, sql, [&](sqlite3_stmt* s) {
    const unsigned char* p = sqlite3_column_text(s, 0);
    if (p != nullptr) v.assign(reinterpret_cast<const char*>(p), static_cast<std::size_t>(sqlite3_column_bytes(s, 0)));
  }));
  return v;
}

// ---- BlobReader ----

BlobReader::~BlobReader() {
  if (blob_ != nullptr) sqlite3_blob_close(blob_);
}

StatusOr<std::size_t> BlobReader::Open(std::int64_t rowid) {
  const int rc = blob_ == nullptr ? sqlite3_blob_open(db_, "main", table_, column_, rowid, 0, &blob_)
                                  : sqlite3_blob_reopen(blob_, rowid);
  if (rc != SQLITE_OK) {
    // After a failed reopen the handle is aborted; close it so the next Open starts afresh.
    if (blob_ != nullptr) sqlite3_blob_close(blob_);
    blob_ = nullptr;
    return Error(db_, rc, Cat("opening ", table_, ".", column_, " of row ", rowid));
  }
  return static_cast<std::size_t>(sqlite3_blob_bytes(blob_));
}

Status BlobReader::Read(void* dst, std::size_t size) {
  if (blob_ == nullptr) return Status::Internal("BlobReader::Read without a successful Open");
  if (size == 0) return Status::Ok();
  const int rc = sqlite3_blob_read(blob_, dst, static_cast<int>(size), 0);
  if (rc != SQLITE_OK) return Error(db_, rc, Cat("reading ", table_, ".", column_));
  return Status::Ok();
}

// ---- Transaction ----

Transaction::~Transaction() {
  // A failed statement may already have rolled the transaction back (e.g. SQLITE_FULL); only roll back what
  // is still open. The result is ignored: there is nothing better to do in a destructor, and SQLite rolls back
  // an open transaction on close anyway.
  if (open_ && sqlite3_get_autocommit(conn_->raw()) == 0) {
    sqlite3_exec(conn_->raw(), "ROLLBACK", nullptr, nullptr, nullptr);
  }
}

Status Transaction::Begin(Kind kind) {
  VB_ASSIGN_OR_RETURN(Stmt begin, conn_->Prepare(kind == Kind::kWrite ? "BEGIN IMMEDIATE" : "BEGIN"));
  VB_RETURN_IF_ERROR(begin.Run());
  open_ = true;
  return Status::Ok();
}

Status Transaction::Commit() {
  VB_ASSIGN_OR_RETURN(Stmt commit, conn_->Prepare("COMMIT"));
  VB_RETURN_IF_ERROR(commit.Run());
  open_ = false;
  return Status::Ok();
}

}  // namespace vb::db::sql
