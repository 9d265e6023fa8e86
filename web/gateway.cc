#include "web/gateway.h"

#include <fmt/format.h>
#include <google/protobuf/util/json_util.h>
#include <httplib.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/rand.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <mutex>
#include <nlohmann/json.hpp>
#include <set>
#include <vector>

#include <signal.h>
#include <unistd.h>

#include <cerrno>

#include "common/csv.h"
#include "common/failed_attempts.h"
#include "common/queue_estimate.h"
#include "experiment/compare.h"
#include "gap/dataset.h"
#include "gap/import_request.h"
#include "model/params.h"
#include "proto/api_convert.h"
#include "report/report.h"
#include "common/trace_columns.h"
#include "experiment/spec.h"
#include "model/effects.h"
#include "export/run_file.h"
#include "proto/trace_chunk.h"
#include "valvebench/v1/api.grpc.pb.h"
#include "web/assets.h"
#include "web/door.h"
#include "web/session_store.h"

namespace vb::web {

namespace v1 = valvebench::v1;
using Json = nlohmann::ordered_json;

int HttpStatusFor(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK: return 200;
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::OUT_OF_RANGE: return 400;
    case grpc::StatusCode::UNAUTHENTICATED: return 401;
    case grpc::StatusCode::PERMISSION_DENIED: return 403;
    case grpc::StatusCode::NOT_FOUND: return 404;
    case grpc::StatusCode::ALREADY_EXISTS:
    case grpc::StatusCode::FAILED_PRECONDITION:
    case grpc::StatusCode::ABORTED: return 409;
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return 429;
    case grpc::StatusCode::CANCELLED: return 499;
    case grpc::StatusCode::UNIMPLEMENTED: return 501;
    case grpc::StatusCode::UNAVAILABLE: return 503;
    case grpc::StatusCode::DEADLINE_EXCEEDED: return 504;
    default: return 500;
  }
}

namespace {

const char* CodeName(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK: return "OK";
    case grpc::StatusCode::CANCELLED: return "CANCELLED";
    case grpc::StatusCode::INVALID_ARGUMENT: return "INVALID_ARGUMENT";
    case grpc::StatusCode::DEADLINE_EXCEEDED: return "DEADLINE_EXCEEDED";
    case grpc::StatusCode::NOT_FOUND: return "NOT_FOUND";
    case grpc::StatusCode::ALREADY_EXISTS: return "ALREADY_EXISTS";
    case grpc::StatusCode::PERMISSION_DENIED: return "PERMISSION_DENIED";
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return "RESOURCE_EXHAUSTED";
    case grpc::StatusCode::FAILED_PRECONDITION: return "FAILED_PRECONDITION";
    case grpc::StatusCode::ABORTED: return "ABORTED";
    case grpc::StatusCode::OUT_OF_RANGE: return "OUT_OF_RANGE";
    case grpc::StatusCode::UNIMPLEMENTED: return "UNIMPLEMENTED";
    case grpc::StatusCode::INTERNAL: return "INTERNAL";
    case grpc::StatusCode::UNAVAILABLE: return "UNAVAILABLE";
    case grpc::StatusCode::DATA_LOSS: return "DATA_LOSS";
    case grpc::StatusCode::UNAUTHENTICATED: return "UNAUTHENTICATED";
    default: return "UNKNOWN";
  }
}

constexpr char kJson[] = "application/json";
constexpr char kCookie[] = "vb_session";
constexpr int kMaxJsonDepth = 64;  // a spec nests 4 deep; a deeper body is refused before any recursive walk

// Text for a JSON answer: invalid UTF-8 (in a message quoting the request) becomes U+FFFD instead of throwing.
std::string Dump(const Json& j) { return j.dump(-1, ' ', false, Json::error_handler_t::replace); }

void SendError(httplib::Response& res, grpc::StatusCode code, const std::string& message) {
  res.status = HttpStatusFor(code);
  res.set_content(Dump(Json{{"code", CodeName(code)}, {"message", message}}), kJson);
}
void SendErrorStatus(httplib::Response& res, int http_status, const char* code, const std::string& message) {
  res.status = http_status;
  res.set_content(Dump(Json{{"code", code}, {"message", message}}), kJson);
}
void SendError(httplib::Response& res, const grpc::Status& st) { SendError(res, st.error_code(), st.error_message()); }
void BadRequest(httplib::Response& res, const std::string& message) {
  SendError(res, grpc::StatusCode::INVALID_ARGUMENT, message);
}

// `with_zeros`: fields at their default (0, false, "") are written too; proto3 JSON leaves them out otherwise,
// and a live sample at t_s = 0 would arrive without its time (the page's charts need every field).
std::string ToJson(const google::protobuf::Message& m, bool with_zeros = false) {
  google::protobuf::util::JsonPrintOptions o;
  o.preserve_proto_field_names = true;  // the names specs are written with (supply_V, not supplyV)
  o.always_print_primitive_fields = with_zeros;
  std::string out;
  (void)google::protobuf::util::MessageToJsonString(m, &out, o);
  return out;
}

}  // namespace

bool ValidUtf8(std::string_view s) {
  size_t k = 0;
  const size_t n = s.size();
  while (k < n) {
    const auto c = static_cast<unsigned char>(s[k]);
    if (c < 0x80) {
      ++k;
      continue;
    }
    size_t len;
    std::uint32_t cp;
    if ((c & 0xE0) == 0xC0) {
      len = 2;
      cp = c & 0x1F;
    } else if ((c & 0xF0) == 0xE0) {
      len = 3;
      cp = c & 0x0F;
    } else if ((c & 0xF8) == 0xF0) {
      len = 4;
      cp = c & 0x07;
    } else {
      return false;
    }
    if (k + len > n) return false;
    for (size_t j = 1; j < len; ++j) {
      const auto d = static_cast<unsigned char>(s[k + j]);
      if ((d & 0xC0) != 0x80) return false;
      cp = (cp << 6) | (d & 0x3F);
    }
    // Overlong forms, UTF-16 surrogates and code points past U+10FFFF are not UTF-8.
    if ((len == 2 && cp < 0x80) || (len == 3 && cp < 0x800) || (len == 4 && cp < 0x10000) || cp > 0x10FFFF ||
        (cp >= 0xD800 && cp <= 0xDFFF))
      return false;
    k += len;
  }
  return true;
}

int JsonDepth(std::string_view s) {
  int depth = 0, max_depth = 0;
  bool in_string = false, escaped = false;
  for (const char c : s) {
    if (in_string) {
      if (escaped) {
        escaped = false;
      } else if (c == '\\') {
        escaped = true;
      } else if (c == '"') {
        in_string = false;
      }
      continue;
    }
    if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      max_depth = std::max(max_depth, ++depth);
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return max_depth;
}

std::string BearerTokenOf(std::string_view header, std::string* problem) {
  constexpr std::string_view kBearer = "Bearer ";
  if (header.substr(0, kBearer.size()) != kBearer) {
    *problem = "Authorization: must be 'Bearer <token>'";
    return "";
  }
  const std::string_view t = header.substr(kBearer.size());
  if (t.empty() || t.size() > 4096) {
    *problem = "Authorization: the bearer token must be 1-4096 characters";
    return "";
  }
  for (const char c : t) {
    if (c < 0x21 || c > 0x7e) {
      *problem = "Authorization: the bearer token must be visible ASCII characters (no space, tab, control or "
                 "non-ASCII byte)";
      return "";
    }
  }
  return std::string(t);
}

namespace {

// A token fit for a cookie and a metadata value: printable, no separators.
bool TokenShapeOk(const std::string& t) {
  if (t.empty() || t.size() > 512) return false;
  return std::all_of(t.begin(), t.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || std::strchr("-._~+/=", c) != nullptr;
  });
}

std::string CookieToken(const httplib::Request& req) {
  const std::string cookies = req.get_header_value("Cookie");
  const std::string key = std::string(kCookie) + "=";
  size_t pos = 0;
  while (pos < cookies.size()) {
    while (pos < cookies.size() && (cookies[pos] == ' ' || cookies[pos] == ';')) ++pos;
    const size_t end = std::min(cookies.find(';', pos), cookies.size());
    if (cookies.compare(pos, key.size(), key) == 0) return cookies.substr(pos + key.size(), end - pos - key.size());
    pos = end;
  }
  return "";
}

// The caller's "authorization" value for the RPC: the Authorization header as sent, else (GET only) the cookie.
// Nothing at all when neither is there: the service answers UNAUTHENTICATED, as it does for gRPC callers.
// The header was checked by the door (Routes::Admit: visible ASCII only, what gRPC metadata may carry); it is
// checked again here so that no other path can forward it unchecked.
void Authorize(const httplib::Request& req, grpc::ClientContext* ctx) {
  if (req.has_header("Authorization")) {
    std::string problem;
    const std::string token = BearerTokenOf(req.get_header_value("Authorization"), &problem);
    if (!token.empty()) ctx->AddMetadata("authorization", "Bearer " + token);
    return;
  }
  // A session cookie was turned into the header by Routes::Admit, on the routes it may authorise.
}

void Deadline(grpc::ClientContext* ctx, double seconds) {
  ctx->set_deadline(std::chrono::system_clock::now() +
                    std::chrono::milliseconds(static_cast<long long>(seconds * 1000.0)));
}

// Ends a server stream before its end (a bad chunk, a cap, a client gone): cancels the call, reads what is still
// in flight into `scratch` and finishes it, so that the reader can be destroyed.
template <class Reader, class Message>
void Abandon(grpc::ClientContext* ctx, Reader* reader, Message* scratch) {
  ctx->TryCancel();
  while (reader->Read(scratch)) {
  }
  (void)reader->Finish();
}

// A query parameter as a number; false (and a 400 naming it) when present but not a number.
bool NumberParam(const httplib::Request& req, httplib::Response& res, const char* name, double* out) {
  if (!req.has_param(name)) return true;
  const std::string v = req.get_param_value(name);
  try {
    size_t used = 0;
    const double d = std::stod(v, &used);
    if (used != v.size() || !std::isfinite(d)) throw std::invalid_argument(v);
    *out = d;
    return true;
  } catch (const std::exception&) {
    BadRequest(res, std::string(name) + ": not a number, got '" + v + "'");
    return false;
  }
}

bool IntParam(const httplib::Request& req, httplib::Response& res, const char* name, long long* out) {
  double d = static_cast<double>(*out);
  if (!NumberParam(req, res, name, &d)) return false;
  if (d != std::floor(d) || std::abs(d) > 9e15) {
    BadRequest(res, std::string(name) + ": not an integer, got '" + req.get_param_value(name) + "'");
    return false;
  }
  *out = static_cast<long long>(d);
  return true;
}

std::int64_t PathId(const httplib::Request& req) { return std::stoll(req.matches[1].str()); }

// A JSON body; false (and a 400) when it is not a JSON object.
bool BodyJson(const httplib::Request& req, httplib::Response& res, Json* out) {
  if (req.body.empty()) {
    *out = Json::object();
    return true;
  }
  if (!ValidUtf8(req.body)) {
    BadRequest(res, "body: not valid UTF-8");
    return false;
  }
  if (JsonDepth(req.body) > kMaxJsonDepth) {
    BadRequest(res, "body: JSON nested deeper than " + std::to_string(kMaxJsonDepth) + " levels");
    return false;
  }
  try {
    *out = Json::parse(req.body);
  } catch (const Json::exception& e) {
    BadRequest(res, std::string("body: not JSON: ") + e.what());
    return false;
  }
  if (!out->is_object()) {
    BadRequest(res, "body: must be a JSON object");
    return false;
  }
  return true;
}

std::string RunStatusText(v1::RunStatus s) { return v1::RunStatus_Name(s); }

void AppendNumber(std::string* out, double v) {
  if (std::isfinite(v)) {
    fmt::format_to(std::back_inserter(*out), "{:.10g}", v);
  } else {
    *out += "null";
  }
}

// The rows [t_s, ch0, ch1, ...] of a stored trace's samples with t in [t_from, t_to], at most max_points of
// them: GetTrace windows and min/max-decimates on the server (common/decimate.h: every channel's extremes of a
// bucket survive), and the one decoder (proto/trace_chunk.h) reads the chunks.
struct TraceRowsOut {
  std::vector<std::string> channels;  // the rows' columns after t_s
  double t0_s = 0.0, period_s = 0.0;
  std::int64_t total_samples = 0;
  bool decimated = false;
  std::string rows = "[";
};

grpc::Status ReadTraceRows(v1::BenchService::Stub* stub, const httplib::Request& req, std::int64_t run_id,
                           double t_from, double t_to, size_t max_points, TraceRowsOut* out) {
  grpc::ClientContext ctx;
  Authorize(req, &ctx);
  Deadline(&ctx, 120.0);
  v1::GetTraceRequest r;
  r.set_run_id(run_id);
  r.set_max_points(static_cast<std::int32_t>(max_points));
  // An open start: before any trace; an open end: to_s <= from_s (api.proto).
  r.set_from_s(std::isfinite(t_from) ? t_from : -1e300);
  r.set_to_s(std::isfinite(t_to) ? t_to : r.from_s());
  auto reader = stub->GetTrace(&ctx, r);
  vb::TraceDecoder decoder;
  v1::TraceChunk c;
  vb::Status bad;
  while (reader->Read(&c)) {
    if (bad = vb::api::DecodeChunk(c, &decoder); !bad.ok()) {
      Abandon(&ctx, reader.get(), &c);
      return grpc::Status(grpc::StatusCode::DATA_LOSS, bad.message());
    }
  }
  if (const grpc::Status st = reader->Finish(); !st.ok()) return st;
  const vb::TraceColumns& t = decoder.trace();
  out->t0_s = t.t0_s;
  out->period_s = t.sample_period_s;
  out->total_samples = t.total_samples;
  out->decimated = t.decimated;
  std::vector<const std::vector<double>*> cols;
  for (const auto& name : t.channels)
    if (name != "t_s") {  // t_s is the rows' first column, not a channel
      out->channels.push_back(name);
      cols.push_back(t.Find(name));
    }
  const std::size_t n = t.samples();
  out->rows.reserve(n * (cols.size() + 1) * 12);
  for (std::size_t k = 0; k < n; ++k) {
    out->rows += k == 0 ? "[" : ",[";
    AppendNumber(&out->rows, t.TimeAt(k));
    for (const auto* col : cols) {
      out->rows += ',';
      AppendNumber(&out->rows, (*col)[k]);
    }
    out->rows += ']';
  }
  out->rows += ']';
  return grpc::Status::OK;
}



}  // namespace

