// Who may call what (issue 40): one table of BenchService's methods and the least role each needs, applied once
// per call by a server interceptor before the handler runs; the handlers hold no role of their own.
//
// gRPC 1.51's server interceptors cannot end a call (no Hijack on the server side), so the decision and its
// enforcement are split: the interceptor (POST_RECV_INITIAL_METADATA) authenticates the caller, applies the
// failure limit per address (common/failed_attempts.h) and the table, and records the verdict on the call; the
// handler's first line asks for it (CallGate::Caller) and returns the refusal as it is. A handler that forgets to
// ask cannot pass silently: its OK answer is replaced by INTERNAL naming the method (PRE_SEND_STATUS), so any
// test that calls it fails. A BenchService method missing from the table is refused to everyone.
//
// Statuses, unchanged from the per-handler checks they replace (docs/server.md, "Status codes"):
//   an address past the failure limit: RESOURCE_EXHAUSTED "too many failed authentications from ADDR ..."
//   no or an unknown token: UNAUTHENTICATED ("not authenticated" in the client's wording)
//   a role below the table's: PERMISSION_DENIED "user U (viewer) needs the operator role for this call"
#pragma once

#include <grpcpp/server_context.h>
#include <grpcpp/support/server_interceptor.h>
#include <grpcpp/support/status.h>
#include <grpcpp/support/string_ref.h>

#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <unordered_map>

#include "common/failed_attempts.h"
#include "service/auth.h"

namespace vb::server {

// One row of the table: a method of valvebench.v1.BenchService by its name ("SubmitRun") and the least role
// that may call it.
struct MethodRole {
  std::string_view method;
  Role role;
};

// The table, one row per method of the service (a test checks it against the service's descriptor).
std::span<const MethodRole> MethodRoles();
// The role a call to `full_method` ("/valvebench.v1.BenchService/SubmitRun") needs; nullopt for a method of
// BenchService that the table does not name (refused to everyone) and for other services' methods.
std::optional<Role> RequiredRole(std::string_view full_method);
// Whether `full_method` is a method of BenchService (other services on the server, health and reflection, are
// not the gate's: they take no token).
bool IsBenchServiceMethod(std::string_view full_method);

// The verdicts of the calls in progress, written by the interceptor, read by the handlers.
class CallGate {
 public:
  explicit CallGate(const Authenticator* auth) : auth_(auth) {}
  CallGate(const CallGate&) = delete;
  CallGate& operator=(const CallGate&) = delete;

  // The handler's first step: the caller the interceptor admitted (into *who), or the status that refuses the
  // call. A call the gate did not decide (the service hosted without its interceptor) is refused with INTERNAL.
  grpc::Status Caller(const grpc::ServerContextBase* ctx, Principal* who) const;

  // For HostService (service/hosting.h): the interceptor that decides each call.
  std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> InterceptorFactory();

  // The interceptor's steps (public for it; nothing else calls them).
  using Metadata = std::multimap<grpc::string_ref, grpc::string_ref>;
  void Decide(const grpc::ServerContextBase* ctx, std::string_view full_method, const Metadata& metadata,
              const std::string& peer);
  // Whether the handler asked (Caller) for the call's verdict; forgets the call.
  bool Forget(const grpc::ServerContextBase* ctx);

 private:
  struct Verdict {
    grpc::Status status;
    Principal who;
    bool asked = false;
  };
  grpc::Status Judge(std::string_view full_method, const Metadata& metadata, const std::string& peer,
                     Principal* who);

  const Authenticator* auth_;
  mutable std::mutex mu_;
  mutable std::unordered_map<const grpc::ServerContextBase*, Verdict> verdicts_;
  // Failed authentications per client address: the same limit as the web's, so that gRPC is no unlimited,
  // unlogged oracle for guessing tokens (issue 34).
  FailedAttempts failures_;
};

}  // namespace vb::server
