// The store on PostgreSQL next to SQLite (docs/store.md, "PostgreSQL"; docs/perf.md): the queue and trace
// ingest, the two things a lab's hosts do to the shared database all the time.
//   claims: 2000 queued runs claimed one by one (ClaimNext with host, lease and aging, as a lab host claims):
//           latency median and p99, claims/s from one connection, and claims/s from 4 connections at once
//           (4 threads, one Store each, until the queue is empty).
//   traces: 1 M samples of 12 float64 channels (96 MB raw) appended in 16384-sample chunks (one transaction
//           per chunk, as a worker does), raw MB/s in, stored MB, then read back whole (ms).
// Prints figures; there is no target to meet (a lab's claim rate is bounded by its benches, a few per second).
//
// Usage: perf_store_pg PG_LOCATION [SQLITE_DIR]
//   PG_LOCATION: a libpq connection string of an EMPTY database the program may fill (e.g. "host=/tmp/pg
//   dbname=perf"); SQLITE_DIR: where the SQLite file goes (default /tmp). Wall clock on a shared machine.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "db/open_store.h"
#include "db/store.h"
#include "db/text.h"

namespace {

using Clock = std::chrono::steady_clock;
constexpr int kRuns = 2000;
constexpr int kThreads = 4;
constexpr int kSamples = 1'000'000;
constexpr int kChunk = 16384;
constexpr int kChannels = 12;

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

[[noreturn]] void Die(const vb::Status& s, const char* what) {
  std::fprintf(stderr, "perf_store_pg: %s: %s\n", what, s.ToString().c_str());
  std::exit(3);
}

std::unique_ptr<vb::db::Store> Open(const std::string& location) {
  auto s = vb::db::OpenStore(location);
  if (!s.ok()) Die(s.status(), "open");
  return std::move(s).value();
}

void SubmitRuns(vb::db::Store& store, int n) {
  std::vector<vb::db::RunRecord> runs;
  for (int k = 0; k < n; ++k) {
    vb::db::RunRecord r;
    r.key = vb::NamedRun(vb::db::Cat("r", k));
    r.controller = "pi_current";
    r.bench_kind = "emulated";
    r.spec_json = "{}";
    r.priority = k % 5;
    runs.push_back(std::move(r));
  }
  auto b = store.SubmitBatch("perf", "claims", "{}", std::move(runs), nullptr);
  if (!b.ok()) Die(b.status(), "submit");
}

vb::db::ClaimRequest Claim(int host) {
  vb::db::ClaimRequest r = vb::db::BenchClaim("emulated", vb::db::Cat("bench-", host));
  r.host = vb::db::Cat("host-", host);
  r.lease_ttl_s = 30;
  r.aging_s = 60;
  return r;
}

void Claims(const char* engine, const std::string& location) {
  auto store = Open(location);
  SubmitRuns(*store, kRuns);
  std::vector<double> ms;
  const auto t0 = Clock::now();
  for (int k = 0; k < kRuns; ++k) {
    const auto a = Clock::now();
    auto c = store->ClaimNext(Claim(0));
    if (!c.ok() || !c->has_value()) Die(c.ok() ? vb::Status::Internal("queue empty early") : c.status(), "claim");
    ms.push_back(1e3 * Seconds(Clock::now() - a));
  }
  const double one_s = Seconds(Clock::now() - t0);
  std::sort(ms.begin(), ms.end());
  // The same again with 4 connections claiming at once.
  SubmitRuns(*store, kRuns);
  std::atomic<int> claimed{0};
  std::vector<std::thread> threads;
  const auto t1 = Clock::now();
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      auto s = Open(location);
      while (true) {
        auto c = s->ClaimNext(Claim(t));
        if (!c.ok()) Die(c.status(), "claim");
        if (!c->has_value()) return;
        ++claimed;
      }
    });
  }
  for (auto& th : threads) th.join();
  const double four_s = Seconds(Clock::now() - t1);
  std::printf(
      "%-10s claims: median %.3f ms, p99 %.3f ms, %.0f claims/s (1 connection); %.0f claims/s "
      "(%d connections, %d runs)\n",
      engine, ms[ms.size() / 2], ms[static_cast<std::size_t>(0.99 * static_cast<double>(ms.size()))], kRuns / one_s,
      claimed.load() / four_s, kThreads, claimed.load());
}

void Traces(const char* engine, const std::string& location) {
  auto store = Open(location);
  SubmitRuns(*store, 1);
  auto run = store->ClaimNext(Claim(9));
  if (!run.ok() || !run->has_value()) Die(run.ok() ? vb::Status::Internal("no run") : run.status(), "claim");
  const vb::db::Lease lease = vb::db::LeaseOf(**run);
  std::mt19937_64 rng(7);
  std::normal_distribution<double> noise(0.0, 1e-4);
  vb::db::TraceChunk c;
  c.sample_period_s = 2e-5;
  for (int ch = 0; ch < kChannels; ++ch) c.channels.push_back(vb::db::Cat("ch", ch));
  const auto t0 = Clock::now();
  int written = 0;
  for (int index = 0; written < kSamples; ++index) {
    const int n = std::min(kChunk, kSamples - written);
    c.index = index;
    c.t0_s = written * c.sample_period_s;
    c.samples = n;
    c.data.resize(static_cast<std::size_t>(kChannels) * static_cast<std::size_t>(n));
    for (int ch = 0; ch < kChannels; ++ch) {
      for (int k = 0; k < n; ++k) {
        const double t = (written + k) * c.sample_period_s;
        c.data[static_cast<std::size_t>(ch) * static_cast<std::size_t>(n) + static_cast<std::size_t>(k)] =
            ch == 0 ? t : std::sin(2 * M_PI * 50 * t + ch) + noise(rng);
      }
    }
    const vb::Status st = store->AppendTraceChunk(lease, c);
    if (!st.ok()) Die(st, "append");
    written += n;
  }
  const double in_s = Seconds(Clock::now() - t0);
  auto bytes = store->StoredTraceBytes("perf");
  if (!bytes.ok()) Die(bytes.status(), "stored bytes");
  const auto t1 = Clock::now();
  auto back = store->ReadTrace(lease.run_id);
  if (!back.ok()) Die(back.status(), "read");
  const double out_s = Seconds(Clock::now() - t1);
  const double raw_mb = static_cast<double>(kSamples) * kChannels * 8 / 1e6;
  std::printf(
      "%-10s traces: %.0f MB raw in %.2f s = %.0f MB/s (%.2f M samples/s), stored %.1f MB, "
      "read back in %.0f ms\n",
      engine, raw_mb, in_s, raw_mb / in_s, kSamples / in_s / 1e6, static_cast<double>(*bytes) / 1e6, 1e3 * out_s);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || !vb::db::IsPostgresLocation(argv[1])) {
    std::fprintf(stderr, "usage: perf_store_pg PG_LOCATION [SQLITE_DIR]  (an empty PostgreSQL database)\n");
    return 2;
  }
  const std::string pg = argv[1];
  const std::string dir = argc > 2 ? argv[2] : "/tmp";
  const std::string lite = vb::db::Cat(dir, "/perf_store_pg_", getpid(), ".db");
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((lite + suffix).c_str());
  std::printf(
      "perf_store_pg: %d claims, then %d with %d connections; a %d-sample trace of %d channels in "
      "%d-sample chunks\n",
      kRuns, kRuns, kThreads, kSamples, kChannels, kChunk);
  Claims("sqlite", lite);
  Claims("postgresql", pg);
  Traces("sqlite", lite);
  Traces("postgresql", pg);
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((lite + suffix).c_str());
  return 0;
}
