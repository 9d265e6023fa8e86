// A server interceptor that gives a request which is not a valid protobuf message a status a client can act
// on. gRPC's generated handlers answer an undecodable request with INTERNAL and an empty message (the codegen's
// GenericDeserialize), which reads as a server bug. No handler of ours returns INTERNAL without a message
// (service/grpc_status.h always carries one), so that pair at PRE_SEND_STATUS means "the request did not
// parse": it becomes INVALID_ARGUMENT naming the method (docs/server.md, "Status codes").
#pragma once

#include <grpcpp/support/server_interceptor.h>

namespace vb::server {

class BadRequestInterceptorFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  grpc::experimental::Interceptor* CreateServerInterceptor(grpc::experimental::ServerRpcInfo* info) override;
};

}  // namespace vb::server
