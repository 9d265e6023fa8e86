// The web door's connection handling (docs/web.md "Limits"): what stands between a socket and cpp-httplib's
// request parser, because Debian's cpp-httplib 0.11.4 bounds none of it (a request line or a header line is read
// whole whatever its length, headers are unbounded in number, a chunked body passes set_payload_max_length, a
// body without Content-Length is read until the peer closes, and a connection holds a pool thread from accept to
// close, however slowly it sends).
//
// Here a connection holds a worker thread only while a complete request head is in hand:
//  - one reader thread accepts the connections handed over by the server's accept loop and reads each request
//    head without blocking, into a buffer of at most max_head_bytes, within
//    head_timeout_s of the head's first byte (idle_timeout_s for an idle keep-alive connection); a slow or
//    oversized head costs a file descriptor and a few KiB, never a thread, and is closed (408/431) at its limit;
//  - TLS handshakes (their CPU: a signature each) run on a thread of their own, one handshake step at a time,
//    taking client addresses in turn: a handshake flood from a few addresses costs one core at most, and another
//    client's handshake waits for one step per flooding address, not for the whole queue;
//  - a complete head goes to the worker pool, where cpp-httplib parses and routes it over a Stream that serves
//    the buffered bytes first, then reads the body from the socket with at most max_body_bytes (+ chunk framing)
//    and within body_timeout_s, whatever the framing;
//  - after the answer, a kept-alive connection goes back to the reader;
//  - open connections are capped in total and per client address (429 beyond, at once).
#pragma once

#include <httplib.h>

#include <atomic>
#include <condition_variable>
#include <cstddef>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "web/limits.h"

namespace vb::web {

// One connection, as the server's worker sees it while it runs a request.
class DoorStream;

// The request-running half: cpp-httplib's Server::process_request, reached through the subclass below.
using ServeFn = std::function<bool(httplib::Stream& strm, bool close_connection, bool& connection_closed)>;

class Door {
 public:
  // `ssl_ctx` non-null: TLS connections (the handshake is done here, not by cpp-httplib).
  Door(const DoorLimits& limits, SSL_CTX* ssl_ctx, ServeFn serve);
  ~Door();
  Door(const Door&) = delete;
  Door& operator=(const Door&) = delete;

  // A freshly accepted socket: the door owns it from here.
  void Adopt(int fd);
  // Closes every waiting connection and joins the threads. Running requests get `grace_s` to finish; then their
  // sockets are shut down, so that a worker blocked reading a trickled body or writing to a slow reader (or
  // streaming a live view) returns at once (SIGTERM must reach the end within the unit's stop timeout).
  void Stop(double grace_s = 1.0);

  // Open connections now (for the tests' figures and the log).
  int open_connections() const;

 private:
  struct Conn;
  void ReaderLoop();
  void WorkerLoop();
  void HandshakeLoop();
  // Hands a connection whose TLS handshake has bytes to process to the handshake thread.
  void QueueHandshake(std::unique_ptr<Conn> c);
  // Reads what the socket has; true when the connection stays in the reader's set.
  bool ReadSome(Conn& c);
  void Close(std::unique_ptr<Conn> c);
  // Half-closes after the answer and hands the connection to the reader, which discards what still arrives.
  void Linger(std::unique_ptr<Conn> c);
  // Gives a connection (back) to the reader's set and wakes it; closes it when the door is stopping.
  void BackToReader(std::unique_ptr<Conn> c);
  // Reads and drops what a lingering connection's socket has; false when it is to be closed now.
  bool Discard(Conn& c);
  static constexpr double kLinger_s = 2.0;             // Apache's lingering close waits 2 s
  static constexpr size_t kLingerBytes = 16u << 20;    // two bodies at the default max_body_bytes
  void Refuse(int fd, int status, const char* message);
  void Wake();

