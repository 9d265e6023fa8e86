// The web gateway's request handling (web/gateway.h, docs/web.md "Door") as an attacker reaches it: the input is
// the bytes of one HTTP connection (request lines, headers, query strings, bodies, chunked or not, several
// requests kept alive), parsed by cpp-httplib and routed by the gateway, whose calls go to a small in-process
// BenchService (canned answers; a call whose token is not "good" is UNAUTHENTICATED), so that whatever the
// gateway would put into gRPC metadata or protobuf really goes through gRPC. Nothing may crash, abort, throw out
// of a handler or hang, whatever the bytes (issue 24: a TAB in a token aborted gRPC, a %ff path threw in the 404
// handler, a deep JSON body overflowed the stack).
#include <grpcpp/grpcpp.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <string>

#include "valvebench/v1/api.grpc.pb.h"
#include "web/gateway.h"
#include "web/head.h"

namespace {

namespace v1 = valvebench::v1;

bool TokenOk(grpc::ServerContext* ctx) {
  const auto& md = ctx->client_metadata();
  auto it = md.find("authorization");
  return it != md.end() && std::string(it->second.data(), it->second.size()) == "Bearer good";
}

class FakeService final : public v1::BenchService::Service {
  grpc::Status ListBenches(grpc::ServerContext* ctx, const v1::ListBenchesRequest*,
                           v1::ListBenchesResponse* out) override {
    if (!TokenOk(ctx)) return {grpc::StatusCode::UNAUTHENTICATED, "no token"};
    out->add_benches()->set_name("emu");
    return grpc::Status::OK;
  }
  grpc::Status GetRun(grpc::ServerContext* ctx, const v1::GetRunRequest* r, v1::Run* out) override {
    if (!TokenOk(ctx)) return {grpc::StatusCode::UNAUTHENTICATED, "no token"};
    if (r->run_id() != 1) return {grpc::StatusCode::NOT_FOUND, "no such run"};
    out->set_id(1);
    out->set_status(v1::DONE);
    (*out->mutable_metrics())["rmse"] = 0.01;
    return grpc::Status::OK;
  }
  grpc::Status ListRuns(grpc::ServerContext* ctx, const v1::ListRunsRequest*, v1::ListRunsResponse* out) override {
    if (!TokenOk(ctx)) return {grpc::StatusCode::UNAUTHENTICATED, "no token"};
    out->add_runs()->set_id(1);
    return grpc::Status::OK;
  }
  grpc::Status SubmitRun(grpc::ServerContext* ctx, const v1::SubmitRunRequest*, v1::SubmitRunResponse* out) override {
    if (!TokenOk(ctx)) return {grpc::StatusCode::UNAUTHENTICATED, "no token"};
    out->add_run_ids(2);
    return grpc::Status::OK;
  }
  grpc::Status CancelRun(grpc::ServerContext* ctx, const v1::CancelRunRequest* r, v1::Run* out) override {
    if (!TokenOk(ctx)) return {grpc::StatusCode::UNAUTHENTICATED, "no token"};
    out->set_id(r->run_id());
    out->set_reason(r->reason());
    return grpc::Status::OK;
  }
  grpc::Status WatchRun(grpc::ServerContext* ctx, const v1::WatchRunRequest*,
                        grpc::ServerWriter<v1::RunEvent>* w) override {
    if (!TokenOk(ctx)) return {grpc::StatusCode::UNAUTHENTICATED, "no token"};
    v1::RunEvent ev;
    ev.set_run_id(1);
    ev.set_status(v1::DONE);
    ev.add_samples()->set_i_a(0.5);
    w->Write(ev);
    return grpc::Status::OK;
  }
  grpc::Status GetTrace(grpc::ServerContext* ctx, const v1::GetTraceRequest*,
                        grpc::ServerWriter<v1::TraceChunk>* w) override {
    if (!TokenOk(ctx)) return {grpc::StatusCode::UNAUTHENTICATED, "no token"};
    v1::TraceChunk c;
    c.set_sample_period_s(1e-3);
    c.set_samples(4);
    c.set_total_samples(4);
    c.add_channels("t_s");
    c.add_channels("i_A");
    std::string data(4 * 2 * 8, '\0');
    for (int k = 0; k < 8; ++k) {
      const double v = k * 0.1;
      std::memcpy(data.data() + k * 8, &v, 8);
    }
    c.set_data(data);
    w->Write(c);
    return grpc::Status::OK;
  }
};

struct World {
  FakeService service;
  std::unique_ptr<grpc::Server> server;
  std::unique_ptr<vb::web::RawGateway> gateway;
  World() {
    grpc::ServerBuilder b;
    b.RegisterService(&service);
    server = b.BuildAndStart();
    grpc::ChannelArguments args;
    vb::web::GatewayOptions o;
    o.limits.max_body_bytes = 64 << 10;
    gateway = std::make_unique<vb::web::RawGateway>(server->InProcessChannel(args), o);
  }
};

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static World* world = new World();  // lives for the process: the gRPC server is costly to start
  std::string raw(reinterpret_cast<const char*>(data), size);
  // The door's head check first, as a socket's bytes meet it (web/head.h): it must not crash, must keep the
  // bytes after the head as they were, and what it passes on goes to cpp-httplib and the routes.
  size_t skip = 0;  // empty lines before the request line, which FilterHead drops
  while (raw.compare(skip, 2, "\r\n") == 0) skip += 2;
  if (const size_t end = raw.find("\r\n\r\n", skip); end != std::string::npos) {
    std::string head = raw;
    const vb::web::HeadVerdict v = vb::web::FilterHead(&head);
    if (v.status == 0) {
      const std::string after = raw.substr(end + 4);
      if (head.size() < after.size() || head.compare(head.size() - after.size(), after.size(), after) != 0)
        __builtin_trap();  // the bytes after the head were changed
      raw = head;
    } else if (v.status != 400) {
      __builtin_trap();
    }
  }
  (void)world->gateway->Serve(raw);
  return 0;
}
