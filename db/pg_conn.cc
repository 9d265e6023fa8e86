#include "db/pg_conn.h"

#include <libpq-fe.h>

#include <poll.h>

#include <algorithm>
#include <bit>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <utility>

#include "common/format.h"
#include "db/text.h"

namespace vb::db::pg {
namespace {

// Type OIDs (src/include/catalog/pg_type.dat); stable across PostgreSQL versions.
constexpr unsigned kBoolOid = 16, kByteaOid = 17, kInt8Oid = 20, kInt2Oid = 21, kInt4Oid = 23, kTextOid = 25,
                   kFloat4Oid = 700, kFloat8Oid = 701;

std::string BigEndian(std::uint64_t v, int bytes) {
  std::string out(static_cast<std::size_t>(bytes), '\0');
  for (int k = bytes - 1; k >= 0; --k) {
    out[static_cast<std::size_t>(k)] = static_cast<char>(v & 0xff);
    v >>= 8;
  }
  return out;
}

std::uint64_t FromBigEndian(const char* p, int bytes) {
  std::uint64_t v = 0;
  for (int k = 0; k < bytes; ++k) v = (v << 8) | static_cast<unsigned char>(p[k]);
  return v;
}

void DropNotice(void*, const char*) {}

}  // namespace

bool IsPostgresLocation(const std::string& location) {
  if (location.rfind("postgresql://", 0) == 0 || location.rfind("postgres://", 0) == 0) return true;
  if (location.find('=') == std::string::npos) return false;
  char* err = nullptr;
  PQconninfoOption* opts = PQconninfoParse(location.c_str(), &err);
  if (err != nullptr) PQfreemem(err);
  if (opts == nullptr) return false;
  PQconninfoFree(opts);
  return true;
}

std::string DescribeLocation(const std::string& location) {
  char* err = nullptr;
  PQconninfoOption* opts = PQconninfoParse(location.c_str(), &err);
  if (err != nullptr) PQfreemem(err);
  if (opts == nullptr) return "postgresql database (unparsable connection string)";
  std::string host, port, dbname, user;
  for (PQconninfoOption* o = opts; o->keyword != nullptr; ++o) {
    if (o->val == nullptr) continue;
    const std::string_view key = o->keyword;
    if (key == "host" || key == "hostaddr") host = o->val;
    if (key == "port") port = o->val;
    if (key == "dbname") dbname = o->val;
    if (key == "user") user = o->val;
  }
  PQconninfoFree(opts);
  std::string out = Cat("postgresql database '", dbname.empty() ? std::string("(default)") : dbname, "'");
  if (!host.empty()) out += Cat(" on '", host, port.empty() ? std::string() : Cat(":", port), "'");
  if (!user.empty()) out += Cat(" as '", user, "'");
  return out;
}

// ---- Params ----

void Params::Owned(unsigned type, std::string bytes) {
  types_.push_back(type);
  lengths_.push_back(static_cast<int>(bytes.size()));
  owned_at_.push_back(static_cast<std::ptrdiff_t>(owned_.size()));
  owned_.push_back(std::move(bytes));
  ext_.push_back(nullptr);
  null_.push_back(false);
}

Params& Params::Int(std::int64_t v) {
  Owned(kInt8Oid, BigEndian(static_cast<std::uint64_t>(v), 8));
  return *this;
}

Params& Params::Double(double v) {
  Owned(kFloat8Oid, BigEndian(std::bit_cast<std::uint64_t>(v), 8));
  return *this;
}

Params& Params::DoubleOrNull(double v) { return std::isnan(v) ? Null(kFloat8Oid) : Double(v); }

Params& Params::Null(unsigned type) {
  types_.push_back(type);
  lengths_.push_back(0);
  owned_at_.push_back(-1);
  ext_.push_back(nullptr);
  null_.push_back(true);
  return *this;
}

Params& Params::IntOrNull(std::optional<std::int64_t> v) { return v ? Int(*v) : Null(kInt8Oid); }

Params& Params::Bool(bool v) {
  Owned(kBoolOid, std::string(1, v ? '\1' : '\0'));
  return *this;
}

Params& Params::Text(std::string_view v) {
  Owned(kTextOid, std::string(v));
  return *this;
}

Params& Params::TextOrNull(std::optional<std::string_view> v) { return v ? Text(*v) : Null(kTextOid); }

Params& Params::Bytes(const void* data, std::size_t size) {
  types_.push_back(kByteaOid);
  lengths_.push_back(static_cast<int>(size));
  owned_at_.push_back(-1);
  // A zero-length value needs a non-null pointer (a null one is SQL NULL).
  ext_.push_back(size == 0 ? "" : static_cast<const char*>(data));
  null_.push_back(false);
  return *this;
}

void Params::Arrays(std::vector<const char*>* values, std::vector<int>* lengths, std::vector<int>* formats) const {
  const std::size_t n = types_.size();
  values->resize(n);
  lengths->assign(lengths_.begin(), lengths_.end());
  formats->assign(n, 1);
  for (std::size_t k = 0; k < n; ++k) {
    if (null_[k]) {
      (*values)[k] = nullptr;
    } else if (owned_at_[k] >= 0) {
      (*values)[k] = owned_[static_cast<std::size_t>(owned_at_[k])].data();
    } else {
      (*values)[k] = ext_[k];
    }
  }
}

// ---- Result ----

void Result::Clear::operator()(pg_result* r) const { PQclear(r); }
Result::Result(pg_result* r) : r_(r) {}
int Result::rows() const { return r_ ? PQntuples(r_.get()) : 0; }
int Result::columns() const { return r_ ? PQnfields(r_.get()) : 0; }
bool Result::IsNull(int row, int col) const { return PQgetisnull(r_.get(), row, col) != 0; }

std::int64_t Result::Int(int row, int col) const {
  if (IsNull(row, col)) return 0;
  const char* p = PQgetvalue(r_.get(), row, col);
  switch (PQgetlength(r_.get(), row, col)) {
    case 1:
      return static_cast<unsigned char>(p[0]);
    case 2:
      return static_cast<std::int16_t>(FromBigEndian(p, 2));
    case 4:
      return static_cast<std::int32_t>(FromBigEndian(p, 4));
    case 8:
      return static_cast<std::int64_t>(FromBigEndian(p, 8));
    default:
      return 0;  // not an integer column: a bug in the query (the store casts sums and counts)
  }
}

double Result::Double(int row, int col) const {
  if (IsNull(row, col)) return std::nan("");
  const char* p = PQgetvalue(r_.get(), row, col);
  const int len = PQgetlength(r_.get(), row, col);
  if (PQftype(r_.get(), col) == kFloat4Oid && len == 4) {
    return std::bit_cast<float>(static_cast<std::uint32_t>(FromBigEndian(p, 4)));
  }
  if (PQftype(r_.get(), col) == kFloat8Oid && len == 8) return std::bit_cast<double>(FromBigEndian(p, 8));
  const unsigned type = PQftype(r_.get(), col);
  if (type == kInt8Oid || type == kInt4Oid || type == kInt2Oid) return static_cast<double>(Int(row, col));
  return std::nan("");  // not a float column: a bug in the query
}

std::string Result::Text(int row, int col) const {
  if (IsNull(row, col)) return std::string();
  return std::string(PQgetvalue(r_.get(), row, col), static_cast<std::size_t>(PQgetlength(r_.get(), row, col)));
}

std::string_view Result::Bytes(int row, int col) const {
  return std::string_view(PQgetvalue(r_.get(), row, col), static_cast<std::size_t>(PQgetlength(r_.get(), row, col)));
}

std::int64_t Result::affected() const {
  const char* n = r_ ? PQcmdTuples(r_.get()) : "";
  return n[0] == '\0' ? 0 : std::strtoll(n, nullptr, 10);
}

// ---- Connection ----

namespace {

std::string FirstLine(std::string msg) {
  if (const std::size_t nl = msg.find('\n'); nl != std::string::npos) msg.resize(nl);
  while (!msg.empty() && (msg.back() == '\n' || msg.back() == ' ')) msg.pop_back();
  return msg;
}

// A statement in a message: its first 60 characters (the whole text, quoted in every error, made the messages
// unreadable: issue 30).
std::string Clip(std::string_view sql) {
  if (sql.size() <= 60) return Cat("\"", sql, "\"");
  return Cat("\"", sql.substr(0, 57), "...\"");
}

bool Failed(const PGresult* r) {
  const ExecStatusType st = r != nullptr ? PQresultStatus(r) : PGRES_FATAL_ERROR;
  return st != PGRES_TUPLES_OK && st != PGRES_COMMAND_OK;
}

}  // namespace

StatusOr<std::unique_ptr<Connection>> Connection::Open(const std::string& location) {
  const std::string where = DescribeLocation(location);
  // Our defaults first, then the location (expanded): libpq keeps the last value of a keyword, so the
  // location's own settings win.
  std::vector<const char*> keys, values;
  for (const auto& kv : kDefaultConnInfo) {
    keys.push_back(kv[0]);
    values.push_back(kv[1]);
  }
  keys.push_back("dbname");
  values.push_back(location.c_str());
  keys.push_back(nullptr);
  values.push_back(nullptr);
  PGconn* conn = PQconnectdbParams(keys.data(), values.data(), /*expand_dbname=*/1);
  if (conn == nullptr) return Status::ResourceExhausted(Cat(where, ": out of memory connecting"));
  if (PQstatus(conn) != CONNECTION_OK) {
    std::string msg = FirstLine(PQerrorMessage(conn));
    PQfinish(conn);
    return Status::Unavailable(Cat("store unavailable: ", where, ": cannot connect: ", msg));
  }
  auto c = std::unique_ptr<Connection>(new Connection(conn, where));
  VB_RETURN_IF_ERROR(c->Setup());
  return c;
}

Status Connection::Setup() {
  PQsetNoticeProcessor(conn_, DropNotice, nullptr);
  broken_ = false;
  deadline_s_ = 10 + kDeadlineMargin_s;  // for the SET and SELECT below, until the session's own is known
  in_setup_ = true;  // a connection lost here is reported, not re-made from inside its own making
  // UTC and UTF-8 whatever the server's defaults; times are stored as unix seconds anyway.
  Status st = Script("SET TIME ZONE 'UTC'; SET client_encoding = 'UTF8'");
  StatusOr<std::int64_t> timeout_ms = std::int64_t{0};
  if (st.ok()) timeout_ms = QueryInt("SELECT setting::int8 FROM pg_settings WHERE name = 'statement_timeout'");
  in_setup_ = false;
  VB_RETURN_IF_ERROR(st);
  if (!timeout_ms.ok()) return timeout_ms.status();
  deadline_s_ = *timeout_ms > 0 ? static_cast<double>(*timeout_ms) / 1000.0 + kDeadlineMargin_s : 0.0;
  return Status::Ok();
}

Connection::~Connection() {
  if (conn_ != nullptr) PQfinish(conn_);
}

bool Connection::in_transaction() const { return PQtransactionStatus(conn_) != PQTRANS_IDLE; }
bool Connection::connected() const { return !broken_ && PQstatus(conn_) == CONNECTION_OK; }

Status Connection::EnsureConnected() {
  if (!broken_ && PQstatus(conn_) == CONNECTION_OK && PQtransactionStatus(conn_) == PQTRANS_IDLE) {
    // Idle: nothing should be on the socket. A server that ended the session (restart, terminated backend)
    // left its error message and EOF there; reading them marks the connection bad without a round trip.
    for (int k = 0; k < 4; ++k) {
      pollfd p{PQsocket(conn_), POLLIN, 0};
      if (p.fd < 0 || poll(&p, 1, 0) <= 0) break;
      if (PQconsumeInput(conn_) == 0) break;
      while (PGresult* r = PQgetResult(conn_)) PQclear(r);  // nothing expected; keep the connection idle
    }
  }
  if (!broken_ && PQstatus(conn_) == CONNECTION_OK) return Status::Ok();
  if (txn_ || in_setup_) {
    return Status::Unavailable(Cat("store unavailable: ", location_, ": connection lost ",
                                   txn_ ? "inside a transaction: " : "while being set up: ",
                                   broken_ ? std::string("a statement passed its deadline")
                                           : FirstLine(PQerrorMessage(conn_))));
  }
  PQreset(conn_);
  prepared_.clear();
  broken_ = false;
  if (PQstatus(conn_) != CONNECTION_OK) {
    return Status::Unavailable(
        Cat("store unavailable: ", location_, ": connection lost and cannot reconnect: ", FirstLine(PQerrorMessage(conn_))));
  }
  return Setup();
}

Status Connection::Error(pg_result* r, std::string_view sql) const {
  std::string msg = FirstLine(r != nullptr ? PQresultErrorMessage(r) : PQerrorMessage(conn_));
  if (msg.empty()) msg = FirstLine(PQerrorMessage(conn_));
  const char* state = r != nullptr ? PQresultErrorField(r, PG_DIAG_SQLSTATE) : nullptr;
  const std::string sqlstate = state != nullptr ? state : "";
  const std::string code = sqlstate.empty() ? std::string() : Cat(" (sqlstate ", sqlstate, ")");
  // The database cannot be reached or does not answer: connection exceptions (08), the server shutting down
  // or starting (57P01-57P05), a statement cancelled by statement_timeout (57014), too many connections (53300).
  if (PQstatus(conn_) != CONNECTION_OK || broken_ || sqlstate.rfind("08", 0) == 0 ||
      sqlstate.rfind("57P", 0) == 0 || sqlstate == "57014" || sqlstate == "53300") {
    return Status::Unavailable(Cat("store unavailable: ", location_, ": ", msg, code));
  }
  std::string text = Cat(location_, ": ", Clip(sql), ": ", msg, code);
  if (sqlstate.rfind("40", 0) == 0 || sqlstate == "55P03") return Status::Aborted(std::move(text));
  if (sqlstate == "23505") return Status::AlreadyExists(std::move(text));
  if (sqlstate.rfind("23", 0) == 0 || sqlstate.rfind("22", 0) == 0) return Status::InvalidArgument(std::move(text));
  if (sqlstate.rfind("53", 0) == 0 || sqlstate == "54000") return Status::ResourceExhausted(std::move(text));
  if (sqlstate.rfind("XX", 0) == 0) return Status::DataLoss(std::move(text));
  return Status::Internal(std::move(text));
}

pg_result* Connection::Collect(bool* timed_out) {
  *timed_out = false;
  using Clock = std::chrono::steady_clock;
  const bool bounded = deadline_s_ > 0;
  const Clock::time_point deadline =
      Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(deadline_s_));
  PGresult* keep = nullptr;
  while (true) {
    while (PQisBusy(conn_)) {
      int wait_ms = -1;
      if (bounded) {
        const auto left = std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now()).count();
        wait_ms = static_cast<int>(std::max<long long>(0, left));
      }
      pollfd p{PQsocket(conn_), POLLIN, 0};
      const int n = p.fd < 0 ? -1 : poll(&p, 1, wait_ms);
      if (n == 0) {  // the deadline passed without an answer: the connection cannot be used again
        if (keep != nullptr) PQclear(keep);
        broken_ = true;
        *timed_out = true;
        return nullptr;
      }
      if (n < 0 && errno == EINTR) continue;
      if (n < 0 || PQconsumeInput(conn_) == 0) break;  // broken: PQgetResult reports it
    }
    PGresult* r = PQgetResult(conn_);
    if (r == nullptr) break;
    if (keep == nullptr || (!Failed(keep) && Failed(r))) {
      if (keep != nullptr) PQclear(keep);
      keep = r;
    } else if (!Failed(keep)) {
      PQclear(keep);
      keep = r;
    } else {
      PQclear(r);  // keep the first failure
    }
    if (PQstatus(conn_) != CONNECTION_OK) break;
  }
  return keep;
}

