// Where benchctl's runs live: a BenchService, reached with client::Client over a channel (issue 27). Remote: a
// valvebench-server's network channel. Local (--local): a local service (service/local_service.h) that this
// process starts over the local store and the embedded emulator, reached through its in-process channel. Both
// are the same code from here on: commands are written once against Backend and render its result types with
// their one renderer (experiment::ComparisonTable/Csv/Json, RunView below); which service a command talks to
// is decided once, from the options (--local, --server), never inside the command.
#pragma once

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "client/client.h"
#include "client/report_runs.h"
#include "valvebench/v1/api.pb.h"
#include "common/run_key.h"
#include "common/run_status.h"
#include "common/status.h"
#include "experiment/compare.h"
#include "experiment/spec.h"
#include "regress/compare.h"
#include "service/local_service.h"
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

// What `run` queued: the batch and its runs.
struct Submitted {
  std::int64_t batch_id = 0;
  std::vector<std::int64_t> run_ids;
};

// How a local service is started (ChooseBackend): whether it executes runs (run, compare SPEC, regress) or only
// reads, cancels and imports (show, queue, watch, cancel, export, diagnose --runs, import: another benchctl
// may be executing on the same store), and whether it keeps executed runs' whole traces (run --trace-csv).
struct LocalUse {
  bool execute = false;
  bool keep_traces = false;
};

class Backend final {
 public:
  // A service reached through `client`; `local`: the local service it talks to (nullptr: a server at
  // `where`, "server ADDR").
  Backend(std::unique_ptr<client::Client> client, std::string where,
          std::unique_ptr<server::LocalService> local = nullptr);
  // A local service that could not start: every call returns `why`.
  Backend(Status why, std::string where);
  ~Backend();

  // For messages: "local store PATH" (or "in-memory store (--no-store)") or "server ADDR".
  std::string Where() const { return where_; }
  // Whether hardware bench classes ("hid", "u3") can be run here (the local emulator plays only emulated ones).
  bool serves_hardware() const { return local_ == nullptr; }
  // Whether runs are executed by this process (a local service): `run` waits for them, whatever --wait says.
  bool executes_here() const { return local_ != nullptr; }
  // Whether runs are kept after this process ends (false: a local service with --no-store).
  bool keeps_runs() const { return local_ == nullptr || local_->keeps_runs(); }

