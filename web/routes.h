// The gateway's routes (web/gateway.h lists them): one object per server holding the client of the service,
// the sessions, the failed-login counts and the live-view and export places. Its parts live in one file each:
//   web/door_routes.cc  the door's checks before every route (Admit), sessions: login, logout, cookie, identity,
//                       and the places for live views and exports
//   web/gateway.cc      the API: each route reads its HTTP request, calls the service through client::Client
//                       (client/: the views benchctl shares) and encodes the answer
#pragma once

#include <grpcpp/grpcpp.h>
#include <httplib.h>

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "client/client.h"
#include "common/failed_attempts.h"
#include "web/gateway.h"
#include "web/session_store.h"

namespace vb::web {

class Routes {
 public:
  Routes(std::shared_ptr<grpc::Channel> channel, const GatewayOptions& options, bool tls);
  void Install(httplib::Server& s);

 private:
  // web/door_routes.cc
  bool Admit(const httplib::Request& req, httplib::Response& res);
  static bool CookieRoute(const std::string& path);
  bool SameOrigin(const httplib::Request& req) const;
  void AfterRoute(const httplib::Request& req, httplib::Response& res);
  std::string CookieHeader(const std::string& session, int max_age_s) const;
  void Login(const httplib::Request& req, httplib::Response& res);
  void Logout(const httplib::Request& req, httplib::Response& res);
  void SessionState(const httplib::Request& req, httplib::Response& res);
  void Session(const httplib::Request& req, httplib::Response& res);
  static std::string SessionKey(const httplib::Request& req);
  std::shared_ptr<void> TakeStream(const std::string& session, std::string* why);
  std::shared_ptr<void> TakeExport(const std::string& session, std::string* why);

  // web/gateway.cc
  // The client as this request's caller: its Authorization header forwarded as it came (none: no credentials,
  // the service answers UNAUTHENTICATED), the deadline, and the service's status of each call kept in *rpc.
  client::Client As(const httplib::Request& req, double deadline_s, grpc::Status* rpc) const;
  void Benches(const httplib::Request& req, httplib::Response& res);
  void Queue(const httplib::Request& req, httplib::Response& res);
  void ListRuns(const httplib::Request& req, httplib::Response& res);
  void Submit(const httplib::Request& req, httplib::Response& res);
  void SubmitAndReply(const httplib::Request& req, httplib::Response& res, const valvebench::v1::ExperimentSpec& spec,
                      const std::string& batch_name);
  // GetRun as this request's caller; false with the error answered.
  bool FetchRun(const httplib::Request& req, httplib::Response& res, std::int64_t id, valvebench::v1::Run* run);
  void GetRun(const httplib::Request& req, httplib::Response& res);
  void Cancel(const httplib::Request& req, httplib::Response& res);
  void Rerun(const httplib::Request& req, httplib::Response& res);
  void TraceRows(const httplib::Request& req, httplib::Response& res);
  void TraceCsv(const httplib::Request& req, httplib::Response& res);
  void Events(const httplib::Request& req, httplib::Response& res);
  void Diagnose(const httplib::Request& req, httplib::Response& res);
  bool FetchComparison(const httplib::Request& req, httplib::Response& res, valvebench::v1::CompareRunsResponse* out,
                       long long* batch);
  void Compare(const httplib::Request& req, httplib::Response& res);
  void Units(const httplib::Request& req, httplib::Response& res);
  void TraceFile(const httplib::Request& req, httplib::Response& res);
  void CompareFile(const httplib::Request& req, httplib::Response& res);
  void BatchReport(const httplib::Request& req, httplib::Response& res);
  void Import(const httplib::Request& req, httplib::Response& res);
  void Nights(const httplib::Request& req, httplib::Response& res);
  void Health(const httplib::Request& req, httplib::Response& res);

  static constexpr int kMaxExports = 2;
  static constexpr int kMaxExportsPerSession = 1;

  client::Client client_;
  SessionStore sessions_;
  FailedAttempts logins_;  // common/failed_attempts.h
  std::mutex streams_mu_;
  int streams_ = 0;
  std::map<std::string, int> streams_per_session_;
  int exports_ = 0;
  std::map<std::string, int> exports_per_session_;
  GatewayOptions options_;
  bool tls_;
  std::size_t max_body_bytes_;
};

}  // namespace vb::web
