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
#include <optional>
#include <string>
#include <vector>

#include "client/client.h"
#include "valvebench/v1/api.pb.h"
#include "common/run_key.h"
#include "common/run_status.h"
#include "common/status.h"
#include "experiment/compare.h"
#include "experiment/spec.h"
#include "benchctl/local_run.h"
#include "benchctl/run_view.h"

namespace vb::benchctl {

using Trace = client::FetchedTrace;

// Which runs `queue` lists.
struct RunFilter {
  std::optional<RunStatus> status;  // any when unset
  std::int64_t batch_id = 0;        // 0 = any
  std::string tag;
  int limit = 100;                  // 1..1000
};

// What `run` queued: the batch and its runs; a backend that executes in process (the local one) has run them
// already and gives their summaries (and traces if asked), in run order.
struct Submitted {
  std::int64_t batch_id = 0;
  std::vector<std::int64_t> run_ids;
  std::vector<LocalRunResult> executed;
};

class Backend {
 public:
  virtual ~Backend() = default;
  // For messages: "local store PATH" (or "in-memory store (--no-store)") or "server ADDR".
  virtual std::string Where() const = 0;
  // Whether hardware bench classes ("hid", "u3") can be run here (the local emulator plays only emulated ones).
  virtual bool serves_hardware() const = 0;
  // Queues already expanded specs with their keys as one batch and waits until every run has ended;
  // progress on stderr. Returns the batch id.
  virtual StatusOr<std::int64_t> RunBatch(const std::vector<experiment::ExperimentSpec>& specs,
                                          const std::vector<RunKey>& keys, const std::string& batch_name,
                                          const std::string& batch_json) = 0;
  // The runs of a batch (batch != 0) or the listed runs, with their metrics, spec and times (no history).
  virtual StatusOr<std::vector<RunView>> Runs(std::int64_t batch, const std::vector<std::int64_t>& run_ids) = 0;
  // The comparison of those runs (repeats grouped by case).
  virtual StatusOr<experiment::Comparison> Compare(std::int64_t batch, const std::vector<std::int64_t>& run_ids) = 0;
  virtual StatusOr<Trace> GetTrace(std::int64_t run_id) = 0;
  // The benches runs go to here, and the USB devices this backend's machine sees.
  virtual StatusOr<valvebench::v1::ListBenchesResponse> Benches() = 0;

  // Whether runs are kept after this process ends (false: the local backend with --no-store).
  virtual bool keeps_runs() const = 0;
  // Queues a spec's runs as one batch. The local backend executes them before it returns (realtime: paced
  // to the wall clock; keep_traces: the traces in Submitted::executed); the server queues them.
  virtual StatusOr<Submitted> Submit(const experiment::ExperimentSpec& spec, bool realtime, bool keep_traces) = 0;
  // One run with its spec and status history.
  virtual StatusOr<RunView> GetRun(std::int64_t run_id) = 0;
  // Runs matching the filter in id order, at most filter.limit; *more: more matched.
  virtual StatusOr<std::vector<RunView>> ListRuns(const RunFilter& filter, bool* more) = 0;
  // Asks the run to stop and returns it as it is then: a queued run is cancelled at once, a running one
  // stops within a control period of whoever executes it (the server, or the benchctl running it locally).
  virtual StatusOr<RunView> Cancel(std::int64_t run_id, const std::string& reason) = 0;
  // Calls on_event (id, status, progress, reason) on every change until the run has ended or on_event
  // returns false.
  virtual Status Watch(std::int64_t run_id, const std::function<bool(const RunView&)>& on_event) = 0;
  // Stores a measured dataset's runs (benchctl import).
  virtual StatusOr<valvebench::v1::SubmitRunResponse> Import(const valvebench::v1::ImportRunsRequest& request) = 0;
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