std::string CsvHeaderProblem(std::string_view text) {
  if (text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);  // UTF-8 BOM
  std::string_view header = text.substr(0, text.find('\n'));
  if (!header.empty() && header.back() == '\r') header.remove_suffix(1);
  std::set<std::string_view> names;
  size_t count = 0;
  for (size_t start = 0;;) {
    const size_t comma = header.find(',', start);
    const std::string_view name =
        header.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start);
    if (++count > kMaxCsvColumns)
      return fmt::format("more than {} columns in the header (a run has at most 5 known ones: t_s, gate, i_A, "
                         "x_m, v_coil_V)",
                         kMaxCsvColumns);
    if (!name.empty() && !names.insert(name).second)
      return "column " + std::string(name.substr(0, 40)) + (name.size() > 40 ? "..." : "") +
             " appears twice in the header";
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return "";
}

std::string ReportCsp(std::string_view html) {
  std::string hashes;
  constexpr std::string_view kOpen = "<script>", kClose = "</script>";
  for (size_t at = html.find(kOpen); at != std::string_view::npos; at = html.find(kOpen, at)) {
    const size_t begin = at + kOpen.size();
    const size_t end = html.find(kClose, begin);
    if (end == std::string_view::npos) break;
    unsigned char digest[EVP_MAX_MD_SIZE];
    unsigned int len = 0;
    EVP_Digest(html.data() + begin, end - begin, digest, &len, EVP_sha256(), nullptr);
    unsigned char b64[4 * ((EVP_MAX_MD_SIZE + 2) / 3) + 1];
    const int n = EVP_EncodeBlock(b64, digest, static_cast<int>(len));
    hashes += " 'sha256-" + std::string(reinterpret_cast<const char*>(b64), static_cast<size_t>(n)) + "'";
    at = end + kClose.size();
  }
  return "default-src 'none'; script-src" + (hashes.empty() ? std::string(" 'none'") : hashes) +
         "; style-src 'unsafe-inline'; img-src data:; frame-ancestors 'none'; base-uri 'none'; form-action 'none'";
}

std::string ImportTempPrefix() {
  std::error_code ec;
  std::filesystem::path dir = std::filesystem::temp_directory_path(ec);
  if (ec) dir = "/tmp";
  return (dir / ("valvebench-import-" + std::to_string(::getpid()) + "-")).string();
}

int RemoveStaleImports() {
  std::error_code ec;
  std::filesystem::path dir = std::filesystem::temp_directory_path(ec);
  if (ec) dir = "/tmp";
  int removed = 0;
  constexpr std::string_view kPrefix = "valvebench-import-";
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(kPrefix, 0) != 0) continue;
    const std::string rest = name.substr(kPrefix.size());
    const size_t dash = rest.find('-');
    bool stale = false;
    if (dash != std::string::npos && dash > 0 && rest.find_first_not_of("0123456789") == dash) {
      // valvebench-import-PID-XXXXXX: stale when that process is gone (another server's upload is left alone).
      const long pid = std::strtol(rest.c_str(), nullptr, 10);
      stale = pid > 0 && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH;
    } else {
      // The older name without a process id: stale after an hour (an import takes seconds).
      std::error_code tec;
      const auto t = std::filesystem::last_write_time(e.path(), tec);
      stale = !tec && std::filesystem::file_time_type::clock::now() - t > std::chrono::hours(1);
    }
    if (!stale) continue;
    std::error_code rec;
    if (std::filesystem::remove_all(e.path(), rec) > 0 && !rec) ++removed;
  }
  return removed;
}

namespace {

class Routes {
 public:
  Routes(std::shared_ptr<grpc::Channel> channel, const GatewayOptions& options, bool tls)
      : stub_(v1::BenchService::NewStub(channel)),
        sessions_(options.sessions_file),
        options_(options),
        tls_(tls),
        max_body_bytes_(options.limits.max_body_bytes) {}

