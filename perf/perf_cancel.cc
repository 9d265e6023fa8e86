// How long a cancel takes, from the request to the run's final state in the store (docs/server.md, "Cancel";
// the target is 100 ms of wall time). Three kinds of run, each ten minutes long so the cancel always lands
// mid-run:
//   open loop behind the interlocks (a server bench), open loop on the bare emulator (benchctl run --local,
//   where one PWM segment of ten minutes is a single Runner step), and a closed-loop PI current law.
// Each run is cancelled 150 ms after it starts, through the in-process registry (what CancelRun does on the
// host that executes the run) and, for the local kind, through the store (what another benchctl does).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <thread>
#include <unistd.h>
#include <vector>

#include "db/sqlite_store.h"
#include "db/store.h"
#include "experiment/spec.h"
#include "runs/admit.h"
#include "runs/bench_setup.h"
#include "runs/monitor.h"
#include "runs/worker.h"

namespace {

using Clock = std::chrono::steady_clock;

vb::experiment::ExperimentSpec Load(const std::string& rel, int variant) {
  auto spec = vb::experiment::LoadSpecFile(std::string(VB_SOURCE_DIR) + "/examples/" + rel);
  if (!spec.ok()) {
    std::fprintf(stderr, "%s: %s\n", rel.c_str(), spec.status().message().c_str());
    std::exit(3);
  }
  auto points = vb::experiment::ExpandRuns(*spec);
  if (!points.ok()) std::exit(3);
  vb::experiment::ExperimentSpec one = (*points)[static_cast<size_t>(variant)].spec;
  one.set_duration_s(600);
  return one;
}

// Cancels one run 150 ms after it starts; returns the ms from the request to Execute's return (the final
// state is then in the store).
double CancelOnce(const vb::experiment::ExperimentSpec& spec, bool interlocks, bool through_store,
                  const std::string& path) {
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((path + suffix).c_str());
  auto store = vb::db::OpenSqliteStore(path);
  if (!store.ok()) std::exit(3);
  vb::runs::BenchSetup bench = vb::runs::LocalEmulatorSetup();
  bench.interlocks = interlocks;
  bench.safety.max_current_A = 100;
  vb::runs::Policy policy;
  policy.benches = {bench};
  auto a = vb::runs::Admit({"perf", "cancel", {spec}, {}, ""}, policy);
  if (!a.ok()) {
    std::fprintf(stderr, "admit: %s\n", a.status().message().c_str());
    std::exit(3);
  }
  auto q = vb::runs::Enqueue(store->get(), std::move(*a), policy);
  if (!q.ok()) std::exit(3);
  const std::int64_t id = q->run_ids[0];
  vb::runs::Registry registry;
  vb::runs::Worker worker(bench, &registry);
  Clock::time_point asked;
  std::thread canceller([&] {
    double progress = 0.0;
    while (!registry.Progress(id, &progress)) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    std::this_thread::sleep_for(std::chrono::milliseconds(150));
    asked = Clock::now();
    if (through_store) {
      // Another process's request, seen by the executing side's 20 ms poll of the store (benchctl's relay).
      auto other = vb::db::OpenSqliteStore(path);
      if (other.ok()) (void)(*other)->RequestCancel(id, "perf");
      while (true) {
        auto c = (*other)->CancelRequested(id);
        if (c.ok() && *c && registry.Cancel(id)) break;
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
      }
    } else {
      registry.Cancel(id);
    }
  });
  auto o = worker.ClaimAndExecute(store->get());
  const Clock::time_point done = Clock::now();
  canceller.join();
  if (!o.ok() || !o->has_value() || (*o)->status != vb::db::RunStatus::kCancelled) {
    std::fprintf(stderr, "the run was not cancelled: %s\n",
                 o.ok() && o->has_value() ? (*o)->reason.c_str() : "no outcome");
    std::exit(1);
  }
  return std::chrono::duration<double, std::milli>(done - asked).count();
}

}  // namespace

int main() {
  const std::string path = "/tmp/perf_cancel_" + std::to_string(getpid()) + ".db";
  struct Case {
    const char* name;
    vb::experiment::ExperimentSpec spec;
    bool interlocks, through_store;
  };
  const std::vector<Case> cases = {
      {"open loop, interlocks (server bench), registry", Load("standard/e1.json", 0), true, false},
      {"open loop, bare emulator (run --local), registry", Load("standard/e1.json", 0), false, false},
      {"open loop, bare emulator, request via the store", Load("standard/e1.json", 0), false, true},
      {"PI current law, interlocks, registry", Load("compare-current-controllers.json", 1), true, false},
  };
  std::printf("cancel latency: request -> final state stored (ms), 10 runs of 600 s each, cancelled at 150 ms\n");
  std::printf("%-52s %8s %8s %8s\n", "run", "median", "p90", "max");
  for (const Case& c : cases) {
    std::vector<double> ms;
    for (int k = 0; k < 10; ++k) ms.push_back(CancelOnce(c.spec, c.interlocks, c.through_store, path));
    std::sort(ms.begin(), ms.end());
    std::printf("%-52s %8.1f %8.1f %8.1f\n", c.name, ms[4], ms[8], ms[9]);
  }
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((path + suffix).c_str());
  return 0;
}
