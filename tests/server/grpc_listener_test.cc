// The gRPC listener's caps (server/grpc_listener.h, issue 34): per client address, and at the total cap the
// newest connection of the address holding the most is shut down to make room for another address. A gRPC
// server with only its health service (and BenchService unimplemented), on loopback; connections from 127.0.0.x source addresses.
#include "server/grpc_listener.h"

#include <arpa/inet.h>
#include <gtest/gtest.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <thread>
#include <vector>

#include "valvebench/v1/api.grpc.pb.h"

namespace vb::server {
namespace {

int ConnectFrom(const char* from, int port) {
  const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
  sockaddr_in a{};
  a.sin_family = AF_INET;
  inet_pton(AF_INET, from, &a.sin_addr);
  sockaddr_in to{};
  to.sin_family = AF_INET;
  to.sin_port = htons(static_cast<uint16_t>(port));
  to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  if (::bind(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) != 0 ||
      ::connect(fd, reinterpret_cast<sockaddr*>(&to), sizeof(to)) != 0) {
    ::close(fd);
    return -1;
  }
  return fd;
}

// True when the peer has closed (or shut down) the connection within `ms`; what it sent first (gRPC's SETTINGS)
// is read and dropped.
bool ClosedWithin(int fd, int ms) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::milliseconds(ms);
  for (;;) {
    const auto left =
        std::chrono::duration_cast<std::chrono::milliseconds>(until - std::chrono::steady_clock::now()).count();
    pollfd p{fd, POLLIN, 0};
    if (poll(&p, 1, static_cast<int>(std::max<long>(0, left))) <= 0) return false;
    char buf[4096];
    const ssize_t n = ::recv(fd, buf, sizeof(buf), MSG_DONTWAIT);
    if (n == 0) return true;
    if (n < 0) return errno != EAGAIN && errno != EWOULDBLOCK;
  }
}

bool WaitFor(const std::function<bool()>& done) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (!done()) {
    if (std::chrono::steady_clock::now() > until) return false;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return true;
}

// A health Check through gRPC's generic stub: true when the server answers.
bool HealthAnswers(int port) {
  auto channel = grpc::CreateChannel("127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  grpc::ByteBuffer request, response;
  grpc::Slice empty("");
  request = grpc::ByteBuffer(&empty, 1);
  std::mutex mu;
  std::condition_variable cv;
  bool done = false;
  grpc::Status status;
  stub.UnaryCall(&ctx, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &request, &response,
                 [&](grpc::Status s) {
                   std::lock_guard<std::mutex> lock(mu);
                   status = s;
                   done = true;
                   cv.notify_all();
                 });
  std::unique_lock<std::mutex> lock(mu);
  cv.wait(lock, [&] { return done; });
  return status.ok();
}

TEST(GrpcListener, CapsPerAddressAndShedsTheLargestAddressAtTheTotalCap) {
  auto bound = GrpcListener::Bind("127.0.0.1:0", GrpcListenerLimits{6, 4});
  ASSERT_TRUE(bound.ok()) << bound.status().message();
  std::unique_ptr<GrpcListener> listener = std::move(*bound);
  ASSERT_GT(listener->port(), 0);
  grpc::EnableDefaultHealthCheckService(true);
  grpc::ServerBuilder builder;
  valvebench::v1::BenchService::Service unimplemented;  // a synchronous service, so the health service is one too
  builder.RegisterService(&unimplemented);
  std::shared_ptr<grpc::experimental::ExternalConnectionAcceptor> acceptor =
      builder.experimental().AddExternalConnectionAcceptor(
          grpc::ServerBuilder::experimental_type::ExternalConnectionType::FROM_FD, grpc::InsecureServerCredentials());
  std::unique_ptr<grpc::Server> server = builder.BuildAndStart();
  ASSERT_NE(server, nullptr);
  listener->Start(acceptor);
  const int port = listener->port();

  std::vector<int> flood;  // 127.0.0.2: its four, then a fifth
  for (int k = 0; k < 4; ++k) flood.push_back(ConnectFrom("127.0.0.2", port));
  ASSERT_TRUE(WaitFor([&] { return listener->counts().accepted == 4; }));
  const int fifth = ConnectFrom("127.0.0.2", port);
  EXPECT_TRUE(ClosedWithin(fifth, 2000)) << "the fifth connection from one address is closed at once";
  EXPECT_EQ(listener->counts().refused_client_cap, 1);
  ::close(fifth);

  std::vector<int> other = {ConnectFrom("127.0.0.3", port), ConnectFrom("127.0.0.3", port)};
  ASSERT_TRUE(WaitFor([&] { return listener->counts().accepted == 6; }));
  EXPECT_EQ(listener->counts().open, 6);

  // The total cap is reached: a client of another address gets in, one of 127.0.0.2's is shut down.
  EXPECT_TRUE(HealthAnswers(port));
  EXPECT_GE(listener->counts().shed, 1);
  int ended = 0;
  for (int fd : flood) ended += ClosedWithin(fd, 1000) ? 1 : 0;
  EXPECT_GE(ended, 1) << "the largest address's newest connection was shut down";
  for (int fd : other) EXPECT_FALSE(ClosedWithin(fd, 0)) << "the smaller address keeps its connections";
  EXPECT_EQ(listener->counts().refused_total_cap, 0);

  listener->Stop();
  server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(1));
  for (int fd : flood) ::close(fd);
  for (int fd : other) ::close(fd);
}

TEST(GrpcListener, BindNamesTheAddressAndRefusesAHeldPort) {
  auto first = GrpcListener::Bind("127.0.0.1:0");
  ASSERT_TRUE(first.ok());
  auto second = GrpcListener::Bind("127.0.0.1:" + std::to_string((*first)->port()));
  ASSERT_FALSE(second.ok());
  EXPECT_NE(second.status().message().find("cannot listen on 127.0.0.1:"), std::string::npos)
      << second.status().message();
  EXPECT_FALSE(GrpcListener::Bind("127.0.0.1").ok());
  EXPECT_FALSE(GrpcListener::Bind("127.0.0.1:99999").ok());
}

}  // namespace
}  // namespace vb::server
