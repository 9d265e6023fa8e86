// The gateway's servers: plain or TLS over the door (web/door.h), bound and run on a thread of their own, and
// the socket-free one the fuzz target drives.
#include <fmt/format.h>
#include <httplib.h>
#include <openssl/pem.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>

#include "web/assets.h"
#include "web/door.h"
#include "web/gateway.h"
#include "web/routes.h"

namespace vb::web {

namespace {

// PEM text -> OpenSSL objects for httplib::SSLServer (which takes ownership of neither).
struct TlsMaterial {
  X509* cert = nullptr;
  EVP_PKEY* key = nullptr;
  ~TlsMaterial() {
    if (cert) X509_free(cert);
    if (key) EVP_PKEY_free(key);
  }
};

}  // namespace

const Asset* FindAsset(std::string_view url_path) {
  for (const Asset& a : Assets())
    if (url_path == a.url_path) return &a;
  return nullptr;
}

StatusOr<std::unique_ptr<Gateway>> Gateway::Start(const GatewayOptions& options,
                                                  std::shared_ptr<grpc::Channel> channel) {
  const size_t colon = options.listen_address.rfind(':');
  if (colon == std::string::npos || colon == 0)
    return Status::InvalidArgument("web.listen_address: must be host:port, got '" + options.listen_address + "'");
  std::string host = options.listen_address.substr(0, colon);
  if (host.size() > 2 && host.front() == '[' && host.back() == ']') host = host.substr(1, host.size() - 2);
  int port = 0;
  try {
    port = std::stoi(options.listen_address.substr(colon + 1));
  } catch (const std::exception&) {
    return Status::InvalidArgument("web.listen_address: bad port in '" + options.listen_address + "'");
  }
  std::unique_ptr<Gateway> g(new Gateway());
  // Uploads of an import left by a server that was killed mid-import (its Cleanup never ran).
  if (const int stale = RemoveStaleImports(); stale > 0)
    spdlog::info("web: removed {} temporary import director{} left by a stopped server", stale, stale == 1 ? "y" : "ies");
  if (!options.tls_cert_pem.empty()) {
    TlsMaterial m;
    BIO* cb = BIO_new_mem_buf(options.tls_cert_pem.data(), static_cast<int>(options.tls_cert_pem.size()));
    m.cert = PEM_read_bio_X509(cb, nullptr, nullptr, nullptr);
    BIO_free(cb);
    BIO* kb = BIO_new_mem_buf(options.tls_key_pem.data(), static_cast<int>(options.tls_key_pem.size()));
    m.key = PEM_read_bio_PrivateKey(kb, nullptr, nullptr, nullptr);
    BIO_free(kb);
    if (!m.cert) return Status::InvalidArgument("tls.cert_file: not a PEM certificate");
    if (!m.key) return Status::InvalidArgument("tls.key_file: not a PEM private key");
    auto ssl = std::make_unique<DoorServer<httplib::SSLServer>>(m.cert, m.key);
    if (!ssl->is_valid()) return Status::InvalidArgument("tls: the certificate and key do not make a TLS server");
    ssl->InitDoor(options.limits, ssl->ssl_context());
    g->http_ = std::move(ssl);
    g->tls_ = true;
  } else {
    auto plain = std::make_unique<DoorServer<httplib::Server>>();
    plain->InitDoor(options.limits, nullptr);
    g->http_ = std::move(plain);
  }
  if (options.max_streams >= options.limits.workers)
    return Status::InvalidArgument(fmt::format("web: max_streams ({}) must stay below the workers ({})",
                                               options.max_streams, options.limits.workers));
  g->http_->set_payload_max_length(options.limits.max_body_bytes);
  g->http_->set_read_timeout(5, 0);   // SO_RCVTIMEO on each socket: one blocking read (a TLS record) at most
  g->http_->set_write_timeout(10, 0); // SO_SNDTIMEO: a reader that stops reading lets its worker go
  // What the answers' Keep-Alive header announces; the door enforces both.
  g->http_->set_keep_alive_timeout(static_cast<time_t>(std::ceil(options.limits.idle_timeout_s)));
  g->http_->set_keep_alive_max_count(static_cast<size_t>(std::max(1, options.limits.max_requests_per_connection)));
  auto routes = std::make_shared<Routes>(std::move(channel), options, g->tls_);
  routes->Install(*g->http_);
  g->routes_ = routes;  // the handlers point into it
  // SO_REUSEADDR (a restarted server rebinds at once) but not cpp-httplib's default SO_REUSEPORT, which lets a
  // second server bind the same port and take half the connections: one server per port.
  auto listening = std::make_shared<socket_t>(INVALID_SOCKET);
  g->http_->set_socket_options([listening](socket_t sock) {
    int yes = 1;
    setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
    *listening = sock;
  });
  if (port == 0) {
    g->port_ = g->http_->bind_to_any_port(host);
    if (g->port_ <= 0) return Status::Unavailable("web.listen_address: cannot listen on " + options.listen_address);
  } else {
    if (!g->http_->bind_to_port(host, port))
      return Status::Unavailable("web.listen_address: cannot listen on " + options.listen_address);
    g->port_ = port;
  }
  // cpp-httplib listens with a backlog of 5: a burst of connections (600 slow heads) overflows it and every
  // further SYN waits for its 1 s retransmit. listen() again on the bound socket sets the kernel's backlog.
  if (*listening != INVALID_SOCKET) (void)::listen(*listening, 1024);
  httplib::Server* http = g->http_.get();
  g->thread_ = std::thread([http] { http->listen_after_bind(); });
  return g;
}

void Gateway::Stop() {
  if (http_) http_->stop();
  if (thread_.joinable()) thread_.join();
}

Gateway::~Gateway() { Stop(); }

RawGateway::RawGateway(std::shared_ptr<grpc::Channel> channel, const GatewayOptions& options) {
  auto server = std::make_unique<DoorServer<httplib::Server>>();
  server->set_payload_max_length(options.limits.max_body_bytes);
  auto routes = std::make_shared<Routes>(std::move(channel), options, false);
  routes->Install(*server);
  routes_ = routes;
  http_ = std::move(server);
}

RawGateway::~RawGateway() = default;

std::string RawGateway::Serve(const std::string& raw) {
  auto* server = static_cast<DoorServer<httplib::Server>*>(http_.get());
  MemoryStream strm(raw);
  for (int k = 0; k < 64 && !strm.consumed(); ++k) {
    bool closed = false;
    if (!server->ServeStream(strm, false, closed) || closed) break;
  }
  return strm.output();
}


}  // namespace vb::web
