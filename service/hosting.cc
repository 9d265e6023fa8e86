#include "service/hosting.h"

#include <memory>
#include <vector>

#include "service/status_interceptor.h"

namespace vb::server {

void HostService(grpc::ServerBuilder* builder, BenchServiceImpl* service) {
  builder->RegisterService(service);
  builder->SetMaxReceiveMessageSize(kMaxMessageBytes);
  builder->SetMaxSendMessageSize(kMaxMessageBytes);
  std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> interceptors;
  interceptors.push_back(std::make_unique<BadRequestInterceptorFactory>());
  interceptors.push_back(service->gate()->InterceptorFactory());  // who may call what (service/authorization.h)
  builder->experimental().SetInterceptorCreators(std::move(interceptors));
}

grpc::ChannelArguments InProcessChannelArguments() {
  grpc::ChannelArguments args;
  args.SetMaxReceiveMessageSize(kMaxMessageBytes);
  args.SetMaxSendMessageSize(kMaxMessageBytes);
  return args;
}

}  // namespace vb::server
