#include "web/door.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <openssl/err.h>
#include <openssl/ssl.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <string_view>

namespace vb::web {

namespace {

using Clock = std::chrono::steady_clock;

Clock::time_point After(double seconds) {
  return Clock::now() + std::chrono::microseconds(static_cast<long long>(seconds * 1e6));
}

int MsUntil(Clock::time_point t) {
  const auto ms = std::chrono::duration_cast<std::chrono::milliseconds>(t - Clock::now()).count();
  return static_cast<int>(std::clamp<long long>(ms, 0, 60'000));
}

void SetBlocking(int fd, bool blocking) {
  const int flags = fcntl(fd, F_GETFL, 0);
  if (flags < 0) return;
  (void)fcntl(fd, F_SETFL, blocking ? (flags & ~O_NONBLOCK) : (flags | O_NONBLOCK));
}

std::string PeerAddress(int fd) {
  sockaddr_storage ss{};
  socklen_t len = sizeof(ss);
  if (getpeername(fd, reinterpret_cast<sockaddr*>(&ss), &len) != 0) return "?";
  char buf[INET6_ADDRSTRLEN] = {};
  if (ss.ss_family == AF_INET) {
    inet_ntop(AF_INET, &reinterpret_cast<sockaddr_in*>(&ss)->sin_addr, buf, sizeof(buf));
  } else if (ss.ss_family == AF_INET6) {
    inet_ntop(AF_INET6, &reinterpret_cast<sockaddr_in6*>(&ss)->sin6_addr, buf, sizeof(buf));
  } else {
    return "local";
  }
  return buf;
}

thread_local DoorRequestState* t_request = nullptr;

std::string PlainAnswer(int status, const char* reason, const char* message) {
  const std::string body = std::string(R"({"code":")") + (status == 429 ? "RESOURCE_EXHAUSTED" : "INVALID_ARGUMENT") +
                           R"(","message":")" + message + "\"}";
  return "HTTP/1.1 " + std::to_string(status) + " " + reason +
         "\r\nContent-Type: application/json\r\nConnection: close\r\nContent-Length: " + std::to_string(body.size()) +
         "\r\n\r\n" + body;
}

}  // namespace

DoorRequestState* CurrentDoorRequest() { return t_request; }

struct Door::Conn {
  int fd = -1;
  SSL* ssl = nullptr;
  bool handshaken = false;
  bool want_write = false;  // TLS: the handshake waits for the socket to take bytes
  std::string client;
  std::string buf;          // the head read so far (and whatever followed it)
  Clock::time_point deadline;
  bool head_started = false;
  int requests = 0;
};

// The worker's view of a connection: the buffered head first; then, once cpp-httplib has parsed the head (the
// gateway's pre-routing handler says so), the body from the socket within the budget and the deadline.
class DoorStream : public httplib::Stream {
 public:
  DoorStream(int fd, SSL* ssl, std::string buffered, size_t body_budget, Clock::time_point deadline,
             DoorRequestState* state)
      : fd_(fd),
        ssl_(ssl),
        buf_(std::move(buffered)),
        budget_(body_budget),
        deadline_(deadline),
        start_(Clock::now()),
        state_(state) {}

  bool is_readable() const override { return pos_ < buf_.size() || (ssl_ && SSL_pending(ssl_) > 0); }
  bool is_writable() const override {
    pollfd p{fd_, POLLOUT, 0};
    return poll(&p, 1, 5000) > 0 && (p.revents & POLLOUT);
  }

  ssize_t read(char* ptr, size_t size) override {
    if (pos_ < buf_.size()) {
      const size_t n = std::min(size, buf_.size() - pos_);
      std::memcpy(ptr, buf_.data() + pos_, n);
      pos_ += n;
      return static_cast<ssize_t>(n);
    }
    // The head is whole in the buffer (the reader saw its blank line): a parser still reading wants more head
    // than was sent (a line without CRLF): no socket read for that.
    if (!state_->head_parsed) return -1;
    if (budget_ == 0) {
      state_->body_too_large = true;
      state_->close_after = true;
      return -1;
    }
    const size_t want = std::min(size, budget_);
    for (;;) {
      if (!(ssl_ && SSL_pending(ssl_) > 0)) {
        pollfd p{fd_, POLLIN, 0};
        // A body trickled in holds a worker: after a grace of kBodyGrace_s it must keep up kMinBodyRate (a spec
        // is a few KiB), and it never gets past body_timeout_s.
        const auto by_rate = start_ + std::chrono::milliseconds(static_cast<long long>(
                                          1000.0 * (kBodyGrace_s + static_cast<double>(read_) / kMinBodyRate)));
        const int r = poll(&p, 1, MsUntil(std::min(deadline_, by_rate)));
        if (r == 0) {
          state_->body_timed_out = true;
          state_->close_after = true;
          return -1;
        }
        if (r < 0) {
          if (errno == EINTR) continue;
          return -1;
        }
      }
      ssize_t n;
      if (ssl_) {
        n = SSL_read(ssl_, ptr, static_cast<int>(want));
        if (n <= 0) {
          const int e = SSL_get_error(ssl_, static_cast<int>(n));
          if (e == SSL_ERROR_WANT_READ || e == SSL_ERROR_WANT_WRITE) continue;
          return -1;
        }
      } else {
        n = ::recv(fd_, ptr, want, 0);
        if (n < 0 && (errno == EINTR || errno == EAGAIN)) continue;
        if (n < 0) return -1;
      }
      budget_ -= static_cast<size_t>(n);
      read_ += static_cast<size_t>(n);
      return n;
    }
  }

  ssize_t write(const char* ptr, size_t size) override {
    if (ssl_) {
      const int n = SSL_write(ssl_, ptr, static_cast<int>(std::min<size_t>(size, 1 << 30)));
      return n > 0 ? n : -1;
    }
    for (;;) {
      const ssize_t n = ::send(fd_, ptr, size, MSG_NOSIGNAL);
      if (n < 0 && errno == EINTR) continue;
      return n;
    }
  }

  void get_remote_ip_and_port(std::string& ip, int& port) const override { AddressOf(false, ip, port); }
  void get_local_ip_and_port(std::string& ip, int& port) const override { AddressOf(true, ip, port); }
  socket_t socket() const override { return fd_; }

  // The bytes after this request (a pipelined next request), for the reader.
  std::string Leftover() const { return buf_.substr(std::min(pos_, buf_.size())); }

 private:
  void AddressOf(bool local, std::string& ip, int& port) const {
    sockaddr_storage ss{};
    socklen_t len = sizeof(ss);
    ip.clear();
    port = 0;
    if ((local ? getsockname(fd_, reinterpret_cast<sockaddr*>(&ss), &len)
               : getpeername(fd_, reinterpret_cast<sockaddr*>(&ss), &len)) != 0)
      return;
    char buf[INET6_ADDRSTRLEN] = {};
    if (ss.ss_family == AF_INET) {
      auto* a = reinterpret_cast<sockaddr_in*>(&ss);
      inet_ntop(AF_INET, &a->sin_addr, buf, sizeof(buf));
      port = ntohs(a->sin_port);
    } else if (ss.ss_family == AF_INET6) {
      auto* a = reinterpret_cast<sockaddr_in6*>(&ss);
      inet_ntop(AF_INET6, &a->sin6_addr, buf, sizeof(buf));
      port = ntohs(a->sin6_port);
    }
    ip = buf;
  }

  int fd_;
  SSL* ssl_;
  std::string buf_;
  size_t pos_ = 0;
  size_t budget_;
  Clock::time_point deadline_;
  Clock::time_point start_;
  size_t read_ = 0;  // body bytes read from the socket
  DoorRequestState* state_;
  static constexpr double kBodyGrace_s = 10.0;
  static constexpr double kMinBodyRate = 64 * 1024.0;  // bytes/s
};

Door::Door(const DoorLimits& limits, SSL_CTX* ssl_ctx, ServeFn serve)
    : limits_(limits), ssl_ctx_(ssl_ctx), serve_(std::move(serve)) {
  if (pipe(wake_) != 0) wake_[0] = wake_[1] = -1;
  for (int fd : wake_)
    if (fd >= 0) SetBlocking(fd, false);
  reader_ = std::thread([this] { ReaderLoop(); });
  for (int k = 0; k < std::max(1, limits_.workers); ++k) workers_.emplace_back([this] { WorkerLoop(); });
}

Door::~Door() {
  Stop();
  for (int fd : wake_)
    if (fd >= 0) ::close(fd);
}

int Door::open_connections() const {
  std::lock_guard<std::mutex> lock(mu_);
  return open_;
}

void Door::Wake() {
  const char c = 1;
  if (wake_[1] >= 0) (void)!::write(wake_[1], &c, 1);
}

void Door::Refuse(int fd, int status, const char* message) {
  if (!ssl_ctx_) {
    const std::string a =
        PlainAnswer(status, status == 429 ? "Too Many Requests" : status == 431 ? "Request Header Fields Too Large"
                                                                                : "Request Timeout",
                    message);
    (void)::send(fd, a.data(), a.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
  }
  ::shutdown(fd, SHUT_RDWR);
  ::close(fd);
}

void Door::Adopt(int fd) {
  auto c = std::make_unique<Conn>();
  c->fd = fd;
  c->client = PeerAddress(fd);
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_) {
      ::close(fd);
      return;
    }
    int& mine = per_client_[c->client];
    if (open_ >= limits_.max_connections || mine >= limits_.max_connections_per_client) {
      const bool total = open_ >= limits_.max_connections;
      if (mine == 0) per_client_.erase(c->client);
      Refuse(fd, 429, total ? "too many open connections to the dashboard; try again later"
                            : "too many open connections from your address; close some tabs");
      return;
    }
    ++mine;
    ++open_;
  }
  SetBlocking(fd, false);
  if (ssl_ctx_) {
    c->ssl = SSL_new(ssl_ctx_);
    if (!c->ssl) return Close(std::move(c));
    SSL_set_fd(c->ssl, fd);
    c->deadline = After(limits_.handshake_timeout_s);
  } else {
    c->handshaken = true;
    c->deadline = After(limits_.idle_timeout_s);
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    incoming_.push_back(std::move(c));
  }
  Wake();
}

void Door::Close(std::unique_ptr<Conn> c) {
  if (c->ssl) {
    if (c->handshaken) {
      SetBlocking(c->fd, false);
      (void)SSL_shutdown(c->ssl);
    }
    SSL_free(c->ssl);
  }
  ::shutdown(c->fd, SHUT_RDWR);
  ::close(c->fd);
  std::lock_guard<std::mutex> lock(mu_);
  --open_;
  auto it = per_client_.find(c->client);
  if (it != per_client_.end() && --it->second <= 0) per_client_.erase(it);
}

bool Door::ReadSome(Conn& c) {
  if (!c.handshaken) {
    ERR_clear_error();
    const int r = SSL_accept(c.ssl);
    if (r == 1) {
      c.handshaken = true;
      c.want_write = false;
      c.deadline = After(limits_.idle_timeout_s);
    } else {
      const int e = SSL_get_error(c.ssl, r);
      if (e == SSL_ERROR_WANT_READ) {
        c.want_write = false;
        return true;
      }
      if (e == SSL_ERROR_WANT_WRITE) {
        c.want_write = true;
        return true;
      }
      return false;
    }
  }
  char tmp[4096];
  for (;;) {
    const size_t room = limits_.max_head_bytes + 1 - std::min(c.buf.size(), limits_.max_head_bytes + 1);
    if (room == 0) return true;  // the caller sees the head is too big
    ssize_t n;
    if (c.ssl) {
      ERR_clear_error();
      const int r = SSL_read(c.ssl, tmp, static_cast<int>(std::min(room, sizeof(tmp))));
      if (r <= 0) {
        const int e = SSL_get_error(c.ssl, r);
        if (e == SSL_ERROR_WANT_READ) return true;
        if (e == SSL_ERROR_WANT_WRITE) {
          c.want_write = true;
          return true;
        }
        return false;
      }
      n = r;
    } else {
      n = ::recv(c.fd, tmp, std::min(room, sizeof(tmp)), 0);
      if (n < 0) return errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR;
      if (n == 0) return false;  // the peer closed
    }
    if (!c.head_started) {
      c.head_started = true;
      c.deadline = After(limits_.head_timeout_s);
    }
    c.buf.append(tmp, static_cast<size_t>(n));
  }
}

void Door::ReaderLoop() {
  std::vector<std::unique_ptr<Conn>> conns;
  std::vector<pollfd> fds;
  for (;;) {
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (stopping_) break;
      for (auto& c : incoming_) conns.push_back(std::move(c));
      incoming_.clear();
    }
    // TLS may hold decrypted bytes of a pipelined request that poll() cannot see.
    for (auto& c : conns)
      if (c && c->ssl && c->handshaken && SSL_pending(c->ssl) > 0 && !ReadSome(*c)) Close(std::move(c));
    conns.erase(std::remove(conns.begin(), conns.end(), nullptr), conns.end());
    // Heads already whole (a pipelined request left by the previous one) go straight on.
    std::vector<std::unique_ptr<Conn>> keep, to_work, to_close;
    const auto now = Clock::now();
    Clock::time_point next = now + std::chrono::seconds(1);
    for (auto& c : conns) {
      if (c->handshaken && c->buf.find("\r\n\r\n") != std::string::npos) {
        to_work.push_back(std::move(c));
      } else if (c->buf.size() > limits_.max_head_bytes) {
        Refuse(c->fd, 431, "request head (request line and headers) larger than the limit");
        c->fd = -1;
        to_close.push_back(std::move(c));
      } else if (now >= c->deadline) {
        if (c->head_started && c->handshaken) {
          Refuse(c->fd, 408, "request head not received in time");
          c->fd = -1;
        }
        to_close.push_back(std::move(c));
      } else {
        next = std::min(next, c->deadline);
        keep.push_back(std::move(c));
      }
    }
    conns = std::move(keep);
    for (auto& c : to_close) {
      if (c->fd < 0) {  // already answered and closed by Refuse: only the accounting
        if (c->ssl) SSL_free(c->ssl);
        std::lock_guard<std::mutex> lock(mu_);
        --open_;
        auto it = per_client_.find(c->client);
        if (it != per_client_.end() && --it->second <= 0) per_client_.erase(it);
      } else {
        Close(std::move(c));
      }
    }
    if (!to_work.empty()) {
      std::lock_guard<std::mutex> lock(mu_);
      for (auto& c : to_work) ready_.push_back(std::move(c));
      work_cv_.notify_all();
    }
    fds.assign(1, pollfd{wake_[0], POLLIN, 0});
    for (auto& c : conns) fds.push_back(pollfd{c->fd, static_cast<short>(c->want_write ? POLLOUT : POLLIN), 0});
    const int r = poll(fds.data(), fds.size(), MsUntil(next));
    if (r < 0 && errno != EINTR) break;
    if (fds[0].revents) {
      char drain[64];
      while (::read(wake_[0], drain, sizeof(drain)) > 0) {
      }
    }
    std::vector<std::unique_ptr<Conn>> still;
    for (size_t k = 0; k < conns.size(); ++k) {
      auto& c = conns[k];
      if (fds[k + 1].revents == 0) {
        still.push_back(std::move(c));
        continue;
      }
      if (ReadSome(*c)) {
        still.push_back(std::move(c));
      } else {
        Close(std::move(c));
      }
    }
    conns = std::move(still);
  }
  for (auto& c : conns) Close(std::move(c));
  std::vector<std::unique_ptr<Conn>> left;
  {
    std::lock_guard<std::mutex> lock(mu_);
    left.swap(incoming_);
  }
  for (auto& c : left) Close(std::move(c));
}

void Door::WorkerLoop() {
  for (;;) {
    std::unique_ptr<Conn> c;
    {
      std::unique_lock<std::mutex> lock(mu_);
      work_cv_.wait(lock, [&] { return stopping_ || !ready_.empty(); });
      if (ready_.empty()) return;  // stopping
      c = std::move(ready_.front());
      ready_.pop_front();
    }
    SetBlocking(c->fd, true);
    DoorRequestState state;
    t_request = &state;
    ++c->requests;
    const bool last = c->requests >= limits_.max_requests_per_connection;
    // Chunk framing ("1000\r\n...\r\n") adds a little to a chunked body on the wire.
    const size_t budget = limits_.max_body_bytes + limits_.max_body_bytes / 16 + 4096;
    DoorStream strm(c->fd, c->ssl, std::move(c->buf), budget, After(limits_.body_timeout_s), &state);
    bool closed = false;
    bool ok = false;
    try {
      ok = serve_(strm, last, closed);
    } catch (...) {
      ok = false;  // cpp-httplib's writer threw (a handler's content provider): the connection ends
    }
    t_request = nullptr;
    if (!ok || closed || last || state.close_after) {
      Close(std::move(c));
      continue;
    }
    c->buf = strm.Leftover();
    c->head_started = !c->buf.empty();
    c->deadline = After(c->head_started ? limits_.head_timeout_s : limits_.idle_timeout_s);
    SetBlocking(c->fd, false);
    bool back = false;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (!stopping_) {
        incoming_.push_back(std::move(c));
        back = true;
      }
    }
    if (back) {
      Wake();
    } else {
      Close(std::move(c));
    }
  }
}

void Door::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stopping_ && !reader_.joinable()) return;
    stopping_ = true;
    work_cv_.notify_all();
  }
  Wake();
  if (reader_.joinable()) reader_.join();
  for (auto& t : workers_)
    if (t.joinable()) t.join();
  workers_.clear();
  std::deque<std::unique_ptr<Conn>> left;
  {
    std::lock_guard<std::mutex> lock(mu_);
    left.swap(ready_);
  }
  for (auto& c : left) Close(std::move(c));
}

ssize_t MemoryStream::read(char* ptr, size_t size) {
  if (pos_ >= in_.size()) return -1;
  const size_t n = std::min(size, in_.size() - pos_);
  std::memcpy(ptr, in_.data() + pos_, n);
  pos_ += n;
  return static_cast<ssize_t>(n);
}

ssize_t MemoryStream::write(const char* ptr, size_t size) {
  out_.append(ptr, size);
  return static_cast<ssize_t>(size);
}

}  // namespace vb::web