  void Install(httplib::Server& s) {
    s.set_default_headers({{"X-Content-Type-Options", "nosniff"},
                           {"Referrer-Policy", "no-referrer"},
                           {"Content-Security-Policy",
                            "default-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data:; "
                            "frame-ancestors 'none'"}});
    if (tls_) {
      httplib::Headers h = {{"X-Content-Type-Options", "nosniff"},
                            {"Referrer-Policy", "no-referrer"},
                            {"Content-Security-Policy",
                             "default-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data:; "
                             "frame-ancestors 'none'"},
                            {"Strict-Transport-Security", "max-age=31536000"}};
      s.set_default_headers(h);
    }
    for (const Asset& a : Assets()) {
      s.Get(a.url_path, [&a](const httplib::Request&, httplib::Response& res) {
        res.set_header("Cache-Control", "no-cache");
        res.set_content(a.data, a.size, a.content_type);
      });
    }
    s.Post("/api/login", [this](const auto& q, auto& r) { Login(q, r); });
    s.Post("/api/logout", [this](const auto& q, auto& r) { Logout(q, r); });
    s.Get("/api/login", [this](const auto& q, auto& r) { SessionState(q, r); });
    s.set_post_routing_handler([this](const auto& q, auto& r) {
      try {
        AfterRoute(q, r);
      } catch (...) {
      }
    });
    s.Get("/api/session", [this](const auto& q, auto& r) { Session(q, r); });
    s.Get("/api/benches", [this](const auto& q, auto& r) { Benches(q, r); });
    s.Get("/api/queue", [this](const auto& q, auto& r) { Queue(q, r); });
    s.Get("/api/runs", [this](const auto& q, auto& r) { ListRuns(q, r); });
    s.Post("/api/runs", [this](const auto& q, auto& r) { Submit(q, r); });
    s.Get(R"(/api/runs/(\d{1,15}))", [this](const auto& q, auto& r) { GetRun(q, r); });
    s.Post(R"(/api/runs/(\d{1,15})/cancel)", [this](const auto& q, auto& r) { Cancel(q, r); });
    s.Post(R"(/api/runs/(\d{1,15})/rerun)", [this](const auto& q, auto& r) { Rerun(q, r); });
    s.Get(R"(/api/runs/(\d{1,15})/trace)", [this](const auto& q, auto& r) { TraceRows(q, r); });
    s.Get(R"(/api/runs/(\d{1,15})/trace\.csv)", [this](const auto& q, auto& r) { TraceCsv(q, r); });
    s.Get(R"(/api/runs/(\d{1,15})/events)", [this](const auto& q, auto& r) { Events(q, r); });
    s.Get("/api/compare", [this](const auto& q, auto& r) { Compare(q, r); });
    s.Get(R"(/api/runs/(\d{1,15})/trace\.(h5|mat))", [this](const auto& q, auto& r) { TraceFile(q, r); });
    s.Get(R"(/api/compare\.(csv|json))", [this](const auto& q, auto& r) { CompareFile(q, r); });
    s.Get(R"(/api/batches/(\d{1,15})/report\.html)", [this](const auto& q, auto& r) { BatchReport(q, r); });
    s.Post("/api/import", [this](const auto& q, auto& r) { Import(q, r); });
    s.Get("/api/diagnose", [this](const auto& q, auto& r) { Diagnose(q, r); });
    s.Get("/api/units", [this](const auto& q, auto& r) { Units(q, r); });
    s.Get("/api/nights", [this](const auto& q, auto& r) { Nights(q, r); });
    s.Get("/api/health", [this](const auto& q, auto& r) { Health(q, r); });
    s.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
      return Admit(req, res) ? httplib::Server::HandlerResponse::Unhandled : httplib::Server::HandlerResponse::Handled;
    });
    // Runs outside cpp-httplib's try block (when the answer is written): must not throw.
    s.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
      try {
        if (!res.body.empty() || res.content_provider_) return;
        DoorRequestState* door = CurrentDoorRequest();
        if (door && door->body_too_large) {
          res.status = 413;
          SendErrorStatus(res, 413, "RESOURCE_EXHAUSTED", "body: larger than the limit");
        } else if (door && door->body_timed_out) {
          SendErrorStatus(res, 408, "DEADLINE_EXCEEDED", "body: not received in time");
        } else if (res.status == 404) {
          SendError(res, grpc::StatusCode::NOT_FOUND, "no such page or API route: " + req.method + " " + req.path);
        } else if (res.status == 413) {
          SendErrorStatus(res, 413, "RESOURCE_EXHAUSTED", "body: larger than the limit");
        } else {
          SendErrorStatus(res, res.status, res.status >= 500 ? "INTERNAL" : "INVALID_ARGUMENT",
                          fmt::format("the request could not be read (HTTP {})", res.status));
        }
      } catch (...) {
        res.body = R"({"code":"INTERNAL","message":"internal error"})";
      }
    });
    s.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
      try {
        std::string what = "internal error";
        try {
          if (ep) std::rethrow_exception(ep);
        } catch (const std::exception& e) {
          what = std::string("internal error: ") + e.what();
        } catch (...) {
        }
        SendError(res, grpc::StatusCode::INTERNAL, what);
      } catch (...) {
        res.status = 500;
        res.body = R"({"code":"INTERNAL","message":"internal error"})";
      }
    });
  }

 private:
  // The door's checks of every request before its route runs (docs/web.md "Door"): true lets it through, false
  // has the answer (a 4xx JSON error) in `res`.
  bool Admit(const httplib::Request& req, httplib::Response& res) {
    DoorRequestState* door = CurrentDoorRequest();
    if (door) door->head_parsed = true;
    // The door keeps at most one range (web/head.h); a head that did not come through it (the fuzz target's
    // RawGateway) gets the same: cpp-httplib would build one copy of the answer per range.
    if (req.ranges.size() > 1) const_cast<httplib::Request&>(req).ranges.clear();
    auto refuse = [&](int status, const char* code, const std::string& message) {
      SendErrorStatus(res, status, code, message);
      res.set_header("Connection", "close");
      if (door) door->close_after = true;  // the body, if any, was not read
      return false;
    };
    if (!ValidUtf8(req.path)) return refuse(400, "INVALID_ARGUMENT", "path: not valid UTF-8");
    for (const char c : req.path)
      if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f)
        return refuse(400, "INVALID_ARGUMENT", "path: control character");
    for (const auto& [key, value] : req.params)
      if (!ValidUtf8(key) || !ValidUtf8(value))
        return refuse(400, "INVALID_ARGUMENT", "query parameter '" + key + "': not valid UTF-8");
    for (const auto& [name, value] : req.headers) {
      for (const char c : value)
        if ((static_cast<unsigned char>(c) < 0x20 && c != '\t') || c == 0x7f)
          return refuse(400, "INVALID_ARGUMENT", "header " + name + ": control character in its value");
      if (!ValidUtf8(value)) return refuse(400, "INVALID_ARGUMENT", "header " + name + ": not valid UTF-8");
    }
    if (req.headers.count("Authorization") > 1)
      return refuse(400, "INVALID_ARGUMENT", "Authorization: sent more than once");
    if (req.has_header("Authorization")) {
      std::string problem;
      if (BearerTokenOf(req.get_header_value("Authorization"), &problem).empty())
        return refuse(401, "UNAUTHENTICATED", problem);
      // The failed-login limit covers a bearer header on every route, not only /api/login (issue 34: any route
      // was an unlimited, unlogged oracle for guessing tokens): a token the server does not know counts as a
      // failed login of this address, and an address past the limit is refused whatever it sends.
      if (double wait_s = logins_.Blocked_s(req.remote_addr); wait_s > 0) {
        res.set_header("Retry-After", std::to_string(static_cast<int>(std::ceil(wait_s))));
        return refuse(429, "RESOURCE_EXHAUSTED",
                      fmt::format("too many failed logins from {}; try again in {:.0f} s", req.remote_addr,
                                  std::ceil(wait_s)));
      }
      if (options_.identify) {
        auto who = options_.identify(req.get_header_value("Authorization"));
        if (!who.ok()) {
          logins_.Failed(req.remote_addr);
          spdlog::warn("web: unknown bearer token from {} on {} {}", req.remote_addr.c_str(), req.method.c_str(),
                       req.path.substr(0, 200).c_str());
          return refuse(401, "UNAUTHENTICATED", "authorization: " + who.status().message());
        }
      }
    }
    const bool has_body_framing = req.has_header("Content-Length") || req.has_header("Transfer-Encoding");
    if (req.method == "POST" || req.method == "PUT" || req.method == "PATCH" || req.method == "DELETE" ||
        has_body_framing) {
      if (req.headers.count("Content-Length") > 1 || req.headers.count("Transfer-Encoding") > 1)
        return refuse(400, "INVALID_ARGUMENT", "Content-Length, Transfer-Encoding: sent more than once");
      if (req.has_header("Transfer-Encoding")) {
        if (req.get_header_value("Transfer-Encoding") != "chunked")
          return refuse(400, "INVALID_ARGUMENT", "Transfer-Encoding: only 'chunked' is accepted");
        if (req.has_header("Content-Length"))
          return refuse(400, "INVALID_ARGUMENT", "Content-Length: not with Transfer-Encoding: chunked");
      } else if (!req.has_header("Content-Length")) {
        return refuse(411, "INVALID_ARGUMENT", "Content-Length: required on a " + req.method + " (0 for no body)");
      } else {
        const std::string len = req.get_header_value("Content-Length");
        if (len.empty() || len.size() > 15 || len.find_first_not_of("0123456789") != std::string::npos)
          return refuse(400, "INVALID_ARGUMENT", "Content-Length: not a number");
        if (std::stoull(len) > max_body_bytes_)
          return refuse(413, "RESOURCE_EXHAUSTED",
                        fmt::format("body: {} bytes, more than the limit of {}", len, max_body_bytes_));
      }
      const std::string encoding = req.get_header_value("Content-Encoding");
      if (!encoding.empty() && encoding != "identity")
        return refuse(415, "INVALID_ARGUMENT", "Content-Encoding: compressed bodies are not accepted");
      if (req.is_multipart_form_data())
        return refuse(415, "INVALID_ARGUMENT", "Content-Type: multipart bodies are not accepted (send JSON)");
    }
    // Every POST but login and logout changes something and needs the operator role: the token and the role are
    // checked here, before cpp-httplib reads the body (up to 8 MiB) and a handler parses it (an import's CSV
    // files), so that a request without them costs a head and a SHA-256, not a body (issue 34). The service
    // checks again; this is the early refusal with the same answer.
    if (req.method == "POST" && req.path != "/api/login" && req.path != "/api/logout" && options_.identify) {
      if (!req.has_header("Authorization"))
        return refuse(401, "UNAUTHENTICATED", "authorization: missing bearer token (Authorization: Bearer <token>)");
      auto who = options_.identify(req.get_header_value("Authorization"));
      if (!who.ok()) return refuse(401, "UNAUTHENTICATED", "authorization: " + who.status().message());
      if (who->role == "viewer")
        return refuse(403, "PERMISSION_DENIED",
                      req.path + ": needs the operator role; " + who->user + " is a viewer");
    }
    // The session cookie authorises what the page cannot send a header with, and nothing else: the live view
    // (EventSource) and the CSV download (a link), both GET. Never from another origin's page (another port of
    // the same host is same-site, so SameSite=Strict alone lets it through).
    const std::string session = CookieToken(req);
    if (!req.has_header("Authorization") && !session.empty() && req.method == "GET" && CookieRoute(req.path)) {
      if (!SameOrigin(req))
        return refuse(403, "PERMISSION_DENIED", "cookie: not accepted from a page of another origin (" +
                                                     req.get_header_value("Origin") +
                                                     req.get_header_value("Sec-Fetch-Site") + ")");
      const std::string token = sessions_.TokenOf(session);
      // The request object is cpp-httplib's own (non-const); its handlers get it as const.
      if (!token.empty()) const_cast<httplib::Request&>(req).set_header("Authorization", "Bearer " + token);
    }
    return true;
  }

  static bool CookieRoute(const std::string& path) {
    static const std::regex re(
        R"(/api/runs/\d{1,15}/(events|trace\.(csv|h5|mat))|/api/compare\.(csv|json)|/api/batches/\d{1,15}/report\.html)");
    return std::regex_match(path, re);
  }

  // No Origin / Sec-Fetch-Site (not a browser, or a same-origin navigation over plain HTTP), or this dashboard's
  // own origin (scheme://Host), or one of GatewayOptions::allowed_origins.
  bool SameOrigin(const httplib::Request& req) const {
    if (req.has_header("Origin")) {
      const std::string o = req.get_header_value("Origin");
      if (o == std::string(tls_ ? "https://" : "http://") + req.get_header_value("Host")) return true;
      return std::find(options_.allowed_origins.begin(), options_.allowed_origins.end(), o) !=
             options_.allowed_origins.end();
    }
    if (req.has_header("Sec-Fetch-Site")) {
      const std::string site = req.get_header_value("Sec-Fetch-Site");
      return site == "same-origin" || site == "none";
    }
    return true;
  }

  // After each answer: API JSON is not cached; a session whose token the service no longer knows (removed from
  // the configuration) is revoked.
  void AfterRoute(const httplib::Request& req, httplib::Response& res) {
    if (req.path.rfind("/api/", 0) == 0 && !res.has_header("Cache-Control")) res.set_header("Cache-Control", "no-store");
    if (res.status == 401) {  // the service refused the session's token itself (not a route the cookie cannot open)
      const std::string session = CookieToken(req);
      const std::string token = session.empty() ? "" : sessions_.TokenOf(session);
      if (!token.empty() && req.get_header_value("Authorization") == "Bearer " + token) sessions_.Revoke(session);
    }
  }

  std::string CookieHeader(const std::string& session, int max_age_s) const {
    return fmt::format("{}={}; Path=/api; Max-Age={}; HttpOnly; SameSite=Strict{}", kCookie, session, max_age_s,
                       tls_ ? "; Secure" : "");
  }

  // Login: a JSON body only (a cross-site form can post text/plain, not application/json without a CORS
  // preflight this server never grants), from this dashboard's origin, at most FailedAttempts::kMax failures per
  // client address in FailedAttempts::kWindow_s (common/failed_attempts.h); each failure is logged. The cookie
  // holds a random session id, not the token: logout revokes it.
  void Login(const httplib::Request& req, httplib::Response& res) {
    if (req.get_header_value("Content-Type").rfind("application/json", 0) != 0)
      return SendErrorStatus(res, 415, "INVALID_ARGUMENT", "Content-Type: must be application/json");
    if (!SameOrigin(req))
      return SendErrorStatus(res, 403, "PERMISSION_DENIED",
                             "Origin: " + req.get_header_value("Origin") + " may not log in to this dashboard");
    if (double wait_s = logins_.Blocked_s(req.remote_addr); wait_s > 0) {
      res.set_header("Retry-After", std::to_string(static_cast<int>(std::ceil(wait_s))));
      return SendErrorStatus(res, 429, "RESOURCE_EXHAUSTED",
                             fmt::format("too many failed logins from {}; try again in {:.0f} s", req.remote_addr,
                                         std::ceil(wait_s)));
    }
    Json body;
    if (!BodyJson(req, res, &body)) return;
    if (!body.contains("token") || !body["token"].is_string())
      return BadRequest(res, "token: must be a string (the bearer token)");
    const std::string token = body["token"].get<std::string>();
    if (!TokenShapeOk(token)) return BadRequest(res, "token: must be 1-512 characters of A-Z a-z 0-9 - . _ ~ + / =");
    grpc::ClientContext ctx;
    ctx.AddMetadata("authorization", "Bearer " + token);
    Deadline(&ctx, 10.0);
    v1::ListBenchesResponse out;
    auto st = stub_->ListBenches(&ctx, v1::ListBenchesRequest(), &out);
    if (!st.ok()) {
      if (st.error_code() == grpc::StatusCode::UNAUTHENTICATED) {
        logins_.Failed(req.remote_addr);
        spdlog::warn("web: failed login from {} ({})", req.remote_addr.c_str(), st.error_message().c_str());
      }
      return SendError(res, st);
    }
    std::string user;
    if (options_.identify)
      if (auto who = options_.identify("Bearer " + token); who.ok()) user = who->user;
    res.set_header("Set-Cookie", CookieHeader(sessions_.Create(token, user), static_cast<int>(sessions_.life_s())));
    res.set_content("{}", kJson);
  }

  // Logout: this session; with {"everywhere": true} every session of its token (other browsers, other tabs'
  // logins), e.g. after a laptop was lost.
  void Logout(const httplib::Request& req, httplib::Response& res) {
    const std::string session = CookieToken(req);
    bool everywhere = false;
    if (!req.body.empty()) {
      Json body;
      if (!BodyJson(req, res, &body)) return;
      if (body.contains("everywhere")) {
        if (!body["everywhere"].is_boolean()) return BadRequest(res, "everywhere: must be true or false");
        everywhere = body["everywhere"].get<bool>();
      }
    }
    std::size_t ended = 0;
    if (!session.empty()) ended = everywhere ? sessions_.RevokeAllOf(session) : (sessions_.Revoke(session) ? 1 : 0);
    res.set_header("Set-Cookie", CookieHeader("", 0));
    res.set_content(Json{{"sessions_ended", ended}}.dump(), kJson);
  }

  // GET /api/login: whether this browser's session cookie stands for a token the service still knows, and whose.
  // The page asks after the server was away: sessions are kept over a restart (web/session_store.h), so it logs
  // in again only when the answer is no. Says nothing about any other session.
  void SessionState(const httplib::Request& req, httplib::Response& res) {
    const std::string session = CookieToken(req);
    const std::string token = session.empty() ? "" : sessions_.TokenOf(session);
    Json out{{"session", false}};
    if (!token.empty()) {
      if (!options_.identify) {
        out["session"] = true;
      } else if (auto who = options_.identify("Bearer " + token); who.ok()) {
        out = Json{{"session", true}, {"user", who->user}, {"role", who->role}};
      } else {
        sessions_.Revoke(session);  // its token was removed from the configuration
      }
    }
    res.set_content(out.dump(), kJson);
  }

  void Benches(const httplib::Request& req, httplib::Response& res) {
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 10.0);
    v1::ListBenchesResponse out;
    auto st = stub_->ListBenches(&ctx, v1::ListBenchesRequest(), &out);
    if (!st.ok()) return SendError(res, st);
    res.set_content(ToJson(out), kJson);
  }

  // Running and queued runs with their place in the queue and their ETA: the service's GetQueue (the view
  // `benchctl queue` shows too), in the JSON shape the page reads.
  void Queue(const httplib::Request& req, httplib::Response& res) {
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 10.0);
    v1::GetQueueResponse q;
    auto st = stub_->GetQueue(&ctx, v1::GetQueueRequest(), &q);
    if (!st.ok()) return SendError(res, st);
    std::string out = R"({"now_unix_s":)" + fmt::format("{:.3f}", q.at_unix_s()) + R"(,"live_benches":)" +
                      std::to_string(q.live_benches()) + R"(,"running":[)";
    for (int k = 0; k < q.running_size(); ++k) {
      const auto& x = q.running(k);
      // Appended piece by piece: GCC 12 -O3 reports a false -Wrestrict on a `"," + std::string` chain.
      if (k) out += ',';
      out.append(R"({"run":)").append(ToJson(x.run())).append(R"(,"eta_s":)");
      AppendNumber(&out, x.eta_s() < 0 ? NAN : x.eta_s());
      out += "}";
    }
    out += R"(],"queued":[)";
    for (int k = 0; k < q.queued_size(); ++k) {
      const auto& x = q.queued(k);
      if (k) out += ',';
      out += fmt::format(R"({{"position":{},"run":{},"eta_s":)", x.position(), ToJson(x.run()));
      AppendNumber(&out, x.eta_s() < 0 ? NAN : x.eta_s());
      out += "}";
    }
    out += "]}";
    res.set_content(out, kJson);
  }

  void ListRuns(const httplib::Request& req, httplib::Response& res) {
    v1::ListRunsRequest r;
    if (req.has_param("status")) {
      v1::RunStatus s;
      if (!v1::RunStatus_Parse(req.get_param_value("status"), &s))
        return BadRequest(res, "status: unknown run status '" + req.get_param_value("status") +
                                   "' (QUEUED, RUNNING, DONE, FAILED, CANCELLED, INTERRUPTED)");
      r.set_status(s);
    }
    long long batch = 0, page_size = 0;
    if (!IntParam(req, res, "batch_id", &batch) || !IntParam(req, res, "page_size", &page_size)) return;
    if (page_size < 0 || page_size > 1000) return BadRequest(res, "page_size: must be 0..1000");
    r.set_batch_id(batch);
    r.set_page_size(static_cast<int>(page_size));
    r.set_tag(req.get_param_value("tag"));
    r.set_bench(req.get_param_value("bench"));
    r.set_controller(req.get_param_value("controller"));
    r.set_page_token(req.get_param_value("page_token"));
    // The contract of api.proto's ListRunsRequest (AIP-132 order_by, a name filter): the service validates them
    // and names the field it refuses; the gateway only carries them.
    r.set_submitter(req.get_param_value("submitter"));
    r.set_name(req.get_param_value("name"));
    r.set_order_by(req.get_param_value("order_by"));
    double after_s = 0, before_s = 0;
    if (!NumberParam(req, res, "submitted_after_unix_s", &after_s) ||
        !NumberParam(req, res, "submitted_before_unix_s", &before_s))
      return;
    r.set_submitted_after_unix_s(after_s);
    r.set_submitted_before_unix_s(before_s);
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 20.0);
    v1::ListRunsResponse out;
    auto st = stub_->ListRuns(&ctx, r, &out);
    if (!st.ok()) return SendError(res, st);
    // Each law's headline metrics as its comparison shows them (experiment::RankMetricOf/EffortMetricOf: the
    // Compare page's effort axis, not a second choice made here): {controller: {rank, effort}}.
    Json headline = Json::object();
    for (const auto& run : out.runs()) {
      if (headline.contains(run.controller())) continue;
      auto view = [](const experiment::HeadlineMetric& m) {
        return Json{{"metric", m.metric}, {"label", m.label}, {"unit", m.unit}};
      };
      headline[run.controller()] = {{"rank", view(experiment::RankMetricOf(run.controller()))},
                                    {"effort", view(experiment::EffortMetricOf(run.controller()))}};
    }
    std::string body = ToJson(out);
    body.pop_back();  // the object's closing brace: the headline map goes beside the runs
    body += std::string(body.size() > 1 ? "," : "") + R"("headline":)" + Dump(headline) + "}";
    res.set_content(body, kJson);
  }

  // The body's spec goes through experiment::ParseSpecJson, the parser `benchctl run` uses, so a misspelt field
  // gets the same "unknown field; did you mean" error; the service then validates it as for any gRPC caller.
  void Submit(const httplib::Request& req, httplib::Response& res) {
    Json body;
    if (!BodyJson(req, res, &body)) return;
    for (const auto& [key, value] : body.items())
      if (key != "spec" && key != "batch_name")
        return BadRequest(res, key + ": unknown field (the body is {\"spec\": {...}, \"batch_name\": \"...\"})");
    if (!body.contains("spec") || !body["spec"].is_object()) return BadRequest(res, "spec: must be a JSON object");
    auto spec = experiment::ParseSpecJson(Dump(body["spec"]));
    if (!spec.ok()) return BadRequest(res, spec.status().message());
    v1::SubmitRunRequest r;
    *r.mutable_spec() = *spec;
    if (body.contains("batch_name")) {
      if (!body["batch_name"].is_string()) return BadRequest(res, "batch_name: must be a string");
      r.set_batch_name(body["batch_name"].get<std::string>());
    }
    SubmitAndReply(req, res, r);
  }

  void SubmitAndReply(const httplib::Request& req, httplib::Response& res, const v1::SubmitRunRequest& r) {
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 30.0);
    v1::SubmitRunResponse out;
    auto st = stub_->SubmitRun(&ctx, r, &out);
    if (!st.ok()) return SendError(res, st);
    res.status = 201;
    res.set_content(ToJson(out), kJson);
  }

  grpc::Status FetchRun(const httplib::Request& req, std::int64_t id, v1::Run* run) {
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 10.0);
    v1::GetRunRequest r;
    r.set_run_id(id);
    return stub_->GetRun(&ctx, r, run);
  }

  void GetRun(const httplib::Request& req, httplib::Response& res) {
    v1::Run run;
    auto st = FetchRun(req, PathId(req), &run);
    if (!st.ok()) return SendError(res, st);
    Json units = Json::object();
    std::vector<std::string> names;
    for (const auto& [name, value] : run.metrics()) names.push_back(name);
    std::sort(names.begin(), names.end());
    for (const auto& name : names) units[name] = exportfile::MetricUnit(name, run.controller());
    Json channel_units = Json::object();
    for (const char* ch : {"gate", "v_coil_V", "i_A", "x_m", "v_mps", "ref", "u"})
      channel_units[ch] = exportfile::ChannelUnit(ch, run.controller());
    res.set_content(R"({"run":)" + ToJson(run) + R"(,"metric_units":)" + Dump(units) + R"(,"channel_units":)" +
                        Dump(channel_units) + "}",
                    kJson);
  }

  void Cancel(const httplib::Request& req, httplib::Response& res) {
    Json body;
    if (!BodyJson(req, res, &body)) return;
    v1::CancelRunRequest r;
    r.set_run_id(PathId(req));
    if (body.contains("reason")) {
      if (!body["reason"].is_string()) return BadRequest(res, "reason: must be a string");
      r.set_reason(body["reason"].get<std::string>());
    }
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 30.0);
    v1::Run out;
    auto st = stub_->CancelRun(&ctx, r, &out);
    if (!st.ok()) return SendError(res, st);
    res.set_content(ToJson(out), kJson);
  }

  // Re-run: the run's exact single-run spec (stored verbatim with it) submitted again as a new batch.
  void Rerun(const httplib::Request& req, httplib::Response& res) {
    v1::Run run;
    const std::int64_t id = PathId(req);
    auto st = FetchRun(req, id, &run);
    if (!st.ok()) return SendError(res, st);
    // An imported run is a measurement (benchctl import): it has no spec a bench could run again.
    if (std::find(run.tags().begin(), run.tags().end(), "imported") != run.tags().end())
      return SendError(res, grpc::Status(grpc::StatusCode::FAILED_PRECONDITION,
                                         fmt::format("run {} is an imported measurement (benchctl import), not a bench run: "
                                                     "there is no spec to run again", id)));
    v1::SubmitRunRequest r;
    *r.mutable_spec() = run.spec();
    r.set_batch_name(fmt::format("rerun of run {}", id));
    SubmitAndReply(req, res, r);
  }

  void TraceRows(const httplib::Request& req, httplib::Response& res) {
    double t_from = -INFINITY, t_to = INFINITY, max_points = 4000;
    if (!NumberParam(req, res, "t_from_s", &t_from) || !NumberParam(req, res, "t_to_s", &t_to) ||
        !NumberParam(req, res, "max_points", &max_points))
      return;
    if (max_points < 10 || max_points > 200000) return BadRequest(res, "max_points: must be 10..200000");
    if (std::isfinite(t_from) && std::isfinite(t_to) && t_to < t_from)
      return BadRequest(res, "t_to_s: must not be before t_from_s");
    TraceRowsOut t;
    auto st = ReadTraceRows(stub_.get(), req, PathId(req), t_from, t_to, static_cast<size_t>(max_points), &t);
    if (!st.ok()) return SendError(res, st);
    Json head{{"channels", t.channels}, {"t0_s", t.t0_s}, {"sample_period_s", t.period_s},
              {"total_samples", t.total_samples}, {"decimated", t.decimated}};
    std::string out = Dump(head);
    out.pop_back();
    out += R"(,"rows":)" + t.rows + "}";
    res.set_content(out, kJson);
  }

  // The whole trace as CSV, streamed: GetTrace's chunks are read one at a time as the client takes the rows, so
  // memory stays at a chunk or two whatever the trace's size (docs/web.md "Limits"). The first chunk is read
  // before answering, so a refusal (token, role, no such run) is still a JSON error with its status; an error
  // later ends the download without its final chunk, which the browser reports as a failed download.
  void TraceCsv(const httplib::Request& req, httplib::Response& res) {
    const std::int64_t id = PathId(req);
    struct Download {
      grpc::ClientContext ctx;
      std::unique_ptr<grpc::ClientReader<v1::TraceChunk>> reader;
      v1::TraceChunk chunk;
      std::vector<std::string> channels;
      std::vector<size_t> value_channels;
      vb::TraceDecoder decoder;
      double t0_s = 0, period_s = 0;
      std::int64_t k = 0;  // the next sample's index
      bool header_sent = false, have_chunk = false, finished = false;
      grpc::Status Finish() {
        finished = true;
        return reader->Finish();
      }
      ~Download() {
        if (finished || !reader) return;
        Abandon(&ctx, reader.get(), &chunk);  // the client went away mid-download: end the RPC before its reader goes
      }
    };
    auto d = std::make_shared<Download>();
    Authorize(req, &d->ctx);
    Deadline(&d->ctx, 3600.0);
    v1::GetTraceRequest r;
    r.set_run_id(id);
    d->reader = stub_->GetTrace(&d->ctx, r);
    if (!d->reader->Read(&d->chunk)) return SendError(res, d->Finish());
    d->have_chunk = true;
    d->channels.assign(d->chunk.channels().begin(), d->chunk.channels().end());
    for (size_t ch = 0; ch < d->channels.size(); ++ch)
      if (d->channels[ch] != "t_s") d->value_channels.push_back(ch);
    d->t0_s = d->chunk.t0_s();
    d->period_s = d->chunk.sample_period_s();
    res.set_header("Content-Disposition", fmt::format("attachment; filename=\"run{}.csv\"", id));
    res.set_header("Cache-Control", "no-store");
    res.set_chunked_content_provider(
        "text/csv; charset=utf-8",
        [d](size_t, httplib::DataSink& sink) {
          try {
            std::string out;
            if (!d->header_sent) {
              out = "t_s";
              for (size_t ch : d->value_channels) out += "," + d->channels[ch];
              out += "\n";
              d->header_sent = true;
            }
            if (!d->have_chunk) {
              if (!d->reader->Read(&d->chunk)) {
                const grpc::Status st = d->Finish();
                if (!st.ok()) return false;  // cut short: no final chunk
                if (!out.empty() && !sink.write(out.data(), out.size())) return false;
                sink.done();
                return true;
              }
            }
            d->have_chunk = false;
            if (!vb::api::DecodeChunk(d->chunk, &d->decoder).ok()) {
              d->ctx.TryCancel();
              return false;
            }
            const vb::TraceColumns& t = d->decoder.trace();
            const size_t n = t.samples();
            std::vector<const std::vector<double>*> cols;
            for (size_t ch : d->value_channels) cols.push_back(t.Find(d->channels[ch]));
            out.reserve(out.size() + n * (cols.size() + 1) * 14);
            for (size_t i = 0; i < n; ++i) {
              AppendCsvNumber(&out, d->t0_s + static_cast<double>(d->k + static_cast<std::int64_t>(i)) * d->period_s);
              for (const auto* col : cols) {
                out += ',';
                AppendCsvNumber(&out, (*col)[i]);  // NaN: an empty field, as benchctl writes it (common/csv.h)
              }
              out += '\n';
            }
            d->decoder.DropRows();  // memory: one chunk, whatever the trace's length
            d->k += static_cast<std::int64_t>(n);
            if (!sink.write(out.data(), out.size())) {
              d->ctx.TryCancel();
              return false;
            }
            return true;
          } catch (...) {
            d->ctx.TryCancel();
            return false;
          }
        },
        [](bool) {});
  }

  // WatchRun re-emitted as Server-Sent Events: "event: run" with each RunEvent (protobuf JSON), then
  // "event: end" with the final status once the run has ended, or "event: error" with {code, message}. A stream
  // lasts at most watch_window_s; the browser's EventSource then reconnects by itself (docs/web.md "SSE").
  void Events(const httplib::Request& req, httplib::Response& res) {
    double rate_Hz = 200.0;
    if (!NumberParam(req, res, "rate_Hz", &rate_Hz)) return;
    if (rate_Hz < 0.0 || rate_Hz > 1000.0) return BadRequest(res, "rate_Hz: must be 0..1000");
    // An interactive run is cancelled when its submitter's watch goes away (docs/server.md); a page's stream ends
    // with every navigation and every watch window, so the page does not watch those: benchctl does.
    v1::Run run;
    if (auto st = FetchRun(req, PathId(req), &run); !st.ok() || run.spec().interactive()) {
      const std::string data =
          st.ok() ? Dump(Json{{"code", "FAILED_PRECONDITION"},
                         {"message", "run " + std::to_string(run.id()) +
                                         " is interactive: follow it with benchctl watch (a watch from this page "
                                         "would cancel it when the page goes away)"}})
                  : Dump(Json{{"code", CodeName(st.error_code())}, {"message", st.error_message()}});
      res.set_header("Cache-Control", "no-cache");
      res.set_content("event: error\ndata: " + data + "\n\n", "text/event-stream");
      return;
    }
    std::string why;
    auto slot = TakeStream(SessionKey(req), &why);
    if (!slot) {
      SendErrorStatus(res, 429, "RESOURCE_EXHAUSTED", why);
      res.set_header("Retry-After", "5");
      if (DoorRequestState* door = CurrentDoorRequest()) door->close_after = true;  // its connection goes too
      res.set_header("Connection", "close");
      return;
    }
    // Capped per session and in all (below the workers): not against its address's share of the workers, so
    // one address's tabs can follow as many runs as their sessions may.
    if (DoorRequestState* door = CurrentDoorRequest(); door && door->release_share) door->release_share();
    struct Watch {
      grpc::ClientContext ctx;
      std::unique_ptr<grpc::ClientReader<v1::RunEvent>> reader;
      std::shared_ptr<void> slot;  // the live view's place, held until the stream is gone
    };
    auto w = std::make_shared<Watch>();
    w->slot = std::move(slot);
    Authorize(req, &w->ctx);
    Deadline(&w->ctx, options_.watch_window_s);
    v1::WatchRunRequest r;
    r.set_run_id(PathId(req));
    r.set_sample_rate_hz(rate_Hz);
    w->reader = stub_->WatchRun(&w->ctx, r);
    res.set_header("Cache-Control", "no-cache");
    res.set_header("X-Accel-Buffering", "no");
    res.set_chunked_content_provider(
        "text/event-stream",
        [w](size_t, httplib::DataSink& sink) {
          auto send = [&](const std::string& event, const std::string& data) {
            const std::string msg = "event: " + event + "\ndata: " + data + "\n\n";
            return sink.write(msg.data(), msg.size());
          };
          if (!send("open", "{}") || !sink.write("retry: 500\n\n", 12)) {
            w->ctx.TryCancel();
            return false;
          }
          v1::RunEvent ev;
          std::string last_status;
          bool ended = false;
          while (w->reader->Read(&ev)) {
            last_status = RunStatusText(ev.status());
            ended = ev.status() != v1::QUEUED && ev.status() != v1::RUNNING;
            if (!send("run", ToJson(ev, /*with_zeros=*/true))) {  // the page went away
              w->ctx.TryCancel();
              (void)w->reader->Finish();
              return false;
            }
          }
          const grpc::Status st = w->reader->Finish();
          if (!st.ok() && st.error_code() != grpc::StatusCode::DEADLINE_EXCEEDED) {
            send("error", Dump(Json{{"code", CodeName(st.error_code())}, {"message", st.error_message()}}));
          } else if (ended) {
            send("end", Dump(Json{{"status", last_status}}));
          }
          sink.done();
          return true;
        },
        [w](bool) { w->ctx.TryCancel(); });
  }

  // "runs=1,2,3" into `ids`; false (the answer sent) when it is not a list of run ids.
  static bool RunIdsParam(const httplib::Request& req, httplib::Response& res,
                          google::protobuf::RepeatedField<std::int64_t>* ids) {
    if (!req.has_param("runs")) return true;
    const std::string list = req.get_param_value("runs");
    size_t pos = 0;
    while (pos <= list.size()) {
      const size_t end = std::min(list.find(',', pos), list.size());
      const std::string item = list.substr(pos, end - pos);
      if (item.empty() || item.size() > 15 || item.find_first_not_of("0123456789") != std::string::npos) {
        BadRequest(res, "runs: must be run ids separated by commas, got '" + list + "'");
        return false;
      }
      ids->Add(std::stoll(item));
      pos = end + 1;
    }
    return true;
  }

  // The gap diagnosis of stored runs: DiagnoseRuns, run by the server (seconds to a minute).
  void Diagnose(const httplib::Request& req, httplib::Response& res) {
    v1::DiagnoseRunsRequest r;
    if (!RunIdsParam(req, res, r.mutable_run_ids())) return;
    if (req.has_param("model")) r.set_model(req.get_param_value("model"));
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 300.0);
    v1::DiagnoseRunsResponse out;
    auto st = stub_->DiagnoseRuns(&ctx, r, &out);
    if (!st.ok()) return SendError(res, st);
    Json j = {{"report", out.report()}};
    j["diagnosis"] = Json::parse(out.report_json(), nullptr, false);
    // The nominal model with the diagnosed effect(s), as `benchctl diagnose --model-out` writes it ("" = none).
    j["improved_model_json"] = out.improved_model_json();
    j["param_units"] = DiagnosisParamUnits(j["diagnosis"]);
    res.set_content(Dump(j), kJson);
  }

  // The unit of every fitted parameter a diagnosis names, from the model's own tables (model::ParamUnit: a plant
  // parameter, an effect's, a fit's "X_excess"). Unknown ones are left out.
  static Json DiagnosisParamUnits(const Json& d) {
    Json units = Json::object();
    auto add = [&](const Json& params) {
      if (!params.is_object()) return;
      for (const auto& [name, value] : params.items()) {
        (void)value;
        if (const std::string unit = model::ParamUnit(name); !unit.empty()) units[name] = unit;
      }
    };
    if (!d.is_object()) return units;
    for (const char* list : {"ranking", "detection_limits"})
      if (d.contains(list) && d[list].is_array())
        for (const auto& row : d[list])
          if (row.contains("params")) add(row["params"]);
    if (d.contains("parametric") && d["parametric"].contains("params")) add(d["parametric"]["params"]);
    return units;
  }

  // CompareRuns on the query's batch (?batch_id=) or runs (?runs=): false when an error was answered.
  bool FetchComparison(const httplib::Request& req, httplib::Response& res, v1::CompareRunsResponse* out,
                       long long* batch) {
    v1::CompareRunsRequest r;
    if (!IntParam(req, res, "batch_id", batch)) return false;
    r.set_batch_id(*batch);
    if (!RunIdsParam(req, res, r.mutable_run_ids())) return false;
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 30.0);
    if (auto st = stub_->CompareRuns(&ctx, r, out); !st.ok()) {
      SendError(res, st);
      return false;
    }
    return true;
  }

  void Compare(const httplib::Request& req, httplib::Response& res) {
    long long batch = 0;
    v1::CompareRunsResponse out;
    if (!FetchComparison(req, res, &out, &batch)) return;
    // The unit of each column; rows of different laws may disagree (rmse is A for a current law, m for a
    // position law): then every unit seen, joined with " or ".
    Json units = Json::object();
    std::vector<std::string> cols(out.columns().begin(), out.columns().end());
    cols.push_back(out.rank_metric());
    cols.push_back(out.effort_metric());
    for (const auto& col : cols) {
      std::set<std::string> seen;
      for (const auto& row : out.rows()) seen.insert(exportfile::MetricUnit(col, row.controller()));
      std::string u;
      for (const auto& s : seen) u += (u.empty() ? "" : " or ") + s;
      units[col] = u;
    }
    // Zeros written (a metric at exactly 0 is a value, a missing one is absent from the row's map).
    res.set_content(R"({"comparison":)" + ToJson(out, /*with_zeros=*/true) + R"(,"units":)" + Dump(units) +
                        R"(,"display":)" + Dump(CompareDisplay(out)) + "}",
                    kJson);
  }

  // How the CLI's table shows each column (experiment::MetricColumnDisplay: one formatter for the CLI, the
  // report and this page): {columns: {metric: {label, unit, header, scale, decimals, spread_decimals}},
  // default_columns, sweep_axes: [{field, ...display}], keys: [RunKey per row], laws: {controller: name}}.
  static Json DisplayJson(const experiment::ColumnDisplay& d) {
    return Json{{"label", d.label}, {"unit", d.unit}, {"header", d.header}, {"scale", d.scale},
                {"decimals", d.decimals}, {"spread_decimals", d.spread_decimals}};
  }
  static Json CompareDisplay(const v1::CompareRunsResponse& out) {
    // The rows' identity is the server's RunKey (CompareRow.key), never read back from the name.
    const experiment::Comparison c = experiment::ComparisonFromProto(out);
    Json keys = Json::array(), laws = Json::object();
    std::vector<std::string> axes;
    std::map<std::string, std::vector<double>> axis_values;
    for (const auto& row : c.rows) {
      laws[row.controller] = experiment::LawName(row.controller);
      Json sweep = Json::array();
      for (const auto& sc : row.key.sweep) {
        sweep.push_back({{"field", sc.field}, {"value", sc.value}});
        if (std::find(axes.begin(), axes.end(), sc.field) == axes.end()) axes.push_back(sc.field);
      }
      keys.push_back({{"name", row.key.name}, {"sweep", sweep}});
    }
    for (size_t i = 0; i < keys.size(); ++i)
      for (const auto& a : axes) {
        double v = NAN;
        for (const auto& sc : keys[i]["sweep"]) if (sc["field"] == a) v = sc["value"].get<double>();
        axis_values[a].push_back(v);
      }
    Json cols = Json::object();
    std::vector<std::string> all = c.columns;
    all.push_back(c.rank_metric);
    all.push_back(c.effort_metric);
    for (const auto& col : all) cols[col] = DisplayJson(experiment::MetricColumnDisplay(c, col));
    Json sweep_axes = Json::array();
    for (const auto& a : axes) {
      Json d = DisplayJson(experiment::SweepColumnDisplay(a, axis_values[a]));
      d["field"] = a;
      sweep_axes.push_back(d);
    }
    return Json{{"columns", cols}, {"default_columns", experiment::DefaultMetricColumns(c)},
                {"sweep_axes", sweep_axes}, {"keys", keys}, {"laws", laws}};
  }

  // The SI prefixes the CLI's columns choose from (experiment::SiPrefixes), for the page's chart axes.
  void Units(const httplib::Request&, httplib::Response& res) {
    Json p = Json::array();
    for (const auto& x : experiment::SiPrefixes()) p.push_back({{"symbol", x.symbol}, {"scale", x.scale}});
    res.set_content(Dump(Json{{"prefixes", p}}), kJson);
  }

  // The trace as HDF5 or MATLAB .mat, the files `benchctl export --hdf5/--mat` writes (export/run_file.h, the
  // same writers). Both formats are written whole by their libraries, so the run's samples are held in memory
  // while the file is written (to a temporary file, unlinked at once) and the file is then streamed from disk
  // in 64 KiB pieces; a trace above kMaxFileTraceBytes is refused (413) with the CLI to use instead.
  static constexpr std::size_t kMaxFileTraceBytes = std::size_t{256} << 20;
  void TraceFile(const httplib::Request& req, httplib::Response& res) {
    const std::int64_t id = PathId(req);
    const std::string format = req.matches[2].str();
    v1::Run run;
    if (auto st = FetchRun(req, id, &run); !st.ok()) return SendError(res, st);
    // An HDF5 or MAT file is built whole in memory (up to kMaxFileTraceBytes of trace, and the file): at most
    // kMaxExportsPerSession per token and kMaxExports at once (issue 34: eight at once took +3.6 GB).
    std::string busy;
    const auto slot = TakeExport(SessionKey(req), &busy);
    if (!slot) {
      res.set_header("Retry-After", "5");
      return SendErrorStatus(res, 429, "RESOURCE_EXHAUSTED", busy);
    }
    exportfile::RunFile f;
    f.run_id = run.id();
    f.name = run.name();
    f.controller = run.controller();
    f.bench = run.bench();
    f.status = RunStatusText(run.status());
    f.reason = run.reason();
    google::protobuf::util::JsonPrintOptions opts;
    opts.preserve_proto_field_names = true;
    (void)google::protobuf::util::MessageToJsonString(run.spec(), &f.spec_json, opts);
    f.conditions = {{"supply_V", run.spec().conditions().supply_v(), "V"},
                    {"supply_pressure_Pa", run.spec().conditions().supply_pressure_pa(), "Pa"}};
    std::map<std::string, double> metrics(run.metrics().begin(), run.metrics().end());  // sorted: a stable file
    for (const auto& [name, value] : metrics)
      if (std::isfinite(value)) f.metrics.push_back({name, value, exportfile::MetricUnit(name, f.controller)});
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 600.0);
    v1::GetTraceRequest r;
    r.set_run_id(id);
    auto reader = stub_->GetTrace(&ctx, r);
    v1::TraceChunk chunk;
    vb::TraceDecoder decoder;  // the one decoder (proto/trace_chunk.h), as for the charts and the CSV
    std::size_t bytes = 0;
    while (reader->Read(&chunk)) {
      if (auto bad = vb::api::DecodeChunk(chunk, &decoder); !bad.ok()) {
        Abandon(&ctx, reader.get(), &chunk);
        return SendError(res, grpc::StatusCode::DATA_LOSS, fmt::format("run {}: {}", id, bad.message()));
      }
      bytes += chunk.data().size() + static_cast<std::size_t>(std::max(0, chunk.samples())) * 8;  // + the times
      if (bytes > kMaxFileTraceBytes) {
        Abandon(&ctx, reader.get(), &chunk);
        return SendErrorStatus(res, 413, "RESOURCE_EXHAUSTED",
                               fmt::format("run {}: the trace is larger than {} MiB, too large for a {} file from the "
                                           "page; use benchctl export {} --{} FILE",
                                           id, kMaxFileTraceBytes >> 20, format, id, format == "h5" ? "hdf5" : "mat"));
      }
    }
    if (auto st = reader->Finish(); !st.ok()) return SendError(res, st);
    vb::TraceColumns trace = decoder.Take();
    f.t0_s = trace.t0_s;
    f.sample_period_s = trace.sample_period_s;
    {
      std::vector<double> t(trace.samples());
      for (std::size_t i = 0; i < t.size(); ++i) t[i] = trace.TimeAt(i);
      f.channels.push_back({"t_s", exportfile::ChannelUnit("t_s", f.controller), std::move(t)});
    }
    for (const auto& name : trace.channels)
      if (name != "t_s")
        f.channels.push_back({name, exportfile::ChannelUnit(name, f.controller), std::move(trace.columns[name])});
    char path[] = "/tmp/valvebench-web-XXXXXX";
    const int fd = mkstemp(path);
    if (fd < 0) return SendError(res, grpc::StatusCode::UNAVAILABLE, "export: cannot create a temporary file");
    ::close(fd);
    const Status written = format == "h5" ? exportfile::WriteHdf5(f, path) : exportfile::WriteMat(f, path);
    std::FILE* file = written.ok() ? std::fopen(path, "rb") : nullptr;
    std::remove(path);  // the open file stays readable; nothing is left behind
    if (!written.ok()) return SendError(res, grpc::StatusCode::INTERNAL, written.message());
    if (file == nullptr) return SendError(res, grpc::StatusCode::UNAVAILABLE, "export: cannot read the written file");
    auto handle = std::shared_ptr<std::FILE>(file, &std::fclose);
    f = {};  // the samples are in the file now
    res.set_header("Content-Disposition", fmt::format("attachment; filename=\"run{}.{}\"", id, format));
    res.set_chunked_content_provider(
        format == "h5" ? "application/x-hdf5" : "application/x-matlab-data",
        [handle](size_t, httplib::DataSink& sink) {
          char buf[64 * 1024];
          const size_t got = std::fread(buf, 1, sizeof buf, handle.get());
          if (got > 0 && !sink.write(buf, got)) return false;
          if (got < sizeof buf) {
            if (std::ferror(handle.get())) return false;
            sink.done();
          }
          return true;
        },
        [](bool) {});
  }

  // The comparison as the files `benchctl compare --csv/--json` prints (experiment::ComparisonCsv/Json): a
  // missing metric is an empty CSV field and a JSON null (docs/cli.md "Missing values").
  void CompareFile(const httplib::Request& req, httplib::Response& res) {
    const std::string format = req.matches[1].str();
    long long batch = 0;
    v1::CompareRunsResponse out;
    if (!FetchComparison(req, res, &out, &batch)) return;
    const experiment::Comparison c = experiment::ComparisonFromProto(out);
    const std::string name = batch != 0 ? fmt::format("batch{}-comparison", batch) : "comparison";
    res.set_header("Content-Disposition", fmt::format("attachment; filename=\"{}.{}\"", name, format));
    if (format == "csv")
      res.set_content(experiment::ComparisonCsv(c), "text/csv; charset=utf-8");
    else
      res.set_content(experiment::ComparisonJson(c), kJson);
  }

  // A batch's HTML report, the page `benchctl report --batch N --html FILE` writes (report::BatchSections and
  // RenderHtml, the same code): comparison, Pareto scatter, static map, overlays and the runs' traces. The traces
  // are read whole (the report decimates them itself) up to kMaxReportTraceBytes in all; the runs beyond that
  // are in the tables without their trace, and the page says how many.
  static constexpr std::size_t kMaxReportTraceBytes = std::size_t{256} << 20;
  static constexpr int kMaxReportTraces = 100;  // benchctl report's --max-traces default
  void BatchReport(const httplib::Request& req, httplib::Response& res) {
    const std::int64_t batch = PathId(req);
    std::vector<v1::Run> listed;
    v1::ListRunsRequest lr;
    lr.set_batch_id(batch);
    lr.set_page_size(1000);
    lr.set_order_by("id");
    do {
      grpc::ClientContext ctx;
      Authorize(req, &ctx);
      Deadline(&ctx, 20.0);
      v1::ListRunsResponse out;
      if (auto st = stub_->ListRuns(&ctx, lr, &out); !st.ok()) return SendError(res, st);
      for (auto& r : *out.mutable_runs()) listed.push_back(std::move(r));
      lr.set_page_token(out.next_page_token());
    } while (!lr.page_token().empty() && listed.size() < 20000);
    if (listed.empty()) return SendError(res, grpc::StatusCode::NOT_FOUND, fmt::format("batch {}: no runs", batch));
    std::sort(listed.begin(), listed.end(), [](const v1::Run& a, const v1::Run& b) { return a.id() < b.id(); });
    std::vector<report::RunInfo> runs;
    std::size_t bytes = 0;
    int traced = 0, left_out = 0;
    for (const v1::Run& listed_run : listed) {
      v1::Run run;
      if (auto st = FetchRun(req, listed_run.id(), &run); !st.ok()) return SendError(res, st);
      report::RunInfo info{run.id(), api::FromProto(run.key()), run.controller(),
                           api::FromProto(run.status()).value_or(RunStatus::kQueued),
                           std::map<std::string, double>(run.metrics().begin(), run.metrics().end()),
                           run.has_spec() ? ToJson(run.spec()) : std::string(), run.submitted_unix_s(),
                           run.started_unix_s(), run.finished_unix_s(), {}};
      const bool ended = run.status() != v1::QUEUED && run.status() != v1::RUNNING;
      if (ended && traced < kMaxReportTraces && bytes < kMaxReportTraceBytes) {
        report::TraceData t;
        t.label = fmt::format("run {}: {}", run.id(), run.name());
        grpc::ClientContext ctx;
        Authorize(req, &ctx);
        Deadline(&ctx, 120.0);
        v1::GetTraceRequest tr;
        tr.set_run_id(run.id());
        auto reader = stub_->GetTrace(&ctx, tr);
        v1::TraceChunk chunk;
        vb::TraceDecoder decoder;  // the one decoder (proto/trace_chunk.h)
        bool too_big = false, bad = false;
        while (reader->Read(&chunk)) {
          bytes += chunk.data().size();
          too_big = bytes > kMaxReportTraceBytes;
          bad = !too_big && !vb::api::DecodeChunk(chunk, &decoder).ok();
          if (too_big || bad) break;
        }
        grpc::Status st;
        if (too_big || bad) {
          Abandon(&ctx, reader.get(), &chunk);
        } else {
          vb::TraceColumns cols = decoder.Take();
          t.t0_s = cols.t0_s;
          t.sample_period_s = cols.sample_period_s;
          t.channels = std::move(cols.columns);
          st = reader->Finish();
        }
        if (bad) return SendError(res, grpc::StatusCode::DATA_LOSS, fmt::format("run {}: its trace's chunks do not decode", run.id()));
        if (!too_big && st.ok() && !t.channels.empty()) {
          info.trace = std::move(t);
          ++traced;
        } else if (too_big) {
          ++left_out;
        } else if (!st.ok() && st.error_code() != grpc::StatusCode::NOT_FOUND) {
          return SendError(res, st);
        }
      } else if (ended) {
        ++left_out;
      }
      runs.push_back(std::move(info));
    }
    std::string where = "web dashboard (" + req.get_header_value("Host") + ")";
    if (left_out > 0) where += fmt::format("; traces of {} runs left out (size): benchctl report --batch {}", left_out, batch);
    const std::string title =
        fmt::format("Batch {}: {}", batch, runs.front().key.name.substr(0, runs.front().key.name.find('/')));
    const std::string html = report::RenderHtml(title, report::BatchSections(where, batch, runs));
    // The report draws its charts with inline scripts (it is one self-contained file): the dashboard's CSP
    // would block them; this answer's CSP allows exactly those scripts, by their hashes.
    res.headers.erase("Content-Security-Policy");
    res.set_header("Content-Security-Policy", ReportCsp(html));
    res.set_header("Content-Disposition", fmt::format("inline; filename=\"batch{}-report.html\"", batch));
    res.set_content(html, "text/html; charset=utf-8");
  }

  // A measured dataset uploaded from the page: {"dataset": NAME, "files": {"manifest.json": TEXT, "a.csv": TEXT,
  // ...}} (within the 8 MiB body limit). The files are written to a temporary directory named after the dataset
  // and read by gap::LoadDataset, the reader of `benchctl import DIR`, so a bad file gets the same error naming
  // the file, the line and the field; the runs then go to the service's ImportRuns (operator role) as
  // benchctl sends them (gap::FillImportRequest). The directory is removed before the answer.
  void Import(const httplib::Request& req, httplib::Response& res) {
    Json body;
    if (!BodyJson(req, res, &body)) return;
    if (!body.is_object()) return BadRequest(res, "body: must be a JSON object {\"dataset\", \"files\"}");
    for (const auto& [key, value] : body.items())
      if (key != "dataset" && key != "files")
        return BadRequest(res, key + ": unknown field (the body is {\"dataset\": \"...\", \"files\": {...}})");
    static const std::regex name_re(R"([A-Za-z0-9][A-Za-z0-9._-]{0,99})");
    if (!body.contains("dataset") || !body["dataset"].is_string())
      return BadRequest(res, "dataset: must be a string (the dataset's name)");
    const std::string dataset = body["dataset"].get<std::string>();
    if (!std::regex_match(dataset, name_re))
      return BadRequest(res, "dataset: '" + dataset + "' must be 1-100 characters of A-Z a-z 0-9 . _ - (not starting with . _ -)");
    if (!body.contains("files") || !body["files"].is_object() || body["files"].empty())
      return BadRequest(res, "files: must be an object of file name -> text (manifest.json and its CSV files)");
    if (body["files"].size() > 2000) return BadRequest(res, "files: more than 2000 files");
    for (const auto& [fname, text] : body["files"].items()) {
      if (!std::regex_match(fname, name_re))
        return BadRequest(res, "files['" + fname + "']: a file name of A-Z a-z 0-9 . _ - (no directories)");
      if (!text.is_string()) return BadRequest(res, "files['" + fname + "']: must be the file's text");
    }
    if (!body["files"].contains("manifest.json"))
      return BadRequest(res, "files: no manifest.json (pick the dataset's manifest.json and its files)");
    // Each data file's header row, in time linear in its length, before a byte is written (issue 34: the
    // dataset reader's duplicate check is a search per column, 150k columns took 45 s).
    for (const auto& [fname, text] : body["files"].items()) {
      if (fname.size() >= 5 && fname.compare(fname.size() - 5, 5, ".json") == 0) continue;
      const std::string why = CsvHeaderProblem(text.get_ref<const std::string&>());
      if (!why.empty()) return BadRequest(res, dataset + "/" + fname + ":1: " + why);
    }
    std::string tmpl_text = ImportTempPrefix() + "XXXXXX";
    std::vector<char> tmpl(tmpl_text.begin(), tmpl_text.end());
    tmpl.push_back('\0');
    if (mkdtemp(tmpl.data()) == nullptr)
      return SendError(res, grpc::StatusCode::UNAVAILABLE, "import: cannot create a temporary directory");
    struct Cleanup {
      std::string dir;
      ~Cleanup() {
        std::error_code ec;
        std::filesystem::remove_all(dir, ec);
      }
    } cleanup{tmpl.data()};
    const std::string dir = std::string(tmpl.data()) + "/" + dataset;
    std::error_code ec;
    std::filesystem::create_directory(dir, ec);
    for (const auto& [fname, text] : body["files"].items()) {
      std::ofstream out(dir + "/" + fname, std::ios::binary);
      const std::string& t = text.get_ref<const std::string&>();
      out.write(t.data(), static_cast<std::streamsize>(t.size()));
      if (!out) return SendError(res, grpc::StatusCode::UNAVAILABLE, "import: cannot write " + fname);
    }
    auto ds = gap::LoadDataset(dir, model::PresetNames());
    if (!ds.ok()) return BadRequest(res, ds.status().message());
    v1::ImportRunsRequest r;
    if (auto st = gap::FillImportRequest(*ds, dataset, &r); !st.ok()) return BadRequest(res, st.message());
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 120.0);
    v1::SubmitRunResponse out;
    auto st = stub_->ImportRuns(&ctx, r, &out);
    if (!st.ok()) return SendError(res, st);
    Json j = Json::parse(ToJson(out));
    j["warnings"] = ds->warnings;
    res.status = 201;
    res.set_content(Dump(j), kJson);
  }

  void Nights(const httplib::Request& req, httplib::Response& res) {
    long long limit = 0;
    if (!IntParam(req, res, "limit", &limit)) return;
    if (limit < 0 || limit > 1000) return BadRequest(res, "limit: must be 0..1000");
    v1::ListNightsRequest r;
    r.set_limit(static_cast<int>(limit));
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 10.0);
    v1::ListNightsResponse out;
    auto st = stub_->ListNights(&ctx, r, &out);
    if (!st.ok()) return SendError(res, st);
    Json j = Json::parse(ToJson(out));
    if (options_.next_night_unix_s) {
      if (auto next = options_.next_night_unix_s(); next.ok()) j["next_night_unix_s"] = *next;
    }
    res.set_content(Dump(j), kJson);
  }

  // Each bench's tracked valve (GetBenchHealth, docs/track.md "On the server"): ?bench= one bench, else every
  // bench with checks stored. The service checks the name (length, known bench).
  void Health(const httplib::Request& req, httplib::Response& res) {
    v1::GetBenchHealthRequest r;
    r.set_bench(req.get_param_value("bench"));
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 30.0);
    v1::GetBenchHealthResponse out;
    auto st = stub_->GetBenchHealth(&ctx, r, &out);
    if (!st.ok()) return SendError(res, st);
    res.set_content(ToJson(out), kJson);
  }

  // Who the bearer token is (user, role), from the server's own Authenticator: the page shows it in its header
  // and hides what the role may not do (the service still refuses it: this is for the eye, not a rule).
  void Session(const httplib::Request& req, httplib::Response& res) {
    if (!options_.identify) return SendError(res, grpc::StatusCode::NOT_FOUND, "session: not available on this server");
    if (!req.has_header("Authorization"))
      return SendError(res, grpc::StatusCode::UNAUTHENTICATED, "authorization: missing bearer token");
    auto who = options_.identify(req.get_header_value("Authorization"));
    if (!who.ok()) return SendError(res, grpc::StatusCode::UNAUTHENTICATED, who.status().message());
    res.set_content(Dump(Json{{"user", who->user}, {"role", who->role}}), kJson);
  }

  // Who a live view belongs to, for the per-session cap: the token (from the header or the cookie), hashed.
  static std::string SessionKey(const httplib::Request& req) {
    std::string problem;
    std::string t = req.has_header("Authorization") ? BearerTokenOf(req.get_header_value("Authorization"), &problem)
                                                    : CookieToken(req);
    return std::to_string(std::hash<std::string>()(t));
  }

  // A place for a live view (GatewayOptions::max_streams, max_streams_per_session), or null with `why`.
  std::shared_ptr<void> TakeStream(const std::string& session, std::string* why) {
    std::lock_guard<std::mutex> lock(streams_mu_);
    int& mine = streams_per_session_[session];
    if (streams_ >= options_.max_streams || mine >= options_.max_streams_per_session) {
      *why = streams_ >= options_.max_streams
                 ? fmt::format("live views: {} open, the dashboard's limit; try again in a moment", streams_)
                 : fmt::format("live views: {} open for this session, its limit; close some tabs", mine);
      if (mine == 0) streams_per_session_.erase(session);
      return nullptr;
    }
    ++mine;
    ++streams_;
    struct Slot {
      Slot(Routes* r, std::string s) : routes(r), session(std::move(s)) {}
      Slot(const Slot&) = delete;
      Slot& operator=(const Slot&) = delete;
      Routes* routes;
      std::string session;
      ~Slot() {
        std::lock_guard<std::mutex> lock(routes->streams_mu_);
        --routes->streams_;
        auto it = routes->streams_per_session_.find(session);
        if (it != routes->streams_per_session_.end() && --it->second <= 0) routes->streams_per_session_.erase(it);
      }
    };
    return std::make_shared<Slot>(this, session);
  }

  static constexpr int kMaxExports = 2;
  static constexpr int kMaxExportsPerSession = 1;
  std::shared_ptr<void> TakeExport(const std::string& session, std::string* why) {
    std::lock_guard<std::mutex> lock(streams_mu_);
    int& mine = exports_per_session_[session];
    if (exports_ >= kMaxExports || mine >= kMaxExportsPerSession) {
      *why = exports_ >= kMaxExports
                 ? fmt::format("HDF5/MAT exports: {} being built, the dashboard's limit; try again in a moment", exports_)
                 : fmt::format("HDF5/MAT exports: {} being built for this session, its limit; wait for it", mine);
      if (mine == 0) exports_per_session_.erase(session);
      return nullptr;
    }
    ++mine;
    ++exports_;
    return std::shared_ptr<void>(new int(0), [this, session](int* p) {
      delete p;
      std::lock_guard<std::mutex> lock(streams_mu_);
      --exports_;
      auto it = exports_per_session_.find(session);
      if (it != exports_per_session_.end() && --it->second <= 0) exports_per_session_.erase(it);
    });
  }

  std::unique_ptr<v1::BenchService::Stub> stub_;
  SessionStore sessions_;
  FailedAttempts logins_;  // common/failed_attempts.h
  std::mutex streams_mu_;
  int streams_ = 0;
  std::map<std::string, int> streams_per_session_;
  int exports_ = 0;
  std::map<std::string, int> exports_per_session_;
  GatewayOptions options_;
  bool tls_;
  size_t max_body_bytes_;
};

