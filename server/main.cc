// valvebench-server --config FILE
// With a "nights" block in the config, a scheduler thread runs the regression suite at each cron fire (UTC;
// server/nights.h). Test hook (hidden): --run-night-now runs one night right after start.
// With a "retention" block, another thread prunes old finished runs at each of its cron fires (server/retention.h).
// With a "web" block, the web dashboard (docs/web.md) on its own port: HTTP(S) in front of this BenchService
// through its in-process channel, so the page gets the same tokens, roles and validation as gRPC callers.
// Serves BenchService, grpc.health.v1 and server reflection; one worker per configured bench. Listens on
// loopback unless the config says otherwise. SIGTERM/SIGINT: stop accepting, stop running experiments (the
// benches go to their safe state; the runs are re-queued at the next start), exit 0.
#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>

#include <CLI/CLI.hpp>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <ctime>

#include <spdlog/sinks/stdout_sinks.h>
#include <spdlog/spdlog.h>
#include <memory>
#include <pthread.h>
#include <sys/resource.h>
#include <unistd.h>
#include <thread>

#include "server/config.h"
#include "server/grpc_listener.h"
#include "server/instance_lock.h"
#include "server/lab.h"
#include "server/nights.h"
#include "server/retention.h"
#include "service/host.h"
#include "service/hosting.h"
#include "regress/cron.h"
#include "db/open_store.h"
#include "web/gateway.h"

// What gRPC's transport may buffer in all (see the quota below).
constexpr int kGrpcMemoryQuotaBytes = 64 << 20;

