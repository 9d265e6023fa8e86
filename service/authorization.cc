#include "service/authorization.h"

#include <spdlog/spdlog.h>

#include <array>
#include <cmath>

#include "service/grpc_status.h"

namespace vb::server {
namespace {

using grpc::experimental::InterceptionHookPoints;

constexpr std::string_view kServicePrefix = "/valvebench.v1.BenchService/";

// viewer: reads everything; operator: submits, imports, cancels its own runs (CancelRun checks ownership: that
// is the run's data, not the method's), saves baselines and regression results; admin: prunes the store.
constexpr std::array kTable = {
    MethodRole{"SubmitRun", Role::kOperator},      MethodRole{"SubmitBatch", Role::kOperator},
    MethodRole{"GetRun", Role::kViewer},           MethodRole{"ListRuns", Role::kViewer},
    MethodRole{"GetQueue", Role::kViewer},         MethodRole{"CancelRun", Role::kOperator},
    MethodRole{"WatchRun", Role::kViewer},         MethodRole{"GetTrace", Role::kViewer},
    MethodRole{"CompareRuns", Role::kViewer},      MethodRole{"ListBenches", Role::kViewer},
    MethodRole{"ImportRuns", Role::kOperator},     MethodRole{"ImportRunsStream", Role::kOperator},
    MethodRole{"ListNights", Role::kViewer},       MethodRole{"GetBenchHealth", Role::kViewer},
    MethodRole{"DiagnoseRuns", Role::kViewer},     MethodRole{"PruneRuns", Role::kAdmin},
    // Records besides runs (service/records_service.cc). Reads are the viewer's, as every read above.
    // Saving a baseline or a regression result adds to the store's shared history the way a submission adds
    // runs, and it is what `benchctl baseline set`/`regress` do right after submitting a suite: the operator's
    // role, not the admin's (who prunes). Nothing here deletes or overwrites (a baseline only gains versions).
    // DescribeStore only counts: the viewer's.
    MethodRole{"SaveBaseline", Role::kOperator},   MethodRole{"GetBaseline", Role::kViewer},
    MethodRole{"ListBaselines", Role::kViewer},    MethodRole{"SaveRegression", Role::kOperator},
    MethodRole{"GetRegression", Role::kViewer},    MethodRole{"DescribeStore", Role::kViewer},
};

class AuthInterceptor final : public grpc::experimental::Interceptor {
 public:
  AuthInterceptor(CallGate* gate, grpc::experimental::ServerRpcInfo* info)
      : gate_(gate), ctx_(info->server_context()), method_(info->method() != nullptr ? info->method() : "") {}
  ~AuthInterceptor() override {
    if (decided_) gate_->Forget(ctx_);
  }

  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(InterceptionHookPoints::POST_RECV_INITIAL_METADATA)) {
      const auto* md = methods->GetRecvInitialMetadata();
      static const CallGate::Metadata kNone;
      gate_->Decide(ctx_, method_, md != nullptr ? *md : kNone, ctx_->peer());
      decided_ = true;
    }
    if (methods->QueryInterceptionHookPoint(InterceptionHookPoints::PRE_SEND_STATUS) && decided_) {
      const bool asked = gate_->Forget(ctx_);
      decided_ = false;
      if (!asked && methods->GetSendStatus().ok()) {
        spdlog::error("grpc: the handler of {} did not ask the call gate who its caller is", method_);
        methods->ModifySendStatus(grpc::Status(
            grpc::StatusCode::INTERNAL, method_ + ": the handler did not check its caller (service/authorization.h)"));
      }
    }
    methods->Proceed();
  }

 private:
  CallGate* gate_;
  grpc::ServerContextBase* ctx_;
  std::string method_;
  bool decided_ = false;
};

class AuthInterceptorFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  explicit AuthInterceptorFactory(CallGate* gate) : gate_(gate) {}
  grpc::experimental::Interceptor* CreateServerInterceptor(grpc::experimental::ServerRpcInfo* info) override {
    if (info->method() == nullptr || !IsBenchServiceMethod(info->method())) return nullptr;  // health, reflection
    return new AuthInterceptor(gate_, info);
  }

 private:
  CallGate* gate_;
};

}  // namespace

std::span<const MethodRole> MethodRoles() { return kTable; }

bool IsBenchServiceMethod(std::string_view full_method) {
  return full_method.substr(0, kServicePrefix.size()) == kServicePrefix;
}

std::optional<Role> RequiredRole(std::string_view full_method) {
  if (!IsBenchServiceMethod(full_method)) return std::nullopt;
  const std::string_view name = full_method.substr(kServicePrefix.size());
  for (const MethodRole& row : kTable)
    if (row.method == name) return row.role;
  return std::nullopt;
}

grpc::Status CallGate::Judge(std::string_view full_method, const Metadata& md, const std::string& peer,
                             Principal* who) {
  // An address past the failure limit is refused whatever it sends (a good token too: a scanner must not learn
  // which of its guesses was right by the answer changing). In-process peers (the web door, which limits by the
  // real client's address, and benchctl --local) have no address here and are not limited.
  const std::string client = ClientAddressOfPeer(peer);
  if (!client.empty()) {
    if (const double wait_s = failures_.Blocked_s(client); wait_s > 0)
      return grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                          "too many failed authentications from " + client + "; try again in " +
                              std::to_string(static_cast<int>(std::ceil(wait_s))) + " s");
  }
  auto it = md.find("authorization");
  if (it == md.end()) return Unauthenticated(Status::FailedPrecondition("missing authorization metadata"));
  auto p = auth_->Authenticate(std::string_view(it->second.data(), it->second.size()));
  if (!p.ok()) {
    if (!client.empty()) {
      failures_.Failed(client);
      spdlog::warn("grpc: failed authentication from {}: {}", client, p.status().message());
    }
    return Unauthenticated(p.status());
  }
  const std::optional<Role> need = RequiredRole(full_method);
  if (!need)
    return PermissionDenied(std::string(full_method) + " is not in the service's method-to-role table "
                            "(service/authorization.cc): nobody may call it");
  if (!p->AtLeast(*need))
    return PermissionDenied("user " + p->user + " (" + RoleName(p->role) + ") needs the " + RoleName(*need) +
                            " role for this call");
  *who = *p;
  return grpc::Status::OK;
}

void CallGate::Decide(const grpc::ServerContextBase* ctx, std::string_view full_method, const Metadata& md,
                      const std::string& peer) {
  Verdict v;
  v.status = Judge(full_method, md, peer, &v.who);
  std::lock_guard<std::mutex> lock(mu_);
  verdicts_[ctx] = std::move(v);
}

bool CallGate::Forget(const grpc::ServerContextBase* ctx) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = verdicts_.find(ctx);
  if (it == verdicts_.end()) return false;
  const bool asked = it->second.asked;
  verdicts_.erase(it);
  return asked;
}

grpc::Status CallGate::Caller(const grpc::ServerContextBase* ctx, Principal* who) const {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = verdicts_.find(ctx);
  if (it == verdicts_.end())
    return grpc::Status(grpc::StatusCode::INTERNAL,
                        "the call was not decided by the service's interceptor (hosted without HostService?)");
  it->second.asked = true;
  if (!it->second.status.ok()) return it->second.status;
  *who = it->second.who;
  return grpc::Status::OK;
}

std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> CallGate::InterceptorFactory() {
  return std::make_unique<AuthInterceptorFactory>(this);
}

}  // namespace vb::server
