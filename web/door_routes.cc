// The door's side of the gateway's routes (web/routes.h): the checks of every request before its route runs,
// the sessions (login, logout, the cookie, who a token is) and the places for live views and exports.
#include <fmt/format.h>
#include <httplib.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <regex>
#include <string>

#include "web/assets.h"
#include "web/door.h"
#include "web/http.h"
#include "web/routes.h"

namespace vb::web {

namespace {

// No token of its own: every call goes with its request's credentials (Routes::As).
client::ClientOptions GatewayClientOptions() {
  client::ClientOptions o;
  o.address = "the server's in-process channel";
  return o;
}

}  // namespace

Routes::Routes(std::shared_ptr<grpc::Channel> channel, const GatewayOptions& options, bool tls)
    : client_(std::move(channel), GatewayClientOptions()),
      sessions_(options.sessions_file),
      options_(options),
      tls_(tls),
      max_body_bytes_(options.limits.max_body_bytes) {}

void Routes::Install(httplib::Server& s) {
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

// The door's checks of every request before its route runs (docs/web.md "Door"): true lets it through, false
// has the answer (a 4xx JSON error) in `res`.
bool Routes::Admit(const httplib::Request& req, httplib::Response& res) {
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

bool Routes::CookieRoute(const std::string& path) {
  static const std::regex re(
      R"(/api/runs/\d{1,15}/(events|trace\.(csv|h5|mat))|/api/compare\.(csv|json)|/api/batches/\d{1,15}/report\.html)");
  return std::regex_match(path, re);
}

// No Origin / Sec-Fetch-Site (not a browser, or a same-origin navigation over plain HTTP), or this dashboard's
// own origin (scheme://Host), or one of GatewayOptions::allowed_origins.
bool Routes::SameOrigin(const httplib::Request& req) const {
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
void Routes::AfterRoute(const httplib::Request& req, httplib::Response& res) {
  if (req.path.rfind("/api/", 0) == 0 && !res.has_header("Cache-Control")) res.set_header("Cache-Control", "no-store");
  if (res.status == 401) {  // the service refused the session's token itself (not a route the cookie cannot open)
    const std::string session = CookieToken(req);
    const std::string token = session.empty() ? "" : sessions_.TokenOf(session);
    if (!token.empty() && req.get_header_value("Authorization") == "Bearer " + token) sessions_.Revoke(session);
  }
}

std::string Routes::CookieHeader(const std::string& session, int max_age_s) const {
  return fmt::format("{}={}; Path=/api; Max-Age={}; HttpOnly; SameSite=Strict{}", kCookie, session, max_age_s,
                     tls_ ? "; Secure" : "");
}

// Login: a JSON body only (a cross-site form can post text/plain, not application/json without a CORS
// preflight this server never grants), from this dashboard's origin, at most FailedAttempts::kMax failures per
// client address in FailedAttempts::kWindow_s (common/failed_attempts.h); each failure is logged. The cookie
// holds a random session id, not the token: logout revokes it.
void Routes::Login(const httplib::Request& req, httplib::Response& res) {
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
  grpc::Status st;
  if (auto out = client_.With({"Bearer " + token, 10.0, &st}).Benches(); !out.ok()) {
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
void Routes::Logout(const httplib::Request& req, httplib::Response& res) {
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
void Routes::SessionState(const httplib::Request& req, httplib::Response& res) {
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

// Who the bearer token is (user, role), from the server's own Authenticator: the page shows it in its header
// and hides what the role may not do (the service still refuses it: this is for the eye, not a rule).
void Routes::Session(const httplib::Request& req, httplib::Response& res) {
  if (!options_.identify) return SendError(res, grpc::StatusCode::NOT_FOUND, "session: not available on this server");
  if (!req.has_header("Authorization"))
    return SendError(res, grpc::StatusCode::UNAUTHENTICATED, "authorization: missing bearer token");
  auto who = options_.identify(req.get_header_value("Authorization"));
  if (!who.ok()) return SendError(res, grpc::StatusCode::UNAUTHENTICATED, who.status().message());
  res.set_content(Dump(Json{{"user", who->user}, {"role", who->role}}), kJson);
}


// Who a live view belongs to, for the per-session cap: the token (from the header or the cookie), hashed.
std::string Routes::SessionKey(const httplib::Request& req) {
  std::string problem;
  std::string t = req.has_header("Authorization") ? BearerTokenOf(req.get_header_value("Authorization"), &problem)
                                                  : CookieToken(req);
  return std::to_string(std::hash<std::string>()(t));
}

// A place for a live view (GatewayOptions::max_streams, max_streams_per_session), or null with `why`.
std::shared_ptr<void> Routes::TakeStream(const std::string& session, std::string* why) {
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

std::shared_ptr<void> Routes::TakeExport(const std::string& session, std::string* why) {
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

}  // namespace vb::web
