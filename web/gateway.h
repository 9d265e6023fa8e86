// The web dashboard's HTTP server (docs/web.md): the embedded pages and a JSON/SSE gateway in front of a
// BenchService channel, reached through client::Client as benchctl reaches it (docs/client.md). Every /api
// request becomes the matching BenchService RPC with the caller's token forwarded as "authorization: Bearer
// <token>" metadata (a per-request Client::With view), so authentication, roles, validation (field-named
// errors), admission and limits are the gRPC API's own: the gateway holds no rule of its own beyond the queue
// view's ordering (docs/web.md "Queue").
//
// Routes (JSON bodies are protobuf JSON with the .proto field names):
//   GET  /, /app.js, /app.css, /dygraph.min.js, /dygraph.min.css   the page (embedded)
//   POST /api/login {"token"}        checks the token (ListBenches), sets the vb_session cookie (a server-side
//                                    session id, for SSE and the CSV link)
//   POST /api/logout {"everywhere"}  revokes the session (with everywhere: every session of its token)
//   GET  /api/login                  whether the cookie's session is live: {session, user, role}
//   GET  /api/benches                ListBenches
//   GET  /api/queue                  running and queued runs, queue positions, ETA of running runs
//   GET  /api/session                who the token is: {user, role} (GatewayOptions::identify)
//   GET  /api/runs?status=&batch_id=&tag=&bench=&controller=&submitter=&name=&submitted_after_unix_s=
//                  &submitted_before_unix_s=&order_by=&page_size=&page_token=   ListRuns (total_size too)
//   POST /api/runs {"spec", "batch_name"}                                 SubmitRun
//   GET  /api/runs/ID                GetRun, with the unit of each metric
//   POST /api/runs/ID/cancel {"reason"}                                   CancelRun
//   POST /api/runs/ID/rerun          GetRun + SubmitRun of its exact spec
//   GET  /api/runs/ID/trace?t_from_s=&t_to_s=&max_points=                 GetTrace, min/max-decimated rows
//   GET  /api/runs/ID/trace.csv      GetTrace, every sample (export)
//   GET  /api/runs/ID/events?rate_Hz=                                     WatchRun as Server-Sent Events
//   GET  /api/compare?runs=1,2,3 | ?batch_id=N                            CompareRuns, with units
//   GET  /api/runs/ID/trace.h5|.mat  GetRun + GetTrace as HDF5 / MATLAB (export/'s writers, benchctl export's)
//   GET  /api/compare.csv|.json?runs=|?batch_id=                        CompareRuns as benchctl compare --csv/--json
//   GET  /api/batches/N/report.html  the batch's HTML report (report/, benchctl report --batch N)
//   POST /api/import {"dataset", "files": {name: text}}                  gap::LoadDataset + ImportRuns
//   GET  /api/nights?limit=          ListNights, and next_night_unix_s (GatewayOptions::next_night_unix_s)
// Tokens: "Authorization: Bearer <token>" on any request; the vb_session cookie (HttpOnly, SameSite=Strict) only
// on GET .../events and the download links (trace.csv/.h5/.mat, compare.csv/.json, report.html), from this
// origin (EventSource and a link cannot send headers; docs/web.md "Sessions"). Every request passes the door's
// checks first (docs/web.md "Door", "Limits").
// Errors: {"code": "INVALID_ARGUMENT", "message": "..."} with the HTTP status of HttpStatusFor(code).
#pragma once

#include <grpcpp/grpcpp.h>

#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>
#include <thread>

#include "common/status.h"
#include "web/limits.h"

namespace httplib {
class Server;
}

