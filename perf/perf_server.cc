// Bench-server figures on loopback: submit-to-done latency of a 0.1 s emulated run, runs per second for tiny
// runs, time to fetch a 1 M-sample trace, and 64 concurrent clients. Starts the real valvebench-server.
// Targets (docs/perf.md, "Bench server"): a 1 M-sample trace back to the client in < 100 ms; 64 concurrent
// clients without errors.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <thread>
#include <vector>

#include "../tests/integration/server_process.h"
#include "client/client.h"
#include "experiment/spec.h"

namespace {

using Clock = std::chrono::steady_clock;
namespace v1 = valvebench::v1;

double Since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

v1::ExperimentSpec Run(double duration_s, double rate_Hz) {
  auto s = vb::experiment::ParseSpecJson(R"({"name": "perf", "conditions": {"supply_V": 24, "supply_pressure_Pa": 400000},
      "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 50, "duty": 0.4}]}}})");
  s->set_duration_s(duration_s);
  s->mutable_recording()->set_rate_hz(rate_Hz);
  return *s;
}

bool WaitDone(vb::client::Client& c, std::int64_t id) {
  for (;;) {
    auto r = c.GetRun(id);
    if (!r.ok()) return false;
    if (r->status() == v1::DONE) return true;
    if (r->status() == v1::FAILED || r->status() == v1::CANCELLED) return false;
    std::this_thread::sleep_for(std::chrono::microseconds(500));
  }
}

}  // namespace

// The server's folder (its store, about 270 MB after these runs) is removed when the program ends; declared
// before the server, so the server has stopped by then.
struct RemovedAtExit {
  std::string dir;
  ~RemovedAtExit() {
    std::error_code ec;
    std::filesystem::remove_all(dir, ec);
  }
};

int main() {
  std::error_code ec;
  const RemovedAtExit scratch{(std::filesystem::temp_directory_path(ec) / ("vb-perf-server-" + std::to_string(::getpid()))).string()};
  vb::testing::ServerProcess server(scratch.dir);
  const std::string addr = server.Start();
  if (addr.empty()) {
    std::fprintf(stderr, "server did not start:\n%s\n", server.Log().c_str());
    return 2;
  }
  vb::client::ClientOptions o;
  o.address = addr;
  o.token = vb::testing::kOperatorToken;
  vb::client::Client c(o);

  // 1. Submit-to-done latency, 0.1 s emulated run at 50 kHz (5001 samples), median of 20.
  std::vector<double> lat;
  for (int k = 0; k < 20; ++k) {
    const auto t0 = Clock::now();
    auto sub = c.Submit(Run(0.1, 50e3));
    if (!sub.ok() || !WaitDone(c, sub->run_ids(0))) return 3;
    lat.push_back(Since(t0));
  }
  std::sort(lat.begin(), lat.end());
  std::printf("submit-to-done, 0.1 s run at 50 kHz: median %.1f ms, max %.1f ms (20 runs)\n", lat[10] * 1e3,
              lat.back() * 1e3);

  // 2. Throughput of tiny runs (1 ms, 1 kHz): one batch of 500 on the two benches.
  {
    auto spec = Run(0.001, 1e3);
    spec.set_repeats(500);
    const auto t0 = Clock::now();
    auto sub = c.Submit(spec);
    if (!sub.ok() || !WaitDone(c, sub->run_ids(sub->run_ids_size() - 1))) return 4;
    for (auto id : sub->run_ids())
      if (!WaitDone(c, id)) return 4;
    const double s = Since(t0);
    std::printf("tiny runs: 500 in %.2f s = %.0f runs/s (2 benches)\n", s, 500 / s);
  }

  // 3. Fetch a 1 M-sample trace (12 channels): a 1 s run at 1 MHz.
  {
    auto sub = c.Submit(Run(1.0, 1e6));
    if (!sub.ok() || !WaitDone(c, sub->run_ids(0))) return 5;
    std::vector<double> t;
    size_t n = 0;
    for (int k = 0; k < 5; ++k) {
      const auto t0 = Clock::now();
      auto trace = c.GetTrace(sub->run_ids(0));
      if (!trace.ok()) return 5;
      t.push_back(Since(t0));
      n = trace->samples();
    }
    std::sort(t.begin(), t.end());
    std::printf("fetch a %zu-sample trace (12 channels, %.0f MB): median %.1f ms, best %.1f ms (target < 100 ms)\n",
                n, n * 12 * 8 / 1e6, t[2] * 1e3, t[0] * 1e3);
  }

  // 4. 64 concurrent clients, each: submit a tiny run, poll it to done, read it, list runs.
  {
    std::atomic<int> errors{0}, calls{0};
    const auto t0 = Clock::now();
    std::vector<std::thread> threads;
    for (int k = 0; k < 64; ++k) {
      threads.emplace_back([&] {
        vb::client::Client mine(o);
        for (int j = 0; j < 5; ++j) {
          auto sub = mine.Submit(Run(0.001, 1e3));
          calls++;
          if (!sub.ok() || !WaitDone(mine, sub->run_ids(0))) {
            errors++;
            continue;
          }
          auto r = mine.GetRun(sub->run_ids(0));
          v1::ListRunsRequest req;
          req.set_page_size(20);
          auto l = mine.ListRuns(req);
          calls += 2;
          if (!r.ok() || !l.ok()) errors++;
        }
      });
    }
    for (auto& th : threads) th.join();
    std::printf("64 concurrent clients: %d calls (plus polling) in %.2f s, %d errors (target 0)\n", calls.load(),
                Since(t0), errors.load());
  }
  return 0;
}
