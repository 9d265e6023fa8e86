// A local service: the BenchService over a store and a few benches in this process, with no listening port
// (issue 27). benchctl --local (and any program that wants the service without a server) creates one and talks
// to it through InProcessChannel() with client::Client, exactly as to a valvebench-server: one implementation
// of every behaviour, whichever door a request comes through (docs/decisions.md, "One service").
//
//   1. choose the store (a SQLite file, a PostgreSQL URL, or none: a private temporary SQLite file that lives as
//      long as the service, for --no-store);
//   2. start the one host of the service (service/host.h, as valvebench-server does) on a grpc::Server with no
//      port, with an admin token of its own (the channel's calls carry it): the store opened, the runs of these
//      benches left queued by an interrupted invocation cancelled (nobody will claim them);
//   3. if asked to execute: the host's workers (runs::Worker: claim and execute, the store's faults retried),
//      and its relay (runs::WatchRuns) between the store and the runs executing here, so another process on the
//      same store (benchctl watch/cancel in another shell) sees and stops them.
// The destructor stops claiming, stops a run still executing (it is cancelled: nobody would resume it), shuts
// the server down and removes the private store.
#pragma once

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "common/status.h"
#include "experiment/trace.h"
#include "runs/bench_setup.h"
#include "runs/monitor.h"
#include "runs/worker.h"
#include "service/host.h"
#include "service/service.h"
#include "service/settings.h"

namespace vb::server {

struct LocalServiceOptions {
  // A SQLite file (its directory is created) or postgresql://...; "" = a private temporary store, removed
  // with the service (benchctl --no-store).
  std::string store;
  // The benches; empty = the local emulator (runs::LocalEmulatorSetup: the spec's own plant, whose default is
  // model::kDefaultPreset; no interlocks).
  std::vector<runs::BenchSetup> benches;
  // Pace every run to the wall clock (benchctl run --local --realtime): loop jitter and overruns are measured.
  bool realtime = false;
  // Start the benches' workers. false: a service that reads, cancels and imports only (benchctl show, queue,
  // cancel --local): runs queued into it wait for a service that executes.
  bool execute = true;
  // Keep every executed run's whole trace in memory (KeptTrace()), for --trace-csv/--plot: the store keeps what
  // the service records, this is the loop's own trace with every channel.
  bool keep_traces = false;
  // A SQLite store must exist already (an administrative command, e.g. prune, would otherwise create an empty
  // one): FailedPrecondition "no local store at PATH" if it does not.
  bool must_exist = false;
  // The user runs are submitted as (default $USER, else the account name, else "local").
  std::string user;
};

class LocalService {
 public:
  static StatusOr<std::unique_ptr<LocalService>> Start(LocalServiceOptions options);
  ~LocalService();
  LocalService(const LocalService&) = delete;
  LocalService& operator=(const LocalService&) = delete;

  // A channel to this service (no network). Calls must carry `authorization: Bearer token()`.
  std::shared_ptr<grpc::Channel> InProcessChannel();
  const std::string& token() const { return token_; }
  // For messages: "local store PATH" or "in-memory store (--no-store)" (a PostgreSQL URL without its password).
  std::string Where() const { return Describe(options_.store); }
  static std::string Describe(const std::string& store);
  // What the service's connections open: the store given, or the private store's file.
  const std::string& store_path() const { return store_path_; }
  // Whether runs outlive the service (false: the private temporary store).
  bool keeps_runs() const { return !options_.store.empty(); }
  // With keep_traces, the whole trace of a run this service executed; nullopt otherwise. What executing a run
  // measured (wall time, loop statistics) is not here: it is stored with the run (Run.execution).
  std::optional<experiment::Trace> KeptTrace(std::int64_t run_id) const;

 private:
  explicit LocalService(LocalServiceOptions options) : options_(std::move(options)) {}
  Status Init();

  LocalServiceOptions options_;
  std::string store_path_;   // what the pool and workers open: options_.store or the private file
  std::string private_dir_;  // the private store's directory ("" if none)
  std::string token_;
  ServiceSettings settings_;  // the host's: declared before it, outlives it
  mutable std::mutex kept_mu_;
  std::map<std::int64_t, experiment::Trace> kept_;
  std::unique_ptr<Host> host_;
};

}  // namespace vb::server
