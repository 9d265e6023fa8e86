// Failed authentications per client address, for every door that takes a token: the web's /api/login and
// bearer headers (web/gateway.cc) and the gRPC service's authorization metadata (service/service.cc).
//
// kMax failures within kWindow_s, then the address is refused, whatever it sends, until its oldest failure ages
// out. Why these figures: a token is 32 random bytes (docs/server.md), so guessing is hopeless at any rate; the
// limit is there to make a scan loud (each failure is logged) and cheap for the server, and to stop a client
// looping on a stale token. Ten in five minutes is more than a person mistyping ever needs (a lockout costs a
// legitimate user at most five minutes, and only after ten failures), while a scanner gets two attempts a minute.
// Behind a proxy all clients share one address: the proxy must then authenticate (docs/web.md).
#pragma once

#include <chrono>
#include <deque>
#include <map>
#include <mutex>
#include <string>

namespace vb {

class FailedAttempts {
 public:
  static constexpr int kMax = 10;
  static constexpr double kWindow_s = 300;
  static constexpr size_t kMaxAddresses = 10000;  // the table's size is bounded too (a spray of addresses)

  void Failed(const std::string& client) {
    std::lock_guard<std::mutex> lock(mu_);
    auto& q = by_client_[client];
    q.push_back(Clock::now());
    while (q.size() > static_cast<size_t>(kMax)) q.pop_front();
    if (by_client_.size() > kMaxAddresses) by_client_.erase(by_client_.begin());
  }

  // Seconds until the next attempt is allowed; 0 = now.
  double Blocked_s(const std::string& client) {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = by_client_.find(client);
    if (it == by_client_.end() || it->second.size() < static_cast<size_t>(kMax)) return 0;
    const double age = std::chrono::duration<double>(Clock::now() - it->second.front()).count();
    if (age >= kWindow_s) {
      by_client_.erase(it);
      return 0;
    }
    return kWindow_s - age;
  }

 private:
  using Clock = std::chrono::steady_clock;
  std::mutex mu_;
  std::map<std::string, std::deque<Clock::time_point>> by_client_;
};

// The address part of a gRPC peer string ("ipv4:10.0.0.7:5123" -> "10.0.0.7", "ipv6:[::1]:5123" -> "::1",
// "unix:/run/x.sock" -> "unix"); "" for an in-process peer, whose own door (the web's, per real client address)
// or machine (benchctl --local) already stands between it and the network. gRPC 1.51 gives an in-process call's
// server side the peer "unknown" (measured: tests/service/authorization_test.cc calls every method in process
// with a wrong token more than kMax times); other versions say "inproc". A network peer always has its scheme.
inline std::string ClientAddressOfPeer(const std::string& peer) {
  if (peer.rfind("inproc", 0) == 0 || peer == "unknown" || peer.empty()) return "";
  if (peer.rfind("unix:", 0) == 0 || peer.rfind("unix-abstract:", 0) == 0) return "unix";
  std::string rest = peer;
  if (const auto colon = rest.find(':'); colon != std::string::npos && (rest.rfind("ipv4:", 0) == 0 ||
                                                                        rest.rfind("ipv6:", 0) == 0))
    rest = rest.substr(colon + 1);
  // URL-encoded brackets in some gRPC versions: "ipv6:%5B::1%5D:5123".
  for (const char* open : {"[", "%5B"}) {
    if (rest.rfind(open, 0) == 0) {
      const std::string close = open[0] == '[' ? "]" : "%5D";
      const auto end = rest.find(close);
      return end == std::string::npos ? rest : rest.substr(std::char_traits<char>::length(open),
                                                           end - std::char_traits<char>::length(open));
    }
  }
  const auto port = rest.rfind(':');
  return port == std::string::npos ? rest : rest.substr(0, port);
}

}  // namespace vb
