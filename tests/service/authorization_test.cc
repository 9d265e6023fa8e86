// Who may call what (service/authorization.h): the method-to-role table against the service's descriptor, the
// gate's verdicts, and every method of a hosted BenchService called anonymously and with each role.
#include <google/protobuf/descriptor.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <set>
#include <string>

#include "service/authorization.h"
#include "service/hosting.h"
#include "service/service.h"

namespace vb::server {
namespace {

namespace v1 = valvebench::v1;

const google::protobuf::ServiceDescriptor* BenchServiceDescriptor() {
  return google::protobuf::DescriptorPool::generated_pool()->FindServiceByName("valvebench.v1.BenchService");
}

std::string FullMethod(const google::protobuf::MethodDescriptor* m) {
  return "/" + m->service()->full_name() + "/" + m->name();
}

constexpr const char* kViewer = "viewer-secret";
constexpr const char* kOperator = "operator-secret";
constexpr const char* kAdmin = "admin-secret";

Authenticator ThreeRoles() {
  google::protobuf::RepeatedPtrField<v1::TokenConfig> tokens;
  for (const auto& [user, role, token] :
       {std::tuple{"vera", "viewer", kViewer}, std::tuple{"olga", "operator", kOperator},
        std::tuple{"ada", "admin", kAdmin}}) {
    auto* t = tokens.Add();
    t->set_user(user);
    t->set_role(role);
    t->set_token_sha256(Sha256Hex(token));
  }
  auto a = Authenticator::Create(tokens);
  EXPECT_TRUE(a.ok()) << a.status().message();
  return std::move(*a);
}

// Every method of the service has a row, and every row a method: a new RPC cannot go unclassified, and a
// removed one leaves no stale row.
TEST(Authorization, TheTableNamesEveryMethodOfTheServiceOnce) {
  const auto* service = BenchServiceDescriptor();
  ASSERT_NE(service, nullptr);
  std::set<std::string> rows;
  for (const MethodRole& row : MethodRoles()) {
    EXPECT_TRUE(rows.insert(std::string(row.method)).second) << row.method << " appears twice";
    EXPECT_NE(service->FindMethodByName(std::string(row.method)), nullptr) << row.method << " is no method";
  }
  for (int k = 0; k < service->method_count(); ++k)
    EXPECT_TRUE(RequiredRole(FullMethod(service->method(k))).has_value()) << service->method(k)->name();
  EXPECT_EQ(static_cast<int>(rows.size()), service->method_count());
  EXPECT_EQ(RequiredRole("/valvebench.v1.BenchService/SubmitRun"), Role::kOperator);
  EXPECT_EQ(RequiredRole("/valvebench.v1.BenchService/PruneRuns"), Role::kAdmin);
  EXPECT_EQ(RequiredRole("/valvebench.v1.BenchService/GetTrace"), Role::kViewer);
  EXPECT_FALSE(RequiredRole("/valvebench.v1.BenchService/Shutdown").has_value());
  EXPECT_FALSE(RequiredRole("/grpc.health.v1.Health/Check").has_value());
  EXPECT_FALSE(IsBenchServiceMethod("/grpc.health.v1.Health/Check"));
}

CallGate::Metadata Bearer(const std::string& header) {
  CallGate::Metadata md;
  md.emplace("authorization", header);  // string_refs into `header`: the caller keeps it alive
  return md;
}

// The gate's verdicts, without a server: roles against the table, a method the table does not name, a call it
// never decided, and whether the handler asked.
TEST(Authorization, TheGateDecidesByTheTable) {
  const Authenticator auth = ThreeRoles();
  CallGate gate(&auth);
  grpc::ServerContext a, b, c, d, never;
  const std::string viewer = std::string("Bearer ") + kViewer, admin = std::string("Bearer ") + kAdmin;
  gate.Decide(&a, "/valvebench.v1.BenchService/ListRuns", Bearer(viewer), "inproc");
  gate.Decide(&b, "/valvebench.v1.BenchService/SubmitRun", Bearer(viewer), "inproc");
  gate.Decide(&c, "/valvebench.v1.BenchService/Shutdown", Bearer(admin), "inproc");
  gate.Decide(&d, "/valvebench.v1.BenchService/PruneRuns", Bearer(admin), "inproc");
  Principal who;
  EXPECT_TRUE(gate.Caller(&a, &who).ok());
  EXPECT_EQ(who.user, "vera");
  auto denied = gate.Caller(&b, &who);
  EXPECT_EQ(denied.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(denied.error_message(), "user vera (viewer) needs the operator role for this call");
  auto unknown = gate.Caller(&c, &who);
  EXPECT_EQ(unknown.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_NE(unknown.error_message().find("not in the service's method-to-role table"), std::string::npos);
  EXPECT_EQ(gate.Caller(&never, &who).error_code(), grpc::StatusCode::INTERNAL);
  EXPECT_TRUE(gate.Forget(&a)) << "the handler asked";
  EXPECT_FALSE(gate.Forget(&d)) << "the handler did not ask";
  EXPECT_FALSE(gate.Forget(&a)) << "forgotten";
}

// kMax failed tokens from one address, then that address is refused even with a good token; an in-process
// peer (no address) is never limited, and another address is not affected.
TEST(Authorization, FailedTokensAreLimitedPerAddressNotInProcess) {
  const Authenticator auth = ThreeRoles();
  CallGate gate(&auth);
  const std::string bad = "Bearer guess", good = std::string("Bearer ") + kViewer;
  Principal who;
  for (int k = 0; k < FailedAttempts::kMax; ++k) {
    grpc::ServerContext ctx;
    gate.Decide(&ctx, "/valvebench.v1.BenchService/ListRuns", Bearer(bad), "ipv4:10.0.0.7:4000");
    EXPECT_EQ(gate.Caller(&ctx, &who).error_code(), grpc::StatusCode::UNAUTHENTICATED);
    gate.Forget(&ctx);
    grpc::ServerContext local;
    gate.Decide(&local, "/valvebench.v1.BenchService/ListRuns", Bearer(bad), "inproc");
    EXPECT_EQ(gate.Caller(&local, &who).error_code(), grpc::StatusCode::UNAUTHENTICATED);
    gate.Forget(&local);
  }
  grpc::ServerContext blocked, local, other;
  gate.Decide(&blocked, "/valvebench.v1.BenchService/ListRuns", Bearer(good), "ipv4:10.0.0.7:4001");
  auto st = gate.Caller(&blocked, &who);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_NE(st.error_message().find("too many failed authentications from 10.0.0.7"), std::string::npos)
      << st.error_message();
  gate.Decide(&local, "/valvebench.v1.BenchService/ListRuns", Bearer(good), "inproc");
  EXPECT_TRUE(gate.Caller(&local, &who).ok());
  gate.Decide(&other, "/valvebench.v1.BenchService/ListRuns", Bearer(good), "ipv4:10.0.0.8:4000");
  EXPECT_TRUE(gate.Caller(&other, &who).ok());
}

// One call of `method` with an empty request message, through the generic stub (every kind of method looks the
// same on the wire): its status.
grpc::Status CallEmpty(const std::shared_ptr<grpc::Channel>& channel, const std::string& method, const char* token) {
  grpc::GenericStub stub(channel);
  grpc::CompletionQueue cq;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  if (token != nullptr) ctx.AddMetadata("authorization", std::string("Bearer ") + token);
  auto call = stub.PrepareCall(&ctx, method, &cq);
  auto step = [&cq](int tag) {
    void* got = nullptr;
    bool ok = false;
    EXPECT_TRUE(cq.Next(&got, &ok));
    EXPECT_EQ(got, reinterpret_cast<void*>(static_cast<intptr_t>(tag)));
    return ok;
  };
  call->StartCall(reinterpret_cast<void*>(1));
  step(1);
  grpc::Slice empty(std::string{});
  grpc::ByteBuffer request(&empty, 1);
  call->Write(request, reinterpret_cast<void*>(2));
  step(2);
  call->WritesDone(reinterpret_cast<void*>(3));
  step(3);
  for (;;) {
    grpc::ByteBuffer response;
    call->Read(&response, reinterpret_cast<void*>(4));
    if (!step(4)) break;
  }
  grpc::Status status;
  call->Finish(&status, reinterpret_cast<void*>(5));
  step(5);
  cq.Shutdown();
  return status;
}

// The hosted service: every method, anonymous and with each role, answers as the table says; a role at or
// above the table's reaches the handler (whatever the handler then makes of an empty request). The wrong
// tokens (one per method, more than FailedAttempts::kMax in all) come in process: they are not limited, or the
// later methods' good tokens would be refused.
TEST(Authorization, EveryMethodOfTheHostedServiceFollowsTheTable) {
  const std::string dir = ::testing::TempDir() + "/vb-authz-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  ServiceSettings settings;
  settings.auth = ThreeRoles();
  StorePool pool(dir + "/runs.db");
  runs::Registry registry;
  std::vector<std::unique_ptr<runs::Worker>> workers;
  BenchServiceImpl service(&settings, &pool, &registry, &workers);
  grpc::ServerBuilder builder;
  HostService(&builder, &service);
  auto server = builder.BuildAndStart();
  ASSERT_NE(server, nullptr);
  auto channel = server->InProcessChannel(InProcessChannelArguments());

  const auto* descriptor = BenchServiceDescriptor();
  const std::pair<const char*, Role> callers[] = {{kViewer, Role::kViewer}, {kOperator, Role::kOperator},
                                                  {kAdmin, Role::kAdmin}};
  for (int k = 0; k < descriptor->method_count(); ++k) {
    const std::string method = FullMethod(descriptor->method(k));
    const Role need = *RequiredRole(method);
    auto anonymous = CallEmpty(channel, method, nullptr);
    EXPECT_EQ(anonymous.error_code(), grpc::StatusCode::UNAUTHENTICATED) << method << ": " << anonymous.error_message();
    auto stranger = CallEmpty(channel, method, "not-a-token");
    EXPECT_EQ(stranger.error_code(), grpc::StatusCode::UNAUTHENTICATED) << method << ": " << stranger.error_message();
    for (const auto& [token, role] : callers) {
      auto st = CallEmpty(channel, method, token);
      if (static_cast<int>(role) < static_cast<int>(need)) {
        EXPECT_EQ(st.error_code(), grpc::StatusCode::PERMISSION_DENIED) << method << " as " << RoleName(role);
        EXPECT_NE(st.error_message().find(std::string("needs the ") + RoleName(need) + " role"), std::string::npos)
            << method << ": " << st.error_message();
      } else {
        EXPECT_NE(st.error_code(), grpc::StatusCode::UNAUTHENTICATED) << method << ": " << st.error_message();
        EXPECT_NE(st.error_code(), grpc::StatusCode::PERMISSION_DENIED) << method << ": " << st.error_message();
        EXPECT_NE(st.error_code(), grpc::StatusCode::INTERNAL) << method << ": " << st.error_message();
      }
    }
  }
  server->Shutdown(std::chrono::system_clock::now());
  std::filesystem::remove_all(dir);
}

// A handler that forgets to ask the gate does not answer OK: its status becomes INTERNAL naming the method.
class Forgetful final : public v1::BenchService::Service {
 public:
  grpc::Status ListBenches(grpc::ServerContext*, const v1::ListBenchesRequest*, v1::ListBenchesResponse*) override {
    return grpc::Status::OK;
  }
};

TEST(Authorization, AHandlerThatDoesNotAskIsCaught) {
  const Authenticator auth = ThreeRoles();
  CallGate gate(&auth);
  Forgetful service;
  grpc::ServerBuilder builder;
  builder.RegisterService(&service);
  std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> interceptors;
  interceptors.push_back(gate.InterceptorFactory());
  builder.experimental().SetInterceptorCreators(std::move(interceptors));
  auto server = builder.BuildAndStart();
  ASSERT_NE(server, nullptr);
  auto st = CallEmpty(server->InProcessChannel(grpc::ChannelArguments()), "/valvebench.v1.BenchService/ListBenches",
                      kAdmin);
  EXPECT_EQ(st.error_code(), grpc::StatusCode::INTERNAL) << st.error_message();
  EXPECT_NE(st.error_message().find("did not check its caller"), std::string::npos) << st.error_message();
  server->Shutdown(std::chrono::system_clock::now());
}

}  // namespace
}  // namespace vb::server
