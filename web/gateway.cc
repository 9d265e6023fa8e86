#include "web/gateway.h"

#include <fmt/format.h>
#include <google/protobuf/util/json_util.h>
#include <httplib.h>
#include <openssl/pem.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <nlohmann/json.hpp>
#include <set>
#include <vector>

#include "common/queue_estimate.h"
#include "experiment/spec.h"
#include "export/run_file.h"
#include "valvebench/v1/api.grpc.pb.h"
#include "web/assets.h"

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
constexpr char kCookie[] = "vb_token";

void SendError(httplib::Response& res, grpc::StatusCode code, const std::string& message) {
  res.status = HttpStatusFor(code);
  res.set_content(Json{{"code", CodeName(code)}, {"message", message}}.dump(), kJson);
}
void SendError(httplib::Response& res, const grpc::Status& st) { SendError(res, st.error_code(), st.error_message()); }
void BadRequest(httplib::Response& res, const std::string& message) {
  SendError(res, grpc::StatusCode::INVALID_ARGUMENT, message);
}

std::string ToJson(const google::protobuf::Message& m) {
  google::protobuf::util::JsonPrintOptions o;
  o.preserve_proto_field_names = true;  // the names specs are written with (supply_V, not supplyV)
  std::string out;
  (void)google::protobuf::util::MessageToJsonString(m, &out, o);
  return out;
}

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
void Authorize(const httplib::Request& req, grpc::ClientContext* ctx) {
  if (req.has_header("Authorization")) {
    ctx->AddMetadata("authorization", req.get_header_value("Authorization"));
    return;
  }
  if (req.method != "GET") return;
  const std::string t = CookieToken(req);
  if (TokenShapeOk(t)) ctx->AddMetadata("authorization", "Bearer " + t);
}