StatusOr<pg_result*> Connection::Run(const std::string& sql, const std::function<int()>& send) {
  if (broken_ || PQstatus(conn_) != CONNECTION_OK) {
    return Status::Unavailable(Cat("store unavailable: ", location_, ": connection lost: ",
                                   broken_ ? std::string("a statement passed its deadline")
                                           : FirstLine(PQerrorMessage(conn_))));
  }
  if (send() == 0) return Error(nullptr, sql);
  bool timed_out = false;
  PGresult* r = Collect(&timed_out);
  if (timed_out) {
    return Status::Unavailable(Cat("store unavailable: ", location_, ": no answer within ", FormatNumber(deadline_s_),
                                   " s (the server is stopped, hung or out of reach); the connection is dropped"));
  }
  if (Failed(r)) {
    Status s = Error(r, sql);
    if (r != nullptr) PQclear(r);
    return s;
  }
  return r;
}

StatusOr<Result> Connection::Exec(const std::string& sql, const Params& params) {
  StatusOr<Result> r = ExecOnce(sql, params);
  // A query on its own (no transaction) whose connection turned out lost as it was sent (a session terminated
  // or a server restarted just then): it changed nothing, so once more on a new connection. Only for queries
  // that read: a write's COMMIT may have landed before the connection went.
  // Not after a deadline: a server that does not answer would only be waited for twice.
  if (!txn_ && !in_setup_ && !r.ok() && r.status().code() == StatusCode::kUnavailable && !broken_ &&
      PQstatus(conn_) != CONNECTION_OK && sql.rfind("SELECT ", 0) == 0) {
    r = ExecOnce(sql, params);
  }
  return r;
}