int main(int argc, char** argv) {
  CLI::App app{"valvebench-server: the bench server"};
  std::string config_path;
  app.add_option("--config", config_path, "server configuration (protobuf JSON)")->required();
  bool run_night_now = false;
  app.add_flag("--run-night-now", run_night_now, "run one night at start (tests)")->group("");
  int simulate_nights = 0;
  app.add_option("--simulate-nights", simulate_nights,
                 "run N nights at start, back to back, dated the N days ending today (tests, demos)")
      ->check(CLI::Range(1, 3650))
      ->group("");
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e) == 0 ? 0 : 2;
  }

  // The log: stderr, UTC time stamps, level, one line per event, flushed at once (supervisors and tests read it
  // as it is written).
  spdlog::set_default_logger(spdlog::stderr_logger_mt("valvebench-server"));
  spdlog::set_pattern("%Y-%m-%dT%H:%M:%S.%eZ %l valvebench-server: %v", spdlog::pattern_time_type::utc);
  spdlog::flush_on(spdlog::level::info);

  // Open files: each gRPC or web connection, pooled store connection and live stream holds one. The soft limit
  // goes up to the hard one (the unit sets LimitNOFILE=65536; a shell's soft default is often 1024), and the gRPC
  // connections get what the other doors leave: the web's 512 connections, the store's 128, 64 for the rest
  // (logs, the database's files, the listeners), so a flood of idle gRPC connections cannot take the descriptors
  // the page and the store need (4096 at most; at a limit of 1024, 320).
  vb::server::GrpcListenerLimits grpc_limits;
  if (rlimit nofile{}; getrlimit(RLIMIT_NOFILE, &nofile) == 0) {
    if (nofile.rlim_cur < nofile.rlim_max) {
      const rlim_t was = nofile.rlim_cur;
      nofile.rlim_cur = nofile.rlim_max;
      if (setrlimit(RLIMIT_NOFILE, &nofile) == 0)
        spdlog::info("open files: limit raised from {} to {}", static_cast<unsigned long long>(was),
                     static_cast<unsigned long long>(nofile.rlim_cur));
      getrlimit(RLIMIT_NOFILE, &nofile);
    }
    const long left = static_cast<long>(std::min<rlim_t>(nofile.rlim_cur, 1 << 20)) - 512 - 128 - 64;
    grpc_limits.max_connections = static_cast<int>(std::clamp(left, 32L, 4096L));
    grpc_limits.max_connections_per_client =
        std::min(grpc_limits.max_connections_per_client, std::max(8, grpc_limits.max_connections / 2));
  }

  // Block the shutdown signals in every thread; one thread waits for them.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  auto settings = vb::server::LoadSettings(config_path);
  if (!settings.ok()) {
    spdlog::error("{}", settings.status().message().c_str());
    return 2;
  }
  if ((run_night_now || simulate_nights > 0) && !settings->nights.enabled) {
    spdlog::error("--run-night-now/--simulate-nights: the config has no \"nights\" block");
    return 2;
  }
  // One server per store, or per lab host identity (server/instance_lock.h): taken before the store is opened,
  // so a second server neither migrates nor recovers the first one's running runs.
  auto instance = vb::server::InstanceLock::Acquire(settings->database_path,
                                                    settings->lab.enabled ? settings->lab.host : std::string());
  if (!instance.ok()) {
    spdlog::error("{}", instance.status().message());
    return 3;
  }
  spdlog::info("this server holds {}", (*instance)->description());
  const std::string host_name = settings->lab.enabled ? settings->lab.host : std::string();

  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  std::shared_ptr<grpc::ServerCredentials> creds;
  if (!settings->tls_cert_pem.empty()) {
    grpc::SslServerCredentialsOptions ssl;
    ssl.pem_key_cert_pairs.push_back({settings->tls_key_pem, settings->tls_cert_pem});
    creds = grpc::SslServerCredentials(ssl);
  } else {
    creds = grpc::InsecureServerCredentials();
  }
  int port = 0;
  // No SO_REUSEPORT (gRPC's default on Linux): a second server on a held port must fail to bind, not share it.
  builder.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  // A connection that has not finished its TLS handshake and sent HTTP/2's SETTINGS within 10 s is closed (gRPC's
  // default is 120 s): idle sockets that never speak do not pile up towards the open-file limit.
  builder.AddChannelArgument(GRPC_ARG_SERVER_HANDSHAKE_TIMEOUT_MS, 10'000);
  // gRPC 1.51 reads a whole message (up to the 64 MiB limit) before its size is checked and before any handler or
  // interceptor sees the call's token, so unauthenticated calls could hold N x 64 MiB (issue 34: 20 at once took
  // the RSS to 771 MiB). A memory quota bounds what the transport buffers in all: under its pressure gRPC shrinks
  // its flow-control windows and, at the limit, closes connections (GOAWAY): 20 such calls at once peaked at
  // 227 MiB of RSS instead of 771 MiB. The price is that other clients' calls may fail with UNAVAILABLE during
  // such a flood (docs/server.md, "Limits under hostile load", measured). 64 MiB holds four of the largest
  // legitimate messages in flight (a client streams an import above 16 MiB, client/client.cc).
  grpc::ResourceQuota quota("valvebench-server");
  quota.Resize(kGrpcMemoryQuotaBytes);
  builder.SetResourceQuota(quota);
  // A TCP address is bound and accepted by the server's own listener (server/grpc_listener.h: connection caps, and
  // it survives running out of descriptors, which gRPC 1.51's accept loop does not); a unix: socket by gRPC.
  std::unique_ptr<vb::server::GrpcListener> listener;
  std::shared_ptr<grpc::experimental::ExternalConnectionAcceptor> acceptor;
  if (settings->listen_address.rfind("unix:", 0) == 0) {
    builder.AddListeningPort(settings->listen_address, creds, &port);
  } else {
    auto bound_listener = vb::server::GrpcListener::Bind(settings->listen_address, grpc_limits);
    if (!bound_listener.ok()) {
      spdlog::error("{} (is the port in use by another server?)", bound_listener.status().message().c_str());
      return 3;
    }
    listener = std::move(*bound_listener);
    port = listener->port();
    acceptor = builder.experimental().AddExternalConnectionAcceptor(
        grpc::ServerBuilder::experimental_type::ExternalConnectionType::FROM_FD, creds);
  }
  // The one host of the service (service/host.h), as a local service is: the store opened, the spool's leftovers
  // uploaded and this host's running runs interrupted and re-queued, the workers, and the service on this builder.
  vb::server::HostOptions host_options;
  host_options.store = settings->database_path;
  host_options.settings = &settings.value();
  host_options.recovery = vb::server::HostOptions::Recovery::kInterruptRunning;
  host_options.spool_dir = settings->spool_dir;
  host_options.spool_max_bytes = settings->spool_max_bytes;
  auto started = vb::server::Host::Start(std::move(host_options), &builder);
  if (!started.ok()) {
    spdlog::error("{}: {}", vb::db::DisplayLocation(settings->database_path).c_str(),
                  started.status().message().c_str());
    return 3;
  }
  std::unique_ptr<vb::server::Host> host = std::move(*started);
  if (host->interrupted_at_start() > 0)
    spdlog::warn("{} run(s) were running when the server stopped: marked interrupted", host->interrupted_at_start());
  grpc::Server* server = host->server();
  if (port == 0) {
    spdlog::error("cannot listen on {} (is the port in use by another server?)", settings->listen_address.c_str());
    return 3;
  }
  if (listener) listener->Start(acceptor);
  // Health by service name (grpc.health.v1 Check with service "valvebench.v1.BenchService") answers SERVING, not
  // NOT_FOUND (issue 14); the overall status ("") is SERVING by default.
  server->GetHealthCheckService()->SetServingStatus(valvebench::v1::BenchService::service_full_name(), true);

  // The address with the port actually bound (a config may ask for port 0: any free port).
  std::string bound = settings->listen_address;
  if (const size_t colon = bound.rfind(':'); colon != std::string::npos && bound.rfind("unix:", 0) != 0)
    bound = bound.substr(0, colon + 1) + std::to_string(port);
  std::unique_ptr<vb::server::LabHost> lab;
  if (settings->lab.enabled) {
    vb::server::LabSetup lab_setup = settings->lab;
    if (lab_setup.advertised_address.empty()) lab_setup.advertised_address = bound;
    lab = std::make_unique<vb::server::LabHost>(lab_setup, settings->database_path,
                                                vb::server::BenchesJson(settings->benches), host->registry(),
                                                &host->workers());
    lab->set_spool(host->spool());
    if (auto st = lab->Start(); !st.ok()) {
      spdlog::error("{}", st.message());
      server->Shutdown();
      return 3;
    }
  }
  host->Run();  // the spool's uploader and the workers
  std::unique_ptr<vb::server::NightScheduler> nights;
  if (settings->nights.enabled) {
    nights = std::make_unique<vb::server::NightScheduler>(
        settings->nights, settings->benches, host->pool(),
        [&host](const vb::runs::Submission& s) { return host->service()->Queue(s); });
    nights->Start(simulate_nights > 0 ? simulate_nights : (run_night_now ? 1 : 0));
  }
  std::unique_ptr<vb::server::RetentionScheduler> retention;
  if (settings->retention.enabled) {
    retention = std::make_unique<vb::server::RetentionScheduler>(settings->retention, settings->nights, host->pool());
    retention->Start();
  }
  spdlog::info("listening on {} ({}), {} bench(es), database {}", bound.c_str(),
               settings->tls_cert_pem.empty() ? "insecure" : "TLS", host->workers().size(),
               vb::db::DisplayLocation(settings->database_path).c_str());
  if (lab)
    spdlog::info("lab: host {} (lease {} s, heartbeat {} s, aging {} s)", settings->lab.host, settings->lab.lease_ttl_s,
                 settings->lab.heartbeat_s, settings->lab.aging_s);
  if (nights) spdlog::info("nights: '{}' (UTC), suite {}",
                           settings->nights.cron.c_str(), settings->nights.suite_path.c_str());

  if (retention)
    spdlog::info("retention: '{}' (UTC), runs finished more than {} days before go, newest {} kept",
                 settings->retention.cron.c_str(), settings->retention.older_than_days, settings->retention.keep_last);

  std::unique_ptr<vb::web::Gateway> web;
  if (!settings->web_listen_address.empty()) {
    grpc::ChannelArguments args = vb::server::InProcessChannelArguments();
    vb::web::GatewayOptions wo;
    wo.listen_address = settings->web_listen_address;
    wo.tls_cert_pem = settings->tls_cert_pem;
    wo.tls_key_pem = settings->tls_key_pem;
    const auto& w = settings->web;
    if (w.head_timeout_s() > 0) wo.limits.head_timeout_s = w.head_timeout_s();
    if (w.max_connections_per_client() > 0) wo.limits.max_connections_per_client = w.max_connections_per_client();
    if (w.workers() > 0) wo.limits.workers = w.workers();
    if (w.max_streams() > 0) wo.max_streams = w.max_streams();
    if (w.max_streams_per_session() > 0) wo.max_streams_per_session = w.max_streams_per_session();
    wo.allowed_origins.assign(w.allowed_origins().begin(), w.allowed_origins().end());
    wo.sessions_file = settings->web_sessions_file;
    if (wo.sessions_file.empty())
      spdlog::warn("web: no sessions_file: the dashboard's sessions end with this process (pages log in again)");
    wo.identify = [&settings](std::string_view authorization) -> vb::StatusOr<vb::web::GatewayOptions::Identity> {
      auto p = settings->auth.Authenticate(authorization);
      if (!p.ok()) return p.status();
      return vb::web::GatewayOptions::Identity{p->user, vb::server::RoleName(p->role)};
    };
    if (settings->nights.enabled)
      wo.next_night_unix_s = [cron = settings->nights.cron, utc = settings->nights.utc]() -> vb::StatusOr<double> {
        auto c = vb::regress::Cron::Parse(cron);
        if (!c.ok()) return c.status();
        return c->NextUnix(static_cast<double>(std::time(nullptr)), utc);
      };
    auto started = vb::web::Gateway::Start(wo, server->InProcessChannel(args));
    if (!started.ok()) {
      spdlog::error("{}", started.status().message().c_str());
      if (nights) nights->Stop();
      if (retention) retention->Stop();
      host->StopBenches(vb::server::Host::StopMode::kLeaveRunning);
      server->Shutdown(std::chrono::system_clock::now());
      return 3;
    }
    web = std::move(*started);
    std::string web_host = wo.listen_address.substr(0, wo.listen_address.rfind(':'));
    spdlog::info("web dashboard on {}://{}:{}/", web->tls() ? "https" : "http", web_host.c_str(), web->port());
  }

  int sig = 0;
  sigwait(&signals, &sig);
  spdlog::info("{}: shutting down", sig == SIGTERM ? "SIGTERM" : "SIGINT");
  // The benches first: whatever the doors are doing (a slow upload, a thousand live views), the experiments stop
  // and the benches go to their safe state before anything waits on a client.
  const auto t_signal = std::chrono::steady_clock::now();
  host->StopBenches(vb::server::Host::StopMode::kLeaveRunning);
  spdlog::info("benches stopped (safe state) {:.2f} s after the signal",
               std::chrono::duration<double>(std::chrono::steady_clock::now() - t_signal).count());
  // Then the doors, within a bound: gRPC calls get 2 s, web requests 1 s more, then their sockets are shut down.
  // Should anything still hang (a handler stuck in CPU work), the process ends kDrainBound_s after the benches
  // were safe: everything stored is in the store's transactions, and the unit's TimeoutStopSec (15 s) is never
  // reached.
  static constexpr int kDrainBound_s = 4;
  std::thread([] {
    std::this_thread::sleep_for(std::chrono::seconds(kDrainBound_s));
    spdlog::warn("shutdown: the doors did not drain within {} s; exiting without them", kDrainBound_s);
    spdlog::default_logger()->flush();
    _exit(0);
  }).detach();
  if (nights) nights->Stop();
  if (retention) retention->Stop();
  if (listener) listener->Stop();  // no new gRPC connections
  server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
  if (web) web->Stop();  // after Shutdown: that ends the live streams (SSE) the page's threads wait on
  spdlog::info("doors closed {:.2f} s after the signal",
               std::chrono::duration<double>(std::chrono::steady_clock::now() - t_signal).count());
  host->StopRest();  // the spool, after the workers: what it has not uploaded stays on disk for the next start
  if (lab) {
    // The runs this host stopped go back to the lab's queue now rather than when their leases lapse.
    lab->Stop();
    if (auto store = host->pool()->Acquire(); store.ok())
      if (auto again = (*store)->RecoverAfterCrash(host_name); again.ok() && *again > 0)
        spdlog::info("lab: {} run(s) stopped by the shutdown re-queued for the lab", *again);
  }
  server->Wait();
  return 0;
}
