#include "server/grpc_listener.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netdb.h>
#include <netinet/in.h>
#include <poll.h>
#include <spdlog/spdlog.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>

namespace vb::server {
namespace {

// "1.2.3.4" or "2001:db8::1" (an IPv4 client of a dual-stack socket as its IPv4 address).
std::string ClientAddress(const sockaddr_storage& a) {
  char text[INET6_ADDRSTRLEN] = "?";
  if (a.ss_family == AF_INET) {
    inet_ntop(AF_INET, &reinterpret_cast<const sockaddr_in&>(a).sin_addr, text, sizeof(text));
  } else if (a.ss_family == AF_INET6) {
    const auto& v6 = reinterpret_cast<const sockaddr_in6&>(a);
    if (IN6_IS_ADDR_V4MAPPED(&v6.sin6_addr)) {
      inet_ntop(AF_INET, &v6.sin6_addr.s6_addr[12], text, sizeof(text));
    } else {
      inet_ntop(AF_INET6, &v6.sin6_addr, text, sizeof(text));
    }
  }
  return text;
}

unsigned long Inode(int fd) {
  struct stat st {};
  return fstat(fd, &st) == 0 ? static_cast<unsigned long>(st.st_ino) : 0;
}

}  // namespace

StatusOr<std::unique_ptr<GrpcListener>> GrpcListener::Bind(const std::string& address, GrpcListenerLimits limits) {
  const size_t colon = address.rfind(':');
  if (colon == std::string::npos)
    return Status::InvalidArgument("listen_address: '" + address + "' is not HOST:PORT");
  std::string host = address.substr(0, colon);
  const std::string port_text = address.substr(colon + 1);
  if (host.size() >= 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  char* end = nullptr;
  const long wanted = std::strtol(port_text.c_str(), &end, 10);
  if (port_text.empty() || *end != '\0' || wanted < 0 || wanted > 65535)
    return Status::InvalidArgument("listen_address: '" + address + "': the port must be 0..65535");
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE | AI_NUMERICSERV;
  addrinfo* found = nullptr;
  if (const int e = getaddrinfo(host.empty() ? nullptr : host.c_str(), port_text.c_str(), &hints, &found); e != 0)
    return Status::Unavailable("cannot listen on " + address + ": " + gai_strerror(e));
  std::vector<int> fds;
  int port = static_cast<int>(wanted);
  std::string failure;
  const bool wildcard_v6 = host == "::";
  for (addrinfo* ai = found; ai; ai = ai->ai_next) {
    const int fd = socket(ai->ai_family, SOCK_STREAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd < 0) continue;  // an address family this host lacks
    const int one = 1, zero = 0;
    (void)setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));  // a restart binds at once (TIME_WAIT)
    if (ai->ai_family == AF_INET6)  // "[::]" is both families (as gRPC binds it); otherwise each its own
      (void)setsockopt(fd, IPPROTO_IPV6, IPV6_V6ONLY, wildcard_v6 ? &zero : &one, sizeof(one));
    sockaddr_storage at{};
    std::memcpy(&at, ai->ai_addr, ai->ai_addrlen);
    if (port != 0) {  // every address on the port the first one got
      if (at.ss_family == AF_INET) reinterpret_cast<sockaddr_in&>(at).sin_port = htons(static_cast<uint16_t>(port));
      if (at.ss_family == AF_INET6) reinterpret_cast<sockaddr_in6&>(at).sin6_port = htons(static_cast<uint16_t>(port));
    }
    if (bind(fd, reinterpret_cast<sockaddr*>(&at), ai->ai_addrlen) != 0 || listen(fd, 1024) != 0) {
      const int e = errno;
      ::close(fd);
      if (e == EADDRNOTAVAIL || e == EAFNOSUPPORT) continue;  // e.g. ::1 on a host without IPv6
      failure = std::strerror(e);
      break;
    }
    if (port == 0) {
      sockaddr_storage got{};
      socklen_t len = sizeof(got);
      getsockname(fd, reinterpret_cast<sockaddr*>(&got), &len);
      port = ntohs(got.ss_family == AF_INET ? reinterpret_cast<sockaddr_in&>(got).sin_port
                                            : reinterpret_cast<sockaddr_in6&>(got).sin6_port);
    }
    fds.push_back(fd);
  }
  freeaddrinfo(found);
  if (fds.empty() || !failure.empty()) {
    for (int fd : fds) ::close(fd);
    return Status::Unavailable("cannot listen on " + address + ": " + (failure.empty() ? "no address" : failure));
  }
  return std::unique_ptr<GrpcListener>(new GrpcListener(std::move(fds), port, limits));
}

GrpcListener::GrpcListener(std::vector<int> fds, int port, GrpcListenerLimits limits)
    : listen_fds_(std::move(fds)), port_(port), limits_(limits) {
  if (pipe2(wake_, O_CLOEXEC | O_NONBLOCK) != 0) wake_[0] = wake_[1] = -1;
  reserve_fd_ = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
}

GrpcListener::~GrpcListener() {
  Stop();
  for (int fd : wake_)
    if (fd >= 0) ::close(fd);
  if (reserve_fd_ >= 0) ::close(reserve_fd_);
}

void GrpcListener::Start(std::shared_ptr<grpc::experimental::ExternalConnectionAcceptor> acceptor) {
  acceptor_ = std::move(acceptor);
  thread_ = std::thread([this] { Loop(); });
}

void GrpcListener::Stop() {
  stopping_ = true;
  if (wake_[1] >= 0) (void)!::write(wake_[1], "x", 1);
  if (thread_.joinable()) thread_.join();
  for (int fd : listen_fds_) ::close(fd);
  listen_fds_.clear();
}

