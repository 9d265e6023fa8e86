#include "web/door.h"

#include "web/head.h"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <openssl/err.h>
#include <openssl/ssl.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
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
  Clock::time_point since = Clock::now();  // accepted, or back from a worker
  bool peer_closed = false;                // the client shut down its sending side after its request
  // Answered and half-closed: the reader discards what the client still sends until it closes, up to the
  // deadline (Door::Linger).
  bool lingering = false;
  size_t discarded = 0;
  size_t scanned = 0;                      // buf[0, scanned) holds no blank line: not searched again
  // True when buf holds a whole head. Each byte is searched once however often the reader wakes (issue 34:
  // rescanning every buffered head on each wake, 384 slow connections put the page's p50 at 387 ms).
  bool HeadWhole() {
    if (buf.find("\r\n\r\n", scanned > 3 ? scanned - 3 : 0) != std::string::npos) return true;
    scanned = buf.size();
    return false;
  }
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

  // A slow reader holds a worker: the time spent waiting for it to take bytes may be at most write_grace_s plus
  // what it took, once the buffers were full, at min_write_rate (a live view writes little and rarely waits; a
  // 1 Mbit/s link waits but takes 128 KiB/s; a reader taking 1 KiB/s is cut after the grace, issue 34).
  ssize_t write(const char* ptr, size_t size) override {
    for (;;) {
      const double allowed_s =
          write_grace_s_ + static_cast<double>(written_after_wait_) / min_write_rate_ - blocked_s_;
      if (allowed_s <= 0) return WriteTimedOut();
      pollfd p{fd_, POLLOUT, 0};
      const auto t0 = Clock::now();
      const int r = poll(&p, 1, static_cast<int>(std::ceil(std::min(allowed_s, 60.0) * 1000.0)));
      const double waited_s = std::chrono::duration<double>(Clock::now() - t0).count();
      blocked_s_ += waited_s;
      if (waited_s > 0.001) waited_ = true;
      if (r == 0) return WriteTimedOut();
      if (r < 0) {
        if (errno == EINTR) continue;
        return -1;
      }
      if (ssl_) {
        const int n = SSL_write(ssl_, ptr, static_cast<int>(std::min<size_t>(size, 1 << 30)));
        if (n > 0 && waited_) written_after_wait_ += static_cast<size_t>(n);
        return n > 0 ? n : -1;
      }
      const ssize_t n = ::send(fd_, ptr, size, MSG_NOSIGNAL | MSG_DONTWAIT);
      if (n < 0 && (errno == EINTR || errno == EAGAIN || errno == EWOULDBLOCK)) continue;
      if (n > 0 && waited_) written_after_wait_ += static_cast<size_t>(n);
      return n;
    }
  }
  void SetWriteLimits(double grace_s, double min_rate) {
    write_grace_s_ = grace_s;
    min_write_rate_ = std::max(1.0, min_rate);
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
  bool waited_ = false;             // the socket's buffers have been full once
  size_t written_after_wait_ = 0;   // bytes the reader took since (what fit in the buffers at first is no credit)
  double blocked_s_ = 0;            // time spent waiting for the reader to take bytes
  double write_grace_s_ = 5.0;
  double min_write_rate_ = 16 * 1024.0;
  ssize_t WriteTimedOut() {
    state_->close_after = true;
    state_->write_timed_out = true;
    return -1;
  }
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
  if (ssl_ctx_) handshaker_ = std::thread([this] { HandshakeLoop(); });
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
        PlainAnswer(status,
                    status == 429   ? "Too Many Requests"
                    : status == 431 ? "Request Header Fields Too Large"
                    : status == 400 ? "Bad Request"
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
    // At the total cap, a connection still waiting for its head (slow, or idle between requests) is shed to make
    // room, rather than this one refused: slow heads from a few addresses cannot lock every other client out.
    if (open_ >= limits_.max_connections && mine < limits_.max_connections_per_client && waiting_ - shed_ > 0) {
      ++shed_;
    } else if (open_ >= limits_.max_connections || mine >= limits_.max_connections_per_client) {
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
  // Answers go out as written (issue 34: Nagle's algorithm with the peer's delayed ACK cost 44 ms per request on
  // a kept-alive connection).
  const int one = 1;
  (void)setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
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
  // fd < 0: Refuse answered and closed the socket already; only the TLS state and the accounting are left.
  if (c->ssl) {
    if (c->fd >= 0 && c->handshaken && !c->lingering) {  // a lingering one sent its close_notify already
      SetBlocking(c->fd, false);
      (void)SSL_shutdown(c->ssl);
    }
    SSL_free(c->ssl);
  }
  if (c->fd >= 0) {
    ::shutdown(c->fd, SHUT_RDWR);
    ::close(c->fd);
  }
  std::lock_guard<std::mutex> lock(mu_);
  --open_;
  auto it = per_client_.find(c->client);
  if (it != per_client_.end() && --it->second <= 0) per_client_.erase(it);
}

// A connection closed after its answer while the client may still be sending (a body refused before it was
// read: a 401/403/413 on an upload, issue 34's "token before the body"): closing a socket with unread bytes makes
// the kernel send RST, and an RST may reach the client before it has read the answer, which is then lost (CI saw
// the import's 403 lost this way). So the door does what Apache's lingering close and nginx's lingering_time do:
// it half-closes (FIN after the answer) and discards what still arrives until the client closes, for at most
// kLinger_s and kLingerBytes. A client that closes at once (the usual case) costs nothing; one that keeps sending
// holds only a connection slot (counted in its address's cap), never a worker.
void Door::Linger(std::unique_ptr<Conn> c) {
  SetBlocking(c->fd, false);
  if (c->ssl && c->handshaken) (void)SSL_shutdown(c->ssl);  // close_notify; later bytes are discarded unread
  if (::shutdown(c->fd, SHUT_WR) != 0) {
    Close(std::move(c));
    return;
  }
  c->lingering = true;
  c->want_write = false;
  c->discarded = 0;
  c->buf.clear();
  c->deadline = After(kLinger_s);
  BackToReader(std::move(c));
}

void Door::BackToReader(std::unique_ptr<Conn> c) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (!stopping_) incoming_.push_back(std::move(c));
  }
  if (c) {
    Close(std::move(c));  // stopping: the reader may be gone
  } else {
    Wake();
  }
}

