// How the service goes on a grpc::Server, the one way for every host of it (service/host.h): valvebench-server
// (server/main.cc, which adds its listening port, TLS, health and reflection) and a local service
// (service/local_service.cc, no port). Same message limits, same interceptors, so a call behaves the same
// whichever host answers it.
#pragma once

#include <grpcpp/grpcpp.h>

#include "service/service.h"

namespace vb::server {

// The largest message either way: a trace page or an import of measured runs.
inline constexpr int kMaxMessageBytes = 64 << 20;

// Registers `service` on `builder` with the message limits, the status interceptor
// (service/status_interceptor.h) and the service's call gate, which authorises every call from one
// method-to-role table (service/authorization.h). The builder must not outlive `service`.
void HostService(grpc::ServerBuilder* builder, BenchServiceImpl* service);

// Channel arguments for an in-process channel to a hosted service (the web door, benchctl --local).
grpc::ChannelArguments InProcessChannelArguments();

}  // namespace vb::server