GrpcListener::Counts GrpcListener::counts() const {
  std::lock_guard<std::mutex> lock(mu_);
  return counts_;
}

void GrpcListener::Pause(int ms) {
  pollfd p{wake_[0], POLLIN, 0};
  (void)poll(&p, 1, ms);
}

void GrpcListener::Loop() {
  std::vector<pollfd> fds;
  while (!stopping_) {
    fds.assign(1, pollfd{wake_[0], POLLIN, 0});
    for (int fd : listen_fds_) fds.push_back(pollfd{fd, POLLIN, 0});
    if (poll(fds.data(), fds.size(), -1) < 0 && errno != EINTR) {
      spdlog::error("grpc listener: poll failed: {}", std::strerror(errno));
      Pause(100);
      continue;
    }
    if (stopping_) break;
    for (size_t k = 1; k < fds.size(); ++k)
      if (fds[k].revents & POLLIN) AcceptFrom(fds[k].fd);
  }
}

void GrpcListener::AcceptFrom(int listen_fd) {
  for (int round = 0; round < 256 && !stopping_; ++round) {  // then the other sockets get their turn
    sockaddr_storage peer{};
    socklen_t len = sizeof(peer);
    const int fd = accept4(listen_fd, reinterpret_cast<sockaddr*>(&peer), &len, SOCK_NONBLOCK | SOCK_CLOEXEC);
    if (fd < 0) {
      if (errno == EAGAIN || errno == EWOULDBLOCK) return;
      if (errno == EINTR || errno == ECONNABORTED) continue;
      if (errno == EMFILE || errno == ENFILE) {
        // Out of descriptors: the reserve makes room to take the waiting connection off the queue and close it
        // (else poll reports it at once again, a busy loop), then is taken again; a pause lets others close.
        long n;
        {
          std::lock_guard<std::mutex> lock(mu_);
          n = ++counts_.out_of_files;
        }
        if (n == 1 || n % 1000 == 0)
          spdlog::warn("grpc: out of file descriptors ({} times so far): new connections are closed until some end",
                       n);
        if (reserve_fd_ >= 0) {
          ::close(reserve_fd_);
          const int drop = accept4(listen_fd, nullptr, nullptr, SOCK_CLOEXEC);
          if (drop >= 0) ::close(drop);
          reserve_fd_ = ::open("/dev/null", O_RDONLY | O_CLOEXEC);
        }
        Pause(10);
        return;
      }
      spdlog::warn("grpc listener: accept failed: {}", std::strerror(errno));  // ENOBUFS, ENOMEM: later
      Pause(10);
      return;
    }
    const std::string client = ClientAddress(peer);
    int open = static_cast<int>(tracked_.size());
    auto mine = [&] {
      auto it = per_client_.find(client);
      return it == per_client_.end() ? 0 : it->second;
    };
    if (open >= limits_.max_connections || mine() >= limits_.max_connections_per_client || ++since_sweep_ >= 1024) {
      Sweep();
      open = static_cast<int>(tracked_.size());
    }
    bool total = open >= limits_.max_connections;
    if (total && mine() < limits_.max_connections_per_client && ShedFromTheLargest(client)) total = false;
    if (total || mine() >= limits_.max_connections_per_client) {
      long n;
      {
        std::lock_guard<std::mutex> lock(mu_);
        n = total ? ++counts_.refused_total_cap : ++counts_.refused_client_cap;
      }
      ::close(fd);  // after the count: whoever sees the close sees it counted
      if (n == 1 || n % 1000 == 0)
        spdlog::warn("grpc: connection from {} closed: {} ({} such so far)", client,
                     total ? "the server has " + std::to_string(limits_.max_connections) + " gRPC connections open"
                           : "that address has " + std::to_string(limits_.max_connections_per_client) +
                                 " gRPC connections open",
                     n);
      continue;
    }
    tracked_.push_back({fd, Inode(fd), client});
    ++per_client_[client];
    {
      std::lock_guard<std::mutex> lock(mu_);
      ++counts_.accepted;
      counts_.open = static_cast<int>(tracked_.size());
    }
    grpc::experimental::ExternalConnectionAcceptor::NewConnectionParameters p;
    p.listener_fd = listen_fd;
    p.fd = fd;
    acceptor_->HandleNewConnection(&p);  // gRPC owns the descriptor from here (and closes it if it has stopped)
  }
}

bool GrpcListener::ShedFromTheLargest(const std::string& client) {
  auto top = std::max_element(per_client_.begin(), per_client_.end(),
                              [](const auto& a, const auto& b) { return a.second < b.second; });
  if (top == per_client_.end() || top->first == client || top->second < 2) return false;
  for (auto it = tracked_.rbegin(); it != tracked_.rend(); ++it) {
    if (it->client != top->first || Inode(it->fd) != it->inode) continue;
    // shutdown, not close: the descriptor stays gRPC's, which sees the connection end and closes it.
    ::shutdown(it->fd, SHUT_RDWR);
    tracked_.erase(std::next(it).base());
    if (--top->second <= 0) per_client_.erase(top);
    std::lock_guard<std::mutex> lock(mu_);
    ++counts_.shed;
    return true;
  }
  return false;
}

void GrpcListener::Sweep() {
  since_sweep_ = 0;
  std::vector<Tracked> live;
  live.reserve(tracked_.size());
  for (auto& t : tracked_) {
    if (Inode(t.fd) == t.inode && t.inode != 0) {
      live.push_back(std::move(t));
    } else if (auto it = per_client_.find(t.client); it != per_client_.end() && --it->second <= 0) {
      per_client_.erase(it);
    }
  }
  tracked_ = std::move(live);
  std::lock_guard<std::mutex> lock(mu_);
  counts_.open = static_cast<int>(tracked_.size());
}

}  // namespace vb::server