StatusOr<Result> Connection::ExecOnce(const std::string& sql, const Params& params) {
  if (!txn_) VB_RETURN_IF_ERROR(EnsureConnected());  // a statement on its own may run on a new connection
  auto it = prepared_.find(sql);
  if (it == prepared_.end()) {
    const std::string name = Cat("vb", prepared_.size());
    VB_ASSIGN_OR_RETURN(PGresult * prep, Run(sql, [&] {
                             return PQsendPrepare(conn_, name.c_str(), sql.c_str(), static_cast<int>(params.size()),
                                                  params.types().data());
                           }));
    PQclear(prep);
    it = prepared_.emplace(sql, name).first;
  }
  std::vector<const char*> values;
  std::vector<int> lengths, formats;
  params.Arrays(&values, &lengths, &formats);
  VB_ASSIGN_OR_RETURN(PGresult * r, Run(sql, [&] {
                           return PQsendQueryPrepared(conn_, it->second.c_str(), static_cast<int>(params.size()),
                                                      values.data(), lengths.data(), formats.data(),
                                                      /*resultFormat=*/1);
                         }));
  return Result(r);
}

Status Connection::Script(const std::string& sql) {
  VB_ASSIGN_OR_RETURN(PGresult * r, Run(sql, [&] { return PQsendQuery(conn_, sql.c_str()); }));
  PQclear(r);
  return Status::Ok();
}