  // Queues already expanded specs with their keys as one batch and waits until every run has ended;
  // progress on stderr. Returns the batch id.
  StatusOr<std::int64_t> RunBatch(const std::vector<experiment::ExperimentSpec>& specs, const std::vector<RunKey>& keys,
                                  const std::string& batch_name, const std::string& batch_json);
  // The runs of a batch (batch != 0) or the listed runs, with their metrics, spec and times (no history).
  StatusOr<std::vector<RunView>> Runs(std::int64_t batch, const std::vector<std::int64_t>& run_ids);
  // The comparison of those runs (repeats grouped by case).
  StatusOr<experiment::Comparison> Compare(std::int64_t batch, const std::vector<std::int64_t>& run_ids);
  StatusOr<Trace> GetTrace(std::int64_t run_id);
  // A run as the API gives it, with its spec: what its export file holds besides the trace (client/run_file.h).
  StatusOr<valvebench::v1::Run> ApiRun(std::int64_t run_id);
  // The runs of a report with their traces (client/report_runs.h, as the web's batch report gathers them).
  StatusOr<client::ReportRuns> ReportRuns(std::int64_t batch, const std::vector<std::int64_t>& run_ids,
                                          const client::ReportLimits& limits);
  // Waits until each run has ended, in order, calling on_ended(id) after each (client/batch_wait.h).
  Status WaitForRuns(const std::vector<std::int64_t>& run_ids, const std::function<void(std::int64_t)>& on_ended);
  // The benches runs go to here, and the USB devices the service's machine sees.
  StatusOr<valvebench::v1::ListBenchesResponse> Benches();
  // The bench twin's tracking kept by the service's nights (GetBenchHealth; "" = every checked bench).
  StatusOr<valvebench::v1::GetBenchHealthResponse> BenchHealth(const std::string& bench);
  // The gap diagnosis of stored runs, computed by the service (DiagnoseRuns: one diagnosis for every door).
  StatusOr<valvebench::v1::DiagnoseRunsResponse> DiagnoseRuns(const valvebench::v1::DiagnoseRunsRequest& request);
  // Queues a spec's runs as one batch (realtime: paced to the wall clock).
  StatusOr<Submitted> Submit(const experiment::ExperimentSpec& spec, bool realtime);
  // The whole trace, every channel, of a run the local service executed with keep_traces (--trace-csv); nullopt
  // remotely or when not kept. Everything else about a run, its loop statistics included, is on the stored run.
  std::optional<experiment::Trace> KeptTrace(std::int64_t run_id) const;
  // One run with its spec and status history.
  StatusOr<RunView> GetRun(std::int64_t run_id);
  // Runs matching the filter, at most filter.limit, in the service's order (newest first); *more: more matched.
  // *total (optional): how many runs match (all pages; 0 when the service does not say).
  StatusOr<std::vector<RunView>> ListRuns(const RunFilter& filter, bool* more, std::int64_t* total = nullptr);
  // The running runs and the queue with positions and ETAs (GetQueue).
  StatusOr<valvebench::v1::GetQueueResponse> Queue();
  // Asks the run to stop and returns it as it is then: a queued run is cancelled at once, a running one
  // stops within a control period of whoever executes it.
  StatusOr<RunView> Cancel(std::int64_t run_id, const std::string& reason);
  // Calls on_event (id, status, progress, reason) on every change until the run has ended or on_event
  // returns false.
  Status Watch(std::int64_t run_id, const std::function<bool(const RunView&)>& on_event);
  // Stores a measured dataset's runs (benchctl import).
  StatusOr<valvebench::v1::SubmitRunResponse> Import(const valvebench::v1::ImportRunsRequest& request);

  // Baselines and regression results, kept in this service's store beside its runs (docs/regress.md): the
  // server's with --server, the local store's otherwise. Not with --no-store (keeps_runs() false): a record
  // nobody can read back is refused, naming --db.
  StatusOr<regress::Baseline> SaveBaseline(const regress::Baseline& baseline);
  StatusOr<regress::Baseline> GetBaseline(const std::string& name, int version);  // 0 = the newest
  StatusOr<std::vector<regress::Baseline>> ListBaselines();
  StatusOr<std::int64_t> SaveRegression(const regress::RegressResult& result);
  StatusOr<valvebench::v1::Regression> GetRegression(std::int64_t id);
  // The service's store as a whole (benchctl db info).
  StatusOr<valvebench::v1::DescribeStoreResponse> DescribeStore();
  // Whether records can be kept here: InvalidArgument naming --db for a local service with --no-store.
  Status RecordsKept() const;

 private:
  // A local service's errors that name nothing of where (a run not found) name its store; with `always`,
  // any error of either service does (records: which store refused the baseline or has none of that name).
  Status Named(Status st, bool always = false) const;

  Status broken_;
  std::string where_;
  std::unique_ptr<server::LocalService> local_;  // declared before c_: destroyed after the client
  std::unique_ptr<client::Client> c_;
};

// A run as the API gives it, as commands see it.
RunView FromProto(const valvebench::v1::Run& r);
// The server's comparison (CompareRuns) as the experiment::Comparison every renderer takes.
StatusOr<experiment::Comparison> RemoteComparison(client::Client& client, std::int64_t batch,
                                                  const std::vector<std::int64_t>& run_ids);
// The one decision: a server address given (and not overridden by --local) means that server; else a local
// service over store_path ("" = --no-store: a private store that lives as long as the backend).
std::unique_ptr<Backend> ChooseBackend(const std::string& server, const std::string& store_path,
                                       const std::function<std::unique_ptr<client::Client>()>& make_client,
                                       LocalUse use = {});
// Where local runs are recorded: $VALVEBENCH_DB, else ~/.local/share/valvebench/local.db, else ./valvebench-local.db.
std::string DefaultLocalStorePath();

}  // namespace vb::benchctl