void Deadline(grpc::ClientContext* ctx, double seconds) {
  ctx->set_deadline(std::chrono::system_clock::now() +
                    std::chrono::milliseconds(static_cast<long long>(seconds * 1000.0)));
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

// A whole recorded trace, from GetTrace's chunks.
struct Trace {
  std::vector<std::string> channels;
  double t0_s = 0.0, period_s = 0.0;
  std::vector<std::vector<double>> columns;
  size_t samples() const { return columns.empty() ? 0 : columns[0].size(); }
  // The channels but the time (t_s is recorded as a channel; rows carry t0_s + k * period_s instead).
  std::vector<size_t> ValueChannels() const {
    std::vector<size_t> out;
    for (size_t ch = 0; ch < channels.size(); ++ch)
      if (channels[ch] != "t_s") out.push_back(ch);
    return out;
  }
};

grpc::Status ReadTrace(v1::BenchService::Stub* stub, const httplib::Request& req, std::int64_t run_id, Trace* t) {
  grpc::ClientContext ctx;
  Authorize(req, &ctx);
  Deadline(&ctx, 60.0);
  v1::GetTraceRequest r;
  r.set_run_id(run_id);
  auto reader = stub->GetTrace(&ctx, r);
  v1::TraceChunk c;
  bool first = true;
  while (reader->Read(&c)) {
    if (first) {
      t->channels.assign(c.channels().begin(), c.channels().end());
      t->t0_s = c.t0_s();
      t->period_s = c.sample_period_s();
      t->columns.assign(t->channels.size(), {});
      for (auto& col : t->columns) col.reserve(static_cast<size_t>(std::max<std::int64_t>(0, c.total_samples())));
      first = false;
    }
    const size_t n = static_cast<size_t>(c.samples());
    if (static_cast<size_t>(c.channels_size()) != t->channels.size() || c.data().size() != n * t->channels.size() * 8)
      return grpc::Status(grpc::StatusCode::DATA_LOSS, fmt::format("trace chunk {}: inconsistent size", c.index()));
    for (size_t ch = 0; ch < t->channels.size(); ++ch) {
      auto& col = t->columns[ch];
      const size_t at = col.size();
      col.resize(at + n);
      std::memcpy(col.data() + at, c.data().data() + ch * n * 8, n * 8);  // little-endian float64 (api.proto)
    }
  }
  return reader->Finish();
}

void AppendNumber(std::string* out, double v) {
  if (std::isfinite(v)) {
    fmt::format_to(std::back_inserter(*out), "{:.10g}", v);
  } else {
    *out += "null";
  }
}

// Rows [t_s, ch0, ch1, ...] of the samples with t in [t_from, t_to]; at most max_points rows: beyond that each
// bucket of samples gives two rows, every channel's minimum at the bucket's start and its maximum at its middle
// (the envelope of a PWM current survives; a bucket is narrower than a pixel at the default 4000 points).
std::string TraceRowsJson(const Trace& t, double t_from, double t_to, size_t max_points, bool* decimated) {
  const size_t n = t.samples();
  size_t k0 = 0, k1 = n;
  if (t.period_s > 0.0 && n > 0) {
    if (std::isfinite(t_from)) k0 = static_cast<size_t>(std::clamp(std::floor((t_from - t.t0_s) / t.period_s), 0.0, double(n)));
    if (std::isfinite(t_to)) k1 = static_cast<size_t>(std::clamp(std::ceil((t_to - t.t0_s) / t.period_s) + 1, 0.0, double(n)));
  }
  if (k1 < k0) k1 = k0;
  const std::vector<size_t> value_channels = t.ValueChannels();
  std::string out = "[";
  auto row = [&](double time, auto&& value) {
    if (out.size() > 1) out += ',';
    out += '[';
    AppendNumber(&out, time);
    for (size_t ch : value_channels) {
      out += ',';
      AppendNumber(&out, value(ch));
    }
    out += ']';
  };
  const size_t count = k1 - k0;
  *decimated = count > max_points;
  if (!*decimated) {
    for (size_t k = k0; k < k1; ++k) row(t.t0_s + k * t.period_s, [&](size_t ch) { return t.columns[ch][k]; });
  } else {
    const size_t buckets = std::max<size_t>(1, max_points / 2);
    for (size_t b = 0; b < buckets; ++b) {
      const size_t a = k0 + count * b / buckets, e = k0 + count * (b + 1) / buckets;
      if (a >= e) continue;
      auto extreme = [&](size_t ch, bool want_max) {
        double m = t.columns[ch][a];
        for (size_t k = a; k < e; ++k) {
          const double v = t.columns[ch][k];
          if (std::isnan(m) || (want_max ? v > m : v < m)) m = v;
        }
        return m;
      };
      row(t.t0_s + a * t.period_s, [&](size_t ch) { return extreme(ch, false); });
      row(t.t0_s + (a + (e - a) / 2) * t.period_s, [&](size_t ch) { return extreme(ch, true); });
    }
  }
  out += ']';
  return out;
}

class Routes {
 public:
  Routes(std::shared_ptr<grpc::Channel> channel, const GatewayOptions& options, bool tls)
      : stub_(v1::BenchService::NewStub(channel)), options_(options), tls_(tls) {}

  void Install(httplib::Server& s) {
    s.set_default_headers({{"X-Content-Type-Options", "nosniff"},
                           {"Referrer-Policy", "no-referrer"},
                           {"Content-Security-Policy",
                            "default-src 'self'; style-src 'self' 'unsafe-inline'; img-src 'self' data:; "
                            "frame-ancestors 'none'"}});
    for (const Asset& a : Assets()) {
      s.Get(a.url_path, [&a](const httplib::Request&, httplib::Response& res) {
        res.set_header("Cache-Control", "no-cache");
        res.set_content(a.data, a.size, a.content_type);
      });
    }
    s.Post("/api/login", [this](const auto& q, auto& r) { Login(q, r); });
    s.Post("/api/logout", [this](const auto&, auto& r) {
      r.set_header("Set-Cookie", CookieHeader("", 0));
      r.set_content("{}", kJson);
    });
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
    s.Get("/api/diagnose", [this](const auto& q, auto& r) { Diagnose(q, r); });
    s.Get("/api/nights", [this](const auto& q, auto& r) { Nights(q, r); });
    s.set_error_handler([](const httplib::Request& req, httplib::Response& res) {
      if (res.body.empty() && res.status == 404)
        SendError(res, grpc::StatusCode::NOT_FOUND, "no such page or API route: " + req.method + " " + req.path);
    });
    s.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr ep) {
      std::string what = "internal error";
      try {
        if (ep) std::rethrow_exception(ep);
      } catch (const std::exception& e) {
        what = e.what();
      } catch (...) {
      }
      SendError(res, grpc::StatusCode::INTERNAL, what);
    });
  }

 private:
  std::string CookieHeader(const std::string& token, int max_age_s) const {
    return fmt::format("{}={}; Path=/api; Max-Age={}; HttpOnly; SameSite=Strict{}", kCookie, token, max_age_s,
                       tls_ ? "; Secure" : "");
  }

  void Login(const httplib::Request& req, httplib::Response& res) {
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
    if (!st.ok()) return SendError(res, st);
    res.set_header("Set-Cookie", CookieHeader(token, 12 * 3600));
    res.set_content("{}", kJson);
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

  // Running and queued runs with their place in the queue and their ETA: common/queue_estimate.h, the
  // estimate `benchctl queue` shows, over the live benches ListBenches reports.
  void Queue(const httplib::Request& req, httplib::Response& res) {
    std::vector<v1::Run> running, queued;
    for (v1::RunStatus s : {v1::RUNNING, v1::QUEUED}) {
      std::string token;
      do {
        grpc::ClientContext ctx;
        Authorize(req, &ctx);
        Deadline(&ctx, 10.0);
        v1::ListRunsRequest r;
        r.set_status(s);
        r.set_page_size(1000);
        r.set_page_token(token);
        v1::ListRunsResponse out;
        auto st = stub_->ListRuns(&ctx, r, &out);
        if (!st.ok()) return SendError(res, st);
        for (auto& run : *out.mutable_runs()) (s == v1::RUNNING ? running : queued).push_back(std::move(run));
        token = out.next_page_token();
      } while (!token.empty());
    }
    int live = 0;
    if (!queued.empty()) {
      grpc::ClientContext ctx;
      Authorize(req, &ctx);
      Deadline(&ctx, 10.0);
      v1::ListBenchesResponse benches;
      if (stub_->ListBenches(&ctx, v1::ListBenchesRequest(), &benches).ok())
        for (const auto& b : benches.benches()) live += b.host().empty() || b.alive();
    }
    auto info = [](const v1::Run& r) {
      return QueueRunInfo{r.id(), r.status() == v1::RUNNING ? RunStatus::kRunning : RunStatus::kQueued, r.priority(),
                          r.duration_s(), r.progress(), r.started_unix_s()};
    };
    std::vector<QueueRunInfo> all;
    for (const auto* list : {&running, &queued})
      for (const auto& r : *list) all.push_back(info(r));
    const auto estimates = EstimateQueue(all, live);
    std::stable_sort(queued.begin(), queued.end(), [&](const v1::Run& a, const v1::Run& b) {
      return estimates.at(a.id()).position < estimates.at(b.id()).position;
    });
    const double now =
        std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
    std::string out = R"({"now_unix_s":)" + fmt::format("{:.3f}", now) + R"(,"live_benches":)" +
                      std::to_string(live) + R"(,"running":[)";
    for (size_t k = 0; k < running.size(); ++k) {
      const double eta = RunningEta_s(info(running[k]), now);
      out += (k ? "," : "") + std::string(R"({"run":)") + ToJson(running[k]) + R"(,"eta_s":)";
      AppendNumber(&out, eta < 0 ? NAN : eta);
      out += "}";
    }
    out += R"(],"queued":[)";
    for (size_t k = 0; k < queued.size(); ++k) {
      const QueueEstimate& e = estimates.at(queued[k].id());
      out += (k ? "," : "") + fmt::format(R"({{"position":{},"run":{},"eta_s":)", e.position, ToJson(queued[k]));
      AppendNumber(&out, e.eta_s < 0 ? NAN : e.eta_s);
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
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 20.0);
    v1::ListRunsResponse out;
    auto st = stub_->ListRuns(&ctx, r, &out);
    if (!st.ok()) return SendError(res, st);
    res.set_content(ToJson(out), kJson);
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
    auto spec = experiment::ParseSpecJson(body["spec"].dump());
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
    res.set_content(R"({"run":)" + ToJson(run) + R"(,"metric_units":)" + units.dump() + R"(,"channel_units":)" +
                        channel_units.dump() + "}",
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
    Trace t;
    auto st = ReadTrace(stub_.get(), req, PathId(req), &t);
    if (!st.ok()) return SendError(res, st);
    bool decimated = false;
    const std::string rows = TraceRowsJson(t, t_from, t_to, static_cast<size_t>(max_points), &decimated);
    std::vector<std::string> names;  // the rows' columns after t_s
    for (size_t ch : t.ValueChannels()) names.push_back(t.channels[ch]);
    Json head{{"channels", names}, {"t0_s", t.t0_s}, {"sample_period_s", t.period_s},
              {"total_samples", t.samples()}, {"decimated", decimated}};
    std::string out = head.dump();
    out.pop_back();
    out += R"(,"rows":)" + rows + "}";
    res.set_content(out, kJson);
  }

  void TraceCsv(const httplib::Request& req, httplib::Response& res) {
    Trace t;
    const std::int64_t id = PathId(req);
    auto st = ReadTrace(stub_.get(), req, id, &t);
    if (!st.ok()) return SendError(res, st);
    const std::vector<size_t> value_channels = t.ValueChannels();
    std::string out = "t_s";
    for (size_t ch : value_channels) out += "," + t.channels[ch];
    out += "\n";
    out.reserve(out.size() + t.samples() * (value_channels.size() + 1) * 14);
    for (size_t k = 0; k < t.samples(); ++k) {
      AppendNumber(&out, t.t0_s + k * t.period_s);
      for (size_t ch : value_channels) {
        out += ',';
        AppendNumber(&out, t.columns[ch][k]);
      }
      out += '\n';
    }
    res.set_header("Content-Disposition", fmt::format("attachment; filename=\"run{}.csv\"", id));
    res.set_content(out, "text/csv; charset=utf-8");
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
          st.ok() ? Json{{"code", "FAILED_PRECONDITION"},
                         {"message", "run " + std::to_string(run.id()) +
                                         " is interactive: follow it with benchctl watch (a watch from this page "
                                         "would cancel it when the page goes away)"}}.dump()
                  : Json{{"code", CodeName(st.error_code())}, {"message", st.error_message()}}.dump();
      res.set_header("Cache-Control", "no-cache");
      res.set_content("event: error\ndata: " + data + "\n\n", "text/event-stream");
      return;
    }
    struct Watch {
      grpc::ClientContext ctx;
      std::unique_ptr<grpc::ClientReader<v1::RunEvent>> reader;
    };
    auto w = std::make_shared<Watch>();
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
            if (!send("run", ToJson(ev))) {  // the page went away
              w->ctx.TryCancel();
              (void)w->reader->Finish();
              return false;
            }
          }
          const grpc::Status st = w->reader->Finish();
          if (!st.ok() && st.error_code() != grpc::StatusCode::DEADLINE_EXCEEDED) {
            send("error", Json{{"code", CodeName(st.error_code())}, {"message", st.error_message()}}.dump());
          } else if (ended) {
            send("end", Json{{"status", last_status}}.dump());
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
    res.set_content(j.dump(), kJson);
  }

  void Compare(const httplib::Request& req, httplib::Response& res) {
    v1::CompareRunsRequest r;
    long long batch = 0;
    if (!IntParam(req, res, "batch_id", &batch)) return;
    r.set_batch_id(batch);
    if (!RunIdsParam(req, res, r.mutable_run_ids())) return;
    grpc::ClientContext ctx;
    Authorize(req, &ctx);
    Deadline(&ctx, 30.0);
    v1::CompareRunsResponse out;
    auto st = stub_->CompareRuns(&ctx, r, &out);
    if (!st.ok()) return SendError(res, st);
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
    res.set_content(R"({"comparison":)" + ToJson(out) + R"(,"units":)" + units.dump() + "}", kJson);
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
    res.set_content(ToJson(out), kJson);
  }

  std::unique_ptr<v1::BenchService::Stub> stub_;
  GatewayOptions options_;
  bool tls_;
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
    auto ssl = std::make_unique<httplib::SSLServer>(m.cert, m.key);
    if (!ssl->is_valid()) return Status::InvalidArgument("tls: the certificate and key do not make a TLS server");
    g->http_ = std::move(ssl);
    g->tls_ = true;
  } else {
    g->http_ = std::make_unique<httplib::Server>();
  }
  const int threads = std::max(4, options.threads);
  g->http_->new_task_queue = [threads] { return new httplib::ThreadPool(static_cast<size_t>(threads)); };
  g->http_->set_payload_max_length(8u << 20);
  auto routes = std::make_shared<Routes>(std::move(channel), options, g->tls_);
  routes->Install(*g->http_);
  g->routes_ = routes;  // the handlers point into it
  // SO_REUSEADDR (a restarted server rebinds at once) but not cpp-httplib's default SO_REUSEPORT, which lets a
  // second server bind the same port and take half the connections: one server per port.
  g->http_->set_socket_options([](socket_t sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
  });
  if (port == 0) {
    g->port_ = g->http_->bind_to_any_port(host);
    if (g->port_ <= 0) return Status::Unavailable("web.listen_address: cannot listen on " + options.listen_address);
  } else {
    if (!g->http_->bind_to_port(host, port))
      return Status::Unavailable("web.listen_address: cannot listen on " + options.listen_address);
    g->port_ = port;
  }
  httplib::Server* http = g->http_.get();
  g->thread_ = std::thread([http] { http->listen_after_bind(); });
  return g;
}

void Gateway::Stop() {
  if (http_) http_->stop();
  if (thread_.joinable()) thread_.join();
}

Gateway::~Gateway() { Stop(); }

}  // namespace vb::web