// PEM text -> OpenSSL objects for httplib::SSLServer (which takes ownership of neither).
struct TlsMaterial {
  X509* cert = nullptr;
  EVP_PKEY* key = nullptr;
  ~TlsMaterial() {
    if (cert) X509_free(cert);
    if (key) EVP_PKEY_free(key);
  }
};

}  // namespace

const Asset* FindAsset(std::string_view url_path) {
  for (const Asset& a : Assets())
    if (url_path == a.url_path) return &a;
  return nullptr;
}

StatusOr<std::unique_ptr<Gateway>> Gateway::Start(const GatewayOptions& options,
                                                  std::shared_ptr<grpc::Channel> channel) {
  const size_t colon = options.listen_address.rfind(':');
  if (colon == std::string::npos || colon == 0)
    return Status::InvalidArgument("web.listen_address: must be host:port, got '" + options.listen_address + "'");
  std::string host = options.listen_address.substr(0, colon);
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  int port = 0;
  try {
    port = std::stoi(options.listen_address.substr(colon + 1));
  } catch (const std::exception&) {
    return Status::InvalidArgument("web.listen_address: bad port in '" + options.listen_address + "'");
  }
  std::unique_ptr<Gateway> g(new Gateway());
  // Uploads of an import left by a server that was killed mid-import (its Cleanup never ran).
  if (const int stale = RemoveStaleImports(); stale > 0)
    spdlog::info("web: removed {} temporary import director{} left by a stopped server", stale, stale == 1 ? "y" : "ies");
  if (!options.tls_cert_pem.empty()) {
    TlsMaterial m;
    BIO* cb = BIO_new_mem_buf(options.tls_cert_pem.data(), static_cast<int>(options.tls_cert_pem.size()));
    m.cert = PEM_read_bio_X509(cb, nullptr, nullptr, nullptr);
    BIO_free(cb);
    BIO* kb = BIO_new_mem_buf(options.tls_key_pem.data(), static_cast<int>(options.tls_key_pem.size()));
    m.key = PEM_read_bio_PrivateKey(kb, nullptr, nullptr, nullptr);
    BIO_free(kb);
    if (!m.cert) return Status::InvalidArgument("tls.cert_file: not a PEM certificate");
    if (!m.key) return Status::InvalidArgument("tls.key_file: not a PEM private key");
    auto ssl = std::make_unique<DoorServer<httplib::SSLServer>>(m.cert, m.key);
    if (!ssl->is_valid()) return Status::InvalidArgument("tls: the certificate and key do not make a TLS server");
    ssl->InitDoor(options.limits, ssl->ssl_context());
    g->http_ = std::move(ssl);
    g->tls_ = true;
  } else {
    auto plain = std::make_unique<DoorServer<httplib::Server>>();
    plain->InitDoor(options.limits, nullptr);
    g->http_ = std::move(plain);
  }
  if (options.max_streams >= options.limits.workers)
    return Status::InvalidArgument(fmt::format("web: max_streams ({}) must stay below the workers ({})",
                                               options.max_streams, options.limits.workers));
  g->http_->set_payload_max_length(options.limits.max_body_bytes);
  g->http_->set_read_timeout(5, 0);   // SO_RCVTIMEO on each socket: one blocking read (a TLS record) at most
  g->http_->set_write_timeout(10, 0); // SO_SNDTIMEO: a reader that stops reading lets its worker go
  // What the answers' Keep-Alive header announces; the door enforces both.
  g->http_->set_keep_alive_timeout(static_cast<time_t>(std::ceil(options.limits.idle_timeout_s)));
  g->http_->set_keep_alive_max_count(static_cast<size_t>(std::max(1, options.limits.max_requests_per_connection)));
  auto routes = std::make_shared<Routes>(std::move(channel), options, g->tls_);
  routes->Install(*g->http_);
  g->routes_ = routes;  // the handlers point into it
  // SO_REUSEADDR (a restarted server rebinds at once) but not cpp-httplib's default SO_REUSEPORT, which lets a
  // second server bind the same port and take half the connections: one server per port.
  auto listening = std::make_shared<socket_t>(INVALID_SOCKET);
  g->http_->set_socket_options([listening](socket_t sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    *listening = sock;
  });
  if (port == 0) {
    g->port_ = g->http_->bind_to_any_port(host);
    if (g->port_ <= 0) return Status::Unavailable("web.listen_address: cannot listen on " + options.listen_address);
  } else {
    if (!g->http_->bind_to_port(host, port))
      return Status::Unavailable("web.listen_address: cannot listen on " + options.listen_address);
    g->port_ = port;
  }
  // cpp-httplib listens with a backlog of 5: a burst of connections (600 slow heads) overflows it and every
  // further SYN waits for its 1 s retransmit. listen() again on the bound socket sets the kernel's backlog.
  if (*listening != INVALID_SOCKET) (void)::listen(*listening, 1024);
  httplib::Server* http = g->http_.get();
  g->thread_ = std::thread([http] { http->listen_after_bind(); });
  return g;
}

void Gateway::Stop() {
  if (http_) http_->stop();
  if (thread_.joinable()) thread_.join();
}

Gateway::~Gateway() { Stop(); }

RawGateway::RawGateway(std::shared_ptr<grpc::Channel> channel, const GatewayOptions& options) {
  auto server = std::make_unique<DoorServer<httplib::Server>>();
  server->set_payload_max_length(options.limits.max_body_bytes);
  auto routes = std::make_shared<Routes>(std::move(channel), options, false);
  routes->Install(*server);
  routes_ = routes;
  http_ = std::move(server);
}

RawGateway::~RawGateway() = default;

std::string RawGateway::Serve(const std::string& raw) {
  auto* server = static_cast<DoorServer<httplib::Server>*>(http_.get());
  MemoryStream strm(raw);
  for (int k = 0; k < 64 && !strm.consumed(); ++k) {
    bool closed = false;
    if (!server->ServeStream(strm, false, closed) || closed) break;
  }
  return strm.output();
}

}  // namespace vb::web