StatusOr<std::int64_t> Connection::QueryInt(const std::string& sql, const Params& params) {
  VB_ASSIGN_OR_RETURN(Result r, Exec(sql, params));
  if (r.rows() < 1 || r.columns() < 1) return Status::Internal(Cat("\"", sql, "\" returned no row"));
  return r.Int(0, 0);
}

// ---- Transaction ----

Transaction::~Transaction() {
  if (open_) (void)Rollback();
}

Status Transaction::Begin(Kind kind) {
  const std::string begin = kind == Kind::kRead ? "BEGIN ISOLATION LEVEL REPEATABLE READ READ ONLY" : "BEGIN";
  VB_RETURN_IF_ERROR(conn_->EnsureConnected());  // a lost connection (restarted server) is re-made here
  Status st = conn_->Script(begin);
  if (st.code() == StatusCode::kUnavailable && !conn_->timed_out()) {
    // The connection died between the check and BEGIN: nothing was done yet, so once more on a new one. Not
    // after a deadline: a server that does not answer would only be waited for twice.
    VB_RETURN_IF_ERROR(conn_->EnsureConnected());
    st = conn_->Script(begin);
  }
  VB_RETURN_IF_ERROR(st);
  open_ = true;
  conn_->set_in_transaction_block(true);
  return Status::Ok();
}

Status Transaction::Commit() {
  open_ = false;
  Status s = conn_->Script("COMMIT");
  conn_->set_in_transaction_block(false);
  return s;
}

Status Transaction::Rollback() {
  open_ = false;
  // On a lost connection there is nothing to roll back (the server rolled the transaction back).
  Status s = conn_->connected() ? conn_->Script("ROLLBACK") : Status::Ok();
  conn_->set_in_transaction_block(false);
  return s;
}

}  // namespace vb::db::pg