bool Door::Discard(Conn& c) {
  char tmp[16384];
  for (;;) {
    const ssize_t n = ::recv(c.fd, tmp, sizeof(tmp), 0);
    if (n == 0) return false;
    if (n < 0) return errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR;
    c.discarded += static_cast<size_t>(n);
    if (c.discarded > kLingerBytes) return false;
  }
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
      if (n == 0) {
        // The peer closed its side: a complete request sent before the half-close is still answered (then the
        // connection closes); anything else ends here.
        if (c.buf.find("\r\n\r\n") == std::string::npos) return false;
        c.peer_closed = true;
        return true;
      }
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
    int shed = 0;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (stopping_) break;
      for (auto& c : incoming_) conns.push_back(std::move(c));
      incoming_.clear();
      shed = shed_;
      shed_ = 0;
    }
    if (shed > 0) {
      // The total cap was reached: close the connections that have waited longest for their heads, slow heads
      // (started, not finished) before idle kept-alive ones.
      std::vector<Conn*> waiting;  // those without a whole head yet
      for (auto& c : conns)
        if (!c->HeadWhole()) waiting.push_back(c.get());
      std::stable_sort(waiting.begin(), waiting.end(), [](const Conn* a, const Conn* b) {
        if (a->head_started != b->head_started) return a->head_started;
        return a->since < b->since;
      });
      if (static_cast<int>(waiting.size()) > shed) waiting.resize(static_cast<size_t>(shed));
      for (auto& c : conns) {
        if (std::find(waiting.begin(), waiting.end(), c.get()) == waiting.end()) continue;
        if (c->head_started && c->handshaken) {
          Refuse(c->fd, 408, "request head not received in time (the dashboard is at its connection limit)");
          c->fd = -1;
        }
        Close(std::move(c));
      }
      conns.erase(std::remove(conns.begin(), conns.end(), nullptr), conns.end());
    }
    // TLS may hold decrypted bytes of a pipelined request that poll() cannot see.
    for (auto& c : conns)
      if (c && !c->lingering && c->ssl && c->handshaken && SSL_pending(c->ssl) > 0 && !ReadSome(*c))
        Close(std::move(c));
    conns.erase(std::remove(conns.begin(), conns.end(), nullptr), conns.end());
    // Heads already whole (a pipelined request left by the previous one) go straight on.
    std::vector<std::unique_ptr<Conn>> keep, to_work, to_close;
    const auto now = Clock::now();
    Clock::time_point next = now + std::chrono::seconds(1);
    for (auto& c : conns) {
      if (c->lingering) {
        if (now >= c->deadline) {
          to_close.push_back(std::move(c));
        } else {
          next = std::min(next, c->deadline);
          keep.push_back(std::move(c));
        }
        continue;
      }
      bool whole = c->handshaken && c->HeadWhole();
      HeadVerdict v;
      if (whole) {
        // The head's framing, Range and Accept-Encoding checked before cpp-httplib sees it (web/head.h); the
        // empty lines it drops before a request line may leave no whole head yet.
        v = FilterHead(&c->buf);
        c->scanned = 0;
        whole = v.status != 0 || c->HeadWhole();
      }
      if (whole && v.status != 0) {
        Refuse(c->fd, v.status, v.message.c_str());
        c->fd = -1;
        to_close.push_back(std::move(c));
      } else if (whole) {
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
    for (auto& c : to_close) Close(std::move(c));
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
      if (!c->handshaken && !c->lingering) {
        QueueHandshake(std::move(c));
        continue;
      }
      if (c->lingering ? Discard(*c) : ReadSome(*c)) {
        still.push_back(std::move(c));
      } else {
        Close(std::move(c));
      }
    }
    conns = std::move(still);
    {
      std::lock_guard<std::mutex> lock(mu_);
      waiting_ = static_cast<int>(conns.size());
    }
  }
  for (auto& c : conns) Close(std::move(c));
  std::vector<std::unique_ptr<Conn>> left;
  {
    std::lock_guard<std::mutex> lock(mu_);
    left.swap(incoming_);
  }
  for (auto& c : left) Close(std::move(c));
}

