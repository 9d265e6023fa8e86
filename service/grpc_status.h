// The service's gRPC statuses: core errors through the one mapping (proto/grpc_status.h, ToGrpcStatus: nothing
// leaves a handler as UNKNOWN), and the two the core has no code for.
#pragma once

#include <grpcpp/support/status.h>

#include "common/status.h"
#include "proto/grpc_status.h"

namespace vb::server {

inline grpc::Status Unauthenticated(const Status& st) {
  return grpc::Status(grpc::StatusCode::UNAUTHENTICATED, st.message());
}
inline grpc::Status PermissionDenied(const std::string& msg) {
  return grpc::Status(grpc::StatusCode::PERMISSION_DENIED, msg);
}

}  // namespace vb::server