namespace vb::web {

struct GatewayOptions {
  std::string listen_address;   // "host:port"; port 0 = any free port
  std::string tls_cert_pem;     // both set = HTTPS (the gRPC server's certificate and key)
  std::string tls_key_pem;
  double watch_window_s = 60.0; // an SSE stream ends after this long; the browser reconnects (docs/web.md "SSE")
  DoorLimits limits;            // connections, heads, bodies, workers (web/limits.h)
  // Live views (SSE) open at once, in all and per session (token); each holds a worker, so the total stays below
  // limits.workers: the page's other requests always find one. Beyond: 429.
  int max_streams = 48;
  int max_streams_per_session = 8;
  // Where the sessions are kept over a restart (web/session_store.h); empty: in memory only.
  std::string sessions_file;
  // Origins besides the dashboard's own accepted on login and on cookie-authorised costly calls.
  std::vector<std::string> allowed_origins;
  // Who a bearer token is, for the page's header and its role-aware controls (GET /api/session): the server's
  // own Authenticator (server/auth.h), so the page shows what the service will enforce. Unset: 404.
  struct Identity {
    std::string user;
    std::string role;  // "viewer", "operator", "admin"
  };
  std::function<StatusOr<Identity>(std::string_view authorization)> identify;
  // The next nightly regression's start (unix seconds), from the server's cron (config "nights"); unset or an
  // error = no night scheduled. GET /api/nights says it as next_night_unix_s.
  std::function<StatusOr<double>()> next_night_unix_s;
};

// The door's checks, public for the tests and the fuzz target.
bool ValidUtf8(std::string_view s);
// The deepest nesting of [ and { outside strings (a pre-scan: the body is not parsed yet).
int JsonDepth(std::string_view s);
// The token of "Bearer <token>", or "" with `problem` saying why not (visible ASCII only: gRPC metadata).
std::string BearerTokenOf(std::string_view header, std::string* problem);
// An uploaded data file's header row (POST /api/import): "" when it has at most kMaxCsvColumns columns and no
// name twice, else why not. Linear in the row (a set of names).
inline constexpr size_t kMaxCsvColumns = 256;
std::string CsvHeaderProblem(std::string_view text);
// The Content-Security-Policy of a served batch report (GET /api/batches/ID/report.html): the report is one
// self-contained file whose charts are drawn by inline scripts, allowed here by their SHA-256 hashes and
// nothing else (no other script, no fetch, no form).
std::string ReportCsp(std::string_view html);
// Uploads are read in memory now; earlier builds wrote each to <temp>/valvebench-import-<pid>-XXXXXX and one
// killed mid-import left it behind. At start, those whose server process is gone are removed; returns how many.
int RemoveStaleImports();

// The gateway's request handling without sockets, for the fuzz target (fuzz/gateway_fuzz.cc): `raw` is read as
// the bytes of one connection (requests one after another), the answers' bytes come back.
class RawGateway {
 public:
  explicit RawGateway(std::shared_ptr<grpc::Channel> channel, const GatewayOptions& options = {});
  ~RawGateway();
  std::string Serve(const std::string& raw);

 private:
  std::shared_ptr<void> routes_;
  std::unique_ptr<httplib::Server> http_;
};

// The HTTP status for a gRPC status code (UNAUTHENTICATED 401, PERMISSION_DENIED 403, INVALID_ARGUMENT 400,
// NOT_FOUND 404, FAILED_PRECONDITION 409, RESOURCE_EXHAUSTED 429, UNAVAILABLE 503, ...).
int HttpStatusFor(grpc::StatusCode code);

class Gateway {
 public:
  // Binds and starts serving on a thread of its own. `channel` reaches the BenchService (in the server: its
  // in-process channel). Unavailable when the address cannot be bound, InvalidArgument for a bad address or
  // TLS material.
  static StatusOr<std::unique_ptr<Gateway>> Start(const GatewayOptions& options, std::shared_ptr<grpc::Channel> channel);
  ~Gateway();
  Gateway(const Gateway&) = delete;
  Gateway& operator=(const Gateway&) = delete;

  int port() const { return port_; }
  bool tls() const { return tls_; }
  // Stops accepting and waits for the serving thread (open SSE streams end with their window).
  void Stop();

 private:
  Gateway() = default;
  std::unique_ptr<httplib::Server> http_;
  std::shared_ptr<void> routes_;  // the handlers' state (gateway.cc)
  std::thread thread_;
  int port_ = 0;
  bool tls_ = false;
};

}  // namespace vb::web