void Door::QueueHandshake(std::unique_ptr<Conn> c) {
  std::lock_guard<std::mutex> lock(mu_);
  if (stopping_) {
    incoming_.push_back(std::move(c));  // closed with the reader's others
    return;
  }
  auto& mine = handshakes_[c->client];
  if (mine.empty()) handshake_turns_.push_back(c->client);
  mine.push_back(std::move(c));
  handshake_cv_.notify_one();
}

// One handshake step (SSL_accept on what has arrived: the ClientHello's step costs the signature) per turn,
// client addresses in turn, then the connection goes back to the reader (or to the workers' queue through it).
void Door::HandshakeLoop() {
  for (;;) {
    std::unique_ptr<Conn> c;
    {
      std::unique_lock<std::mutex> lock(mu_);
      handshake_cv_.wait(lock, [this] { return stopping_ || !handshake_turns_.empty(); });
      if (stopping_) break;
      const std::string client = handshake_turns_.front();
      handshake_turns_.pop_front();
      auto it = handshakes_.find(client);
      c = std::move(it->second.front());
      it->second.pop_front();
      if (it->second.empty()) {
        handshakes_.erase(it);
      } else {
        handshake_turns_.push_back(client);
      }
    }
    if (Clock::now() >= c->deadline || !ReadSome(*c)) {
      Close(std::move(c));
      continue;
    }
    BackToReader(std::move(c));
  }
  std::map<std::string, std::deque<std::unique_ptr<Conn>>> left;
  {
    std::lock_guard<std::mutex> lock(mu_);
    left.swap(handshakes_);
    handshake_turns_.clear();
  }
  for (auto& [client, queue] : left)
    for (auto& c : queue) Close(std::move(c));
}

