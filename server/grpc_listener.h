// gRPC's TCP port, accepted here and handed to gRPC (issue 34, docs/server.md "Limits under hostile load").
//
// gRPC 1.51's own accept loop gives up for good at its first EMFILE (1,100 idle connections on a soft limit of
// 1,024 and the server never answered again), and it has no cap on connections: idle TCP connections that never
// speak are closed only by the 10 s handshake timeout, so a client that opens them faster than that reaches any
// file limit. This listener binds the port itself (no SO_REUSEPORT: a second server must fail to bind), accepts
// on a thread of its own and gives each connection to the server through gRPC's ExternalConnectionAcceptor, so:
//  - connections are capped per client address (beyond, the new connection is closed at once) and in all: at the
//    total cap, the newest connection of the address holding the most is shut down to make room (one address's
//    flood cannot lock the others out), unless the newcomer is that address;
//  - running out of descriptors (EMFILE/ENFILE) is survived: a descriptor kept in reserve is released to accept
//    and close the waiting connection (its client sees a close, not a hang), then taken again, and the loop goes
//    on after a pause (the classic reserve-descriptor guard, as in libev's and nginx's accept loops).
// gRPC does not say when it closes a connection, so the count is kept by (descriptor, inode) pairs checked with
// fstat when a cap is reached: a closed connection's descriptor is gone or names another file.
#pragma once

#include <grpcpp/grpcpp.h>
#include <grpcpp/server_builder.h>

#include <atomic>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "common/status.h"

namespace vb::server {

struct GrpcListenerLimits {
  int max_connections = 4096;            // gRPC connections open at once (with the web's 512 and the store's 128,
                                         // far below the unit's LimitNOFILE=65536)
  int max_connections_per_client = 256;  // from one address (a benchctl or a Python client uses one)
};

class GrpcListener {
 public:
  // Binds `address` ("host:port", "[v6]:port", "0.0.0.0:port"; port 0 is any free port) on every address the
  // host resolves to, with the same port. Unavailable names the address and why.
  static StatusOr<std::unique_ptr<GrpcListener>> Bind(const std::string& address, GrpcListenerLimits limits = {});
  ~GrpcListener();
  GrpcListener(const GrpcListener&) = delete;
  GrpcListener& operator=(const GrpcListener&) = delete;

  int port() const { return port_; }
  // Starts accepting; `acceptor` comes from ServerBuilder::experimental().AddExternalConnectionAcceptor and is
  // used once the server has started.
  void Start(std::shared_ptr<grpc::experimental::ExternalConnectionAcceptor> acceptor);
  // Stops accepting and closes the listening sockets (open connections stay gRPC's).
  void Stop();

  struct Counts {
    long accepted = 0;
    long refused_total_cap = 0;   // closed at once: max_connections open
    long refused_client_cap = 0;  // closed at once: max_connections_per_client open from that address
    long shed = 0;                // shut down to make room at the total cap (the largest address's newest)
    long out_of_files = 0;        // accept failed for lack of descriptors (EMFILE/ENFILE)
    int open = 0;                 // as of the last count
  };
  Counts counts() const;

 private:
  GrpcListener(std::vector<int> fds, int port, GrpcListenerLimits limits);
  void Loop();
  void AcceptFrom(int listen_fd);
  // Drops the connections gRPC has closed since the last sweep.
  void Sweep();
  // At the total cap: shuts down the newest connection of the address holding the most (not `client`'s); false
  // when there is none to shed.
  bool ShedFromTheLargest(const std::string& client);
  void Pause(int ms);

  struct Tracked {
    int fd;
    unsigned long inode;
    std::string client;
  };
  std::vector<int> listen_fds_;
  int port_;
  GrpcListenerLimits limits_;
  int wake_[2] = {-1, -1};
  int reserve_fd_ = -1;
  std::shared_ptr<grpc::experimental::ExternalConnectionAcceptor> acceptor_;
  std::thread thread_;
  std::atomic<bool> stopping_{false};
  // The accept thread's own; counts_ under mu_ for counts().
  std::vector<Tracked> tracked_;
  std::map<std::string, int> per_client_;
  long since_sweep_ = 0;
  mutable std::mutex mu_;
  Counts counts_;
};

}  // namespace vb::server
