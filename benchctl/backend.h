// Where benchctl's runs live, behind one interface: the local store with the run pipeline in process
// (LocalBackend: runs/ Admit, Enqueue and a Worker on this thread), or a valvebench-server (RemoteBackend:
// client/). Commands are written once against it and render its result types with their one renderer
// (experiment::ComparisonTable/Csv/Json, RunView below); which backend a command gets is decided once, from
// the options (--local, --server), never inside the command.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "client/client.h"
#include "valvebench/v1/api.pb.h"
#include "common/run_key.h"
#include "common/run_status.h"
#include "common/status.h"
#include "experiment/compare.h"
#include "experiment/spec.h"

namespace vb::benchctl {

// A stored run as commands see it, from either backend.
struct RunView {
  std::int64_t id = 0;
  std::int64_t batch_id = 0;
  RunKey key;
  std::string controller;
  RunStatus status = RunStatus::kQueued;
  std::string reason;
  std::map<std::string, double> metrics;
  std::string spec_json;  // the single-run spec (reports show it with the run)
  double submitted_unix_s = 0.0, started_unix_s = 0.0, finished_unix_s = 0.0;

  bool ok() const { return status == RunStatus::kDone; }
  bool ended() const { return Ended(status); }
};

using Trace = client::FetchedTrace;

class Backend {
 public:
  virtual ~Backend() = default;
  // For messages and records: "local" or "server ADDR".
  virtual std::string Where() const = 0;
  // Whether hardware bench classes ("hid", "u3") can be run here (the local emulator plays only emulated ones).
  virtual bool serves_hardware() const = 0;
  // Queues already expanded specs with their keys as one batch and waits until every run has ended;
  // progress on stderr. Returns the batch id.
  virtual StatusOr<std::int64_t> RunBatch(const std::vector<experiment::ExperimentSpec>& specs,
                                          const std::vector<RunKey>& keys, const std::string& batch_name,
                                          const std::string& batch_json) = 0;
  // The runs of a batch (batch != 0) or the listed runs, with their metrics.
  virtual StatusOr<std::vector<RunView>> Runs(std::int64_t batch, const std::vector<std::int64_t>& run_ids) = 0;
  // The comparison of those runs (repeats grouped by case).
  virtual StatusOr<experiment::Comparison> Compare(std::int64_t batch, const std::vector<std::int64_t>& run_ids) = 0;
  virtual StatusOr<Trace> GetTrace(std::int64_t run_id) = 0;
  // The benches runs go to here, and the USB devices this backend's machine sees.
  virtual StatusOr<valvebench::v1::ListBenchesResponse> Benches() = 0;
};

// store_path "" (--no-store): an in-memory store that lives as long as the backend.
std::unique_ptr<Backend> LocalBackend(std::string store_path);
std::unique_ptr<Backend> RemoteBackend(std::unique_ptr<client::Client> client, std::string address);
// The server's comparison (CompareRuns) as the experiment::Comparison every renderer takes.
StatusOr<experiment::Comparison> RemoteComparison(client::Client& client, std::int64_t batch,
                                                  const std::vector<std::int64_t>& run_ids);
// The one decision: a server address given (and not overridden by --local) means the remote backend.
std::unique_ptr<Backend> ChooseBackend(const std::string& server, const std::string& store_path,
                                       const std::function<std::unique_ptr<client::Client>()>& make_client);

}  // namespace vb::benchctl