void Door::WorkerLoop() {
  for (;;) {
    std::unique_ptr<Conn> c;
    {
      // The first waiting request whose client runs fewer than its share of the workers: one address cannot hold
      // them all (issue 34: 66 trickled bodies held all 64).
      const int per_client =
          limits_.max_workers_per_client > 0 ? limits_.max_workers_per_client : std::max(1, limits_.workers / 4);
      std::unique_lock<std::mutex> lock(mu_);
      std::deque<std::unique_ptr<Conn>>::iterator pick;
      work_cv_.wait(lock, [&] {
        if (stopping_) return true;
        pick = std::find_if(ready_.begin(), ready_.end(), [&](const std::unique_ptr<Conn>& r) {
          auto it = busy_per_client_.find(r->client);
          return it == busy_per_client_.end() || it->second < per_client;
        });
        return pick != ready_.end();
      });
      if (stopping_) return;
      c = std::move(*pick);
      ready_.erase(pick);
      busy_.insert(c->fd);
      ++busy_per_client_[c->client];
    }
    SetBlocking(c->fd, true);
    DoorRequestState state;
    bool share_released = false;
    state.release_share = [this, &share_released, client = c->client] {
      std::lock_guard<std::mutex> lock(mu_);
      if (share_released) return;
      share_released = true;
      if (auto it = busy_per_client_.find(client); it != busy_per_client_.end() && --it->second <= 0)
        busy_per_client_.erase(it);
      work_cv_.notify_all();
    };
    t_request = &state;
    ++c->requests;
    const bool last = c->requests >= limits_.max_requests_per_connection || c->peer_closed;
    // Chunk framing ("1000\r\n...\r\n") adds a little to a chunked body on the wire.
    const size_t budget = limits_.max_body_bytes + limits_.max_body_bytes / 16 + 4096;
    DoorStream strm(c->fd, c->ssl, std::move(c->buf), budget, After(limits_.body_timeout_s), &state);
    strm.SetWriteLimits(limits_.write_grace_s, limits_.min_write_rate);
    bool closed = false;
    bool ok = false;
    try {
      ok = serve_(strm, last, closed);
    } catch (...) {
      ok = false;  // cpp-httplib's writer threw (a handler's content provider): the connection ends
    }
    t_request = nullptr;
    {
      std::lock_guard<std::mutex> lock(mu_);
      busy_.erase(c->fd);  // before any close: Stop shuts down only sockets still owned here
      if (!share_released) {
        if (auto it = busy_per_client_.find(c->client); it != busy_per_client_.end() && --it->second <= 0)
          busy_per_client_.erase(it);
      }
      if (busy_.empty()) idle_cv_.notify_all();
      work_cv_.notify_all();  // a request of this client may have waited for its share
    }
    if (!ok || closed || last || state.close_after) {
      if (c->peer_closed) {
        Close(std::move(c));
      } else {
        Linger(std::move(c));
      }
      continue;
    }
    c->buf = strm.Leftover();
    c->scanned = 0;
    c->head_started = !c->buf.empty();
    c->deadline = After(c->head_started ? limits_.head_timeout_s : limits_.idle_timeout_s);
    c->since = Clock::now();
    SetBlocking(c->fd, false);
    BackToReader(std::move(c));
  }
}

void Door::Stop(double grace_s) {
  {
    std::unique_lock<std::mutex> lock(mu_);
    if (stopping_ && !reader_.joinable()) return;
    stopping_ = true;
    work_cv_.notify_all();
    handshake_cv_.notify_all();
    // Running requests get the grace to finish their answers; then their sockets are shut down (a read or a
    // write blocked on them fails at once, and the handler returns).
    idle_cv_.wait_for(lock, std::chrono::duration<double>(std::max(0.0, grace_s)), [this] { return busy_.empty(); });
    for (int fd : busy_) ::shutdown(fd, SHUT_RDWR);
  }
  Wake();
  if (handshaker_.joinable()) handshaker_.join();
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