  DoorLimits limits_;
  SSL_CTX* ssl_ctx_;
  ServeFn serve_;
  int wake_[2] = {-1, -1};
  mutable std::mutex mu_;
  std::condition_variable work_cv_;
  std::vector<std::unique_ptr<Conn>> incoming_;  // adopted or back from a worker, not yet in the reader's set
  std::deque<std::unique_ptr<Conn>> ready_;      // a complete head, waiting for a worker
  std::map<std::string, int> per_client_;
  std::set<int> busy_;  // sockets a worker runs a request on (shut down by Stop after its grace)
  std::map<std::string, int> busy_per_client_;  // requests running per client address
  // Connections with a handshake step to do, per client address, and the addresses in their turn's order.
  std::map<std::string, std::deque<std::unique_ptr<Conn>>> handshakes_;
  std::deque<std::string> handshake_turns_;
  std::condition_variable handshake_cv_;
  int waiting_ = 0;  // connections in the reader's set (waiting for a head), as the reader last counted
  int shed_ = 0;     // of those, how many the reader is to close to make room (the total cap was reached)
  std::condition_variable idle_cv_;
  int open_ = 0;
  bool stopping_ = false;
  std::thread reader_;
  std::thread handshaker_;
  std::vector<std::thread> workers_;
};

// cpp-httplib's Server (or SSLServer) with its sockets handed to a Door. `Base` is httplib::Server or
// httplib::SSLServer; construct, then call InitDoor before listening.
template <class Base>
class DoorServer : public Base {
 public:
  using Base::Base;
  void InitDoor(const DoorLimits& limits, SSL_CTX* ssl_ctx) {
    door_ = std::make_unique<Door>(limits, ssl_ctx, [this](httplib::Stream& s, bool close, bool& closed) {
      return this->process_request(s, close, closed, nullptr);
    });
    // cpp-httplib's accept loop hands each socket to process_and_close_socket through this queue: run inline,
    // it only gives the socket to the door. The loop's end (stop()) shuts the door.
    Door* door = door_.get();
    this->new_task_queue = [door] { return new InlineQueue(door); };
  }
  Door* door() { return door_.get(); }
  // One connection's bytes through the request path with no socket (the fuzz target).
  bool ServeStream(httplib::Stream& s, bool close, bool& closed) {
    return this->process_request(s, close, closed, nullptr);
  }

 private:
  struct InlineQueue : httplib::TaskQueue {
    explicit InlineQueue(Door* d) : door(d) {}
    void enqueue(std::function<void()> fn) override { fn(); }
    void shutdown() override { door->Stop(); }
    Door* door;
  };
  bool process_and_close_socket(socket_t sock) override {
    door_->Adopt(sock);
    return true;
  }
  std::unique_ptr<Door> door_;
};

// The door's note about the request the calling worker thread runs, for the gateway's handlers: set by
// the gateway (Connection: close after a refused body), read by the door after the answer.
struct DoorRequestState {
  bool head_parsed = false;     // cpp-httplib has the head (the gateway's pre-routing handler): the body may be read
  bool close_after = false;     // do not keep the connection alive after this answer
  bool body_too_large = false;  // the body went past max_body_bytes (set by the door's stream)
  bool body_timed_out = false;  // the body did not arrive within body_timeout_s
  bool write_timed_out = false; // the client did not take the answer fast enough (DoorLimits::min_write_rate)
  // Called by a route that holds its worker for long under caps of its own (a live view: per session and in
  // all, below the workers): the request stops counting against its address's share of the workers.
  std::function<void()> release_share;
};
// Null outside a door worker (e.g. the fuzz target's direct calls).
DoorRequestState* CurrentDoorRequest();

// A Stream over bytes in memory, for the fuzz target and unit tests: reads `input`, collects what is written.
class MemoryStream : public httplib::Stream {
 public:
  explicit MemoryStream(std::string input) : in_(std::move(input)) {}
  bool is_readable() const override { return pos_ < in_.size(); }
  bool is_writable() const override { return true; }
  ssize_t read(char* ptr, size_t size) override;
  ssize_t write(const char* ptr, size_t size) override;
  void get_remote_ip_and_port(std::string& ip, int& port) const override {
    ip = "127.0.0.1";
    port = 40000;
  }
  void get_local_ip_and_port(std::string& ip, int& port) const override {
    ip = "127.0.0.1";
    port = 8080;
  }
  socket_t socket() const override { return 0; }
  const std::string& output() const { return out_; }
  bool consumed() const { return pos_ >= in_.size(); }

 private:
  std::string in_;
  size_t pos_ = 0;
  std::string out_;
};

}  // namespace vb::web
