// Trace ingest and read-back speed of the SQLite store (db/sqlite_store.h) on a real file: 1 M-sample traces of
// 12 float64 channels appended in chunks (one transaction per chunk, as a worker does), then read back whole,
// and how much smaller the compressed chunks are than the raw values (docs/store.md, "Trace encoding").
// Prints figures; targets (docs/store.md): ingest >= 5 M samples/s, read back of 1 M samples < 100 ms, stored
// size at most 1/4 of the raw values on a real emulator trace. A "sample" is one instant of all 12 channels
// (12 values, 96 bytes raw).
//
// Two traces: "emulator", a real recorded run (examples/standard/e1.json, 50 Hz PWM at 50 kHz, run for 20 s:
// 1 000 002 samples of the experiment's 12 channels), and "noise", a slow sine plus Gaussian noise in every
// channel (random low mantissa bytes everywhere: the codec's worst case for time and size).
// Times are wall clock on whatever else the machine is doing; the thread's CPU time is printed beside them.
//
// Usage: perf_store [DIR [CHUNK_SAMPLES...]]   (database DIR/perf_store.db, default $TMPDIR or /tmp, removed
//        after; chunk sizes default to 10000 16384 65536)
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <sqlite3.h>
#include <time.h>
#include <unistd.h>

#include "db/run_query.h"
#include "db/sqlite_store.h"
#include "db/store.h"
#include "db/text.h"
#include "experiment/runner.h"
#include "experiment/spec.h"
#include "hw/emulated_bench.h"

namespace {

using Clock = std::chrono::steady_clock;

constexpr int kSamples = 1'000'000;
constexpr int kChannels = 12;
constexpr int kRepeats = 5;
constexpr double kIngestTarget = 5e6;   // samples/s
constexpr double kReadTargetMs = 100;   // for kSamples

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

double ThreadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

void Die(const vb::Status& s, const char* what) {
  std::fprintf(stderr, "perf_store: %s: %s\n", what, s.ToString().c_str());
  std::exit(3);
}

// A whole trace, channel-major, before it is cut into chunks.
struct Trace {
  std::string name;
  std::vector<std::string> channels;
  double period_s = 0.0;
  std::size_t samples = 0;
  std::vector<double> data;  // channels.size() * samples
};

// A slow sine plus noise per channel: random low mantissa bytes in every value.
Trace NoiseTrace() {
  Trace t;
  t.name = "noise";
  for (int c = 0; c < kChannels; ++c) t.channels.push_back(vb::db::Cat("ch", c));
  t.period_s = 1e-5;
  t.samples = kSamples;
  t.data.resize(static_cast<std::size_t>(kChannels) * kSamples);
  std::mt19937_64 rng(42);
  std::normal_distribution<double> noise(0.0, 1e-3);
  for (int c = 0; c < kChannels; ++c)
    for (int k = 0; k < kSamples; ++k) t.data[static_cast<std::size_t>(c) * kSamples + k] = std::sin(1e-3 * k + c) + noise(rng);
  return t;
}

// A recorded emulator run of `spec` (optionally run for `duration_s` instead of the spec's duration).
Trace EmulatorTrace(const std::string& spec_name, double duration_s) {
  auto spec = vb::experiment::LoadSpecFile(std::string(VB_SOURCE_DIR) + "/examples/standard/" + spec_name + ".json");
  if (!spec.ok()) Die(spec.status(), "spec");
  if (duration_s > 0) spec->set_duration_s(duration_s);
  auto e = vb::experiment::BuildExperiment(*spec);
  if (!e.ok()) Die(e.status(), "experiment");
  vb::hw::EmulatedBench bench(vb::experiment::EmulatedBenchFor(*e));
  vb::experiment::Trace rec;
  const auto summary = vb::experiment::Runner::Run(*e, bench, &rec);
  if (!summary.ok()) Die(vb::Status::Internal(summary.message), "run");
  Trace t;
  t.name = spec_name;
  t.channels = vb::experiment::Trace::ChannelNames();
  t.period_s = rec.sample_period_s;
  t.samples = rec.size();
  t.data.resize(t.channels.size() * t.samples);
  for (std::size_t c = 0; c < t.channels.size(); ++c)
    for (std::size_t k = 0; k < t.samples; ++k) t.data[c * t.samples + k] = rec.Value(c, k);
  return t;
}

// The chunks of one trace, cut before timing.
std::vector<vb::db::TraceChunk> Chunks(const Trace& t, int chunk_samples) {
  std::vector<vb::db::TraceChunk> chunks;
  const std::size_t n = t.samples, step = static_cast<std::size_t>(chunk_samples);
  for (std::size_t start = 0, idx = 0; start < n; start += step, ++idx) {
    vb::db::TraceChunk ch;
    ch.index = static_cast<std::int32_t>(idx);
    ch.t0_s = static_cast<double>(start) * t.period_s;
    ch.sample_period_s = t.period_s;
    ch.samples = static_cast<std::int32_t>(std::min(step, n - start));
    ch.channels = t.channels;
    ch.data.resize(t.channels.size() * static_cast<std::size_t>(ch.samples));
    for (std::size_t c = 0; c < t.channels.size(); ++c)
      std::memcpy(&ch.data[c * ch.samples], &t.data[c * n + start], sizeof(double) * ch.samples);
    chunks.push_back(std::move(ch));
  }
  return chunks;
}

// Stored BLOB bytes of the trace chunks in the database at `path` (what the trace takes on disk, less the
// pages' slack), and the raw float64 bytes they hold.
std::pair<double, double> StoredAndRawBytes(const std::string& path) {
  sqlite3* db = nullptr;
  std::pair<double, double> out{0, 0};
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) == SQLITE_OK) {
    sqlite3_stmt* st = nullptr;
    const char* sql =
        "SELECT SUM(length(data)), SUM(8.0 * samples * (length(channels) - length(replace(channels, char(10), '')) + 1)) "
        "FROM trace_chunks";
    if (sqlite3_prepare_v2(db, sql, -1, &st, nullptr) == SQLITE_OK && sqlite3_step(st) == SQLITE_ROW)
      out = {sqlite3_column_double(st, 0), sqlite3_column_double(st, 1)};
    sqlite3_finalize(st);
  }
  sqlite3_close(db);
  return out;
}

vb::db::Lease NewRunningRun(vb::db::Store& store) {
  vb::db::RunRecord r;
  r.key = vb::NamedRun("perf");
  r.controller = "pi_current";
  r.bench_kind = "emulated";
  r.spec_json = "{}";
  std::vector<std::int64_t> ids;
  auto b = store.SubmitBatch("perf", "perf", "{}", {r}, &ids);
  if (!b.ok()) Die(b.status(), "submit");
  auto c = store.ClaimNext(vb::db::BenchClaim("emulated", "perf-bench"));
  if (!c.ok() || !c->has_value()) Die(c.ok() ? vb::Status::Internal("queue empty") : c.status(), "claim");
  return vb::db::LeaseOf(**c);
}


std::unique_ptr<vb::db::Store> OpenFresh(const std::string& path) {
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((path + suffix).c_str());
  auto opened = vb::db::OpenSqliteStore(path);
  if (!opened.ok()) Die(opened.status(), "open");
  return std::move(opened).value();
}

struct Figures {
  double ingest_samples_per_s;  // median over the traces
  double read_ms;               // median
  double ratio;                 // raw bytes / stored bytes
};

// kRepeats traces of `trace` in `chunk_samples` chunks, one after the other, into a fresh database.
Figures MeasureTraces(const std::string& path, const Trace& trace, int chunk_samples) {
  const auto chunks = Chunks(trace, chunk_samples);
  auto store = OpenFresh(path);
  sync();  // start with no dirty pages left over from the previous configuration
  std::vector<double> ingest_s, read_s, ingest_cpu_s, read_cpu_s;
  for (int rep = 0; rep < kRepeats; ++rep) {
    const vb::db::Lease run = NewRunningRun(*store);
    const double c0 = ThreadCpuSeconds();
    const auto t0 = Clock::now();
    for (const auto& ch : chunks) {
      vb::Status s = store->AppendTraceChunk(run, ch);
      if (!s.ok()) Die(s, "append");
    }
    const auto t1 = Clock::now();
    const double c1 = ThreadCpuSeconds();
    auto back = store->ReadTrace(run.run_id);
    const auto t2 = Clock::now();
    const double c2 = ThreadCpuSeconds();
    if (!back.ok()) Die(back.status(), "read");
    ingest_s.push_back(Seconds(t1 - t0));
    read_s.push_back(Seconds(t2 - t1));
    ingest_cpu_s.push_back(c1 - c0);
    read_cpu_s.push_back(c2 - c1);
    // Checked outside the timing: what came back is what went in, bit for bit.
    if (back->size() != chunks.size()) Die(vb::Status::DataLoss("chunk count differs"), "verify");
    for (std::size_t k = 0; k < chunks.size(); ++k) {
      const auto& a = chunks[k].data;
      const auto& b = (*back)[k].data;
      if (a.size() != b.size() || std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) != 0) {
        Die(vb::Status::DataLoss(vb::db::Cat("chunk ", k, " differs")), "verify");
      }
    }
    vb::Status f = store->Finish(run, vb::db::RunStatus::kDone, "", {});
    if (!f.ok()) Die(f, "finish");
  }
  store.reset();
  const auto [stored, raw] = StoredAndRawBytes(path);
  const double per_million = 1e6 / static_cast<double>(trace.samples);  // figures for 1 M samples
  const Figures fig{static_cast<double>(trace.samples) / Median(ingest_s), 1e3 * Median(read_s) * per_million,
                    stored > 0 ? raw / stored : 0.0};
  std::printf("%-9s %8d %7zu %10.3g %10.3g %8.1f %8.1f %7.2f   ", trace.name.c_str(), chunk_samples, chunks.size(),
              fig.ingest_samples_per_s, static_cast<double>(trace.samples) / Median(ingest_cpu_s), fig.read_ms,
              1e3 * Median(read_cpu_s) * per_million, fig.ratio);
  for (double s : ingest_s) std::printf(" %.0f", 1e3 * s);
  std::printf("%s\n", fig.ingest_samples_per_s >= kIngestTarget && fig.read_ms < kReadTargetMs
                          ? ""
                          : "   (misses a target)");
  return fig;
}

// Sustained: kRepeats traces appended back to back with nothing in between, then the Store closed, which
// waits for the last checkpoint: every sample is then in the database file and fsynced. Disk-bound.
void MeasureSustained(const std::string& path, const Trace& trace, int chunk_samples) {
  const auto chunks = Chunks(trace, chunk_samples);
  auto store = OpenFresh(path);
  sync();
  std::vector<vb::db::Lease> runs;
  for (int rep = 0; rep < kRepeats; ++rep) runs.push_back(NewRunningRun(*store));
  const auto t0 = Clock::now();
  for (const vb::db::Lease& run : runs) {
    for (const auto& ch : chunks) {
      vb::Status s = store->AppendTraceChunk(run, ch);
      if (!s.ok()) Die(s, "append");
    }
  }
  const auto t1 = Clock::now();
  store.reset();
  const auto t2 = Clock::now();
  const double samples = static_cast<double>(trace.samples) * kRepeats;
  std::printf("\nsustained, %d %s traces of %d-sample chunks back to back: %.3g samples/s until the last append "
              "returned,\n  %.3g samples/s until closed (all checkpointed into the database file and fsynced)\n",
              kRepeats, trace.name.c_str(), chunk_samples, samples / Seconds(t1 - t0), samples / Seconds(t2 - t0));
}

// The queue's small transactions, for scale: one-run batches submitted, then claimed and finished.
void MeasureQueue(const std::string& path) {
  constexpr int kQueueRuns = 2000;
  auto store = OpenFresh(path);
  vb::db::RunRecord r;
  r.key = vb::NamedRun("q");
  r.controller = "pi_current";
  r.bench_kind = "emulated";
  r.spec_json = "{\"name\": \"q\"}";
  r.tags = {"perf"};
  const auto q0 = Clock::now();
  for (int k = 0; k < kQueueRuns; ++k) {
    std::vector<std::int64_t> ids;
    auto b = store->SubmitBatch("perf", "q", "{}", {r}, &ids);
    if (!b.ok()) Die(b.status(), "submit");
  }
  const auto q1 = Clock::now();
  for (int k = 0; k < kQueueRuns; ++k) {
    auto c = store->ClaimNext(vb::db::BenchClaim("emulated", "perf-bench"));
    if (!c.ok() || !c->has_value()) Die(c.ok() ? vb::Status::Internal("queue empty") : c.status(), "claim");
    vb::Status f = store->Finish(vb::db::LeaseOf(**c), vb::db::RunStatus::kDone, "", {{"rmse_A", 0.01}, {"effort_J", 1.0}});
    if (!f.ok()) Die(f, "finish");
  }
  const auto q2 = Clock::now();
  std::printf("\nqueue (%d runs, one transaction each): submit %.0f runs/s, claim + finish %.0f runs/s\n", kQueueRuns,
              kQueueRuns / Seconds(q1 - q0), kQueueRuns / Seconds(q2 - q1));
}

// Listing (ListRuns/CountRuns, docs/store.md "Listing runs"): 20 000 runs with 1 KB specs, statuses and times
// spread out; the median of 20 calls each: the API's default first page (submitted desc), a page 100 pages deep
// by its keyset cursor, a full-sort order (duration desc), a name filter, and the counts.
void MeasureListing(const std::string& path) {
  constexpr int kBatches = 20, kPerBatch = 1000, kCalls = 20;
  auto store = OpenFresh(path);
  const std::string spec = "{\"name\": \"list\", \"pad\": \"" + std::string(1000, 'x') + "\"}";
  for (int b = 0; b < kBatches; ++b) {
    std::vector<vb::db::RunRecord> runs;
    for (int k = 0; k < kPerBatch; ++k) {
      vb::db::RunRecord r;
      r.key = vb::NamedRun(vb::db::Cat(k % 3 == 0 ? "hold-" : "map-", k % 97));
      r.controller = k % 2 == 0 ? "pi_current" : "bang_bang";
      r.bench_kind = "emulated";
      r.spec_json = spec;
      runs.push_back(std::move(r));
    }
    auto id = store->SubmitBatch("perf", "list", "{}", runs, nullptr);
    if (!id.ok()) Die(id.status(), "submit");
  }
  sqlite3* raw = nullptr;
  if (sqlite3_open(path.c_str(), &raw) != SQLITE_OK ||
      sqlite3_exec(raw,
                   "UPDATE runs SET submitted = submitted + id, started = 1e9 + id * 2.0, "
                   "finished = 1e9 + id * 2.0 + (id % 613) * 0.1, "
                   "status = CASE id % 4 WHEN 0 THEN 'failed' ELSE 'done' END",
                   nullptr, nullptr, nullptr) != SQLITE_OK) {
    Die(vb::Status::Internal(sqlite3_errmsg(raw)), "update");
  }
  sqlite3_close(raw);
  auto median_ms = [&](const auto& call) {
    std::vector<double> ms;
    for (int k = 0; k < kCalls; ++k) {
      const auto t0 = Clock::now();
      call();
      ms.push_back(1e3 * Seconds(Clock::now() - t0));
    }
    std::nth_element(ms.begin(), ms.begin() + kCalls / 2, ms.end());
    return ms[kCalls / 2];
  };
  vb::db::RunFilter newest;
  newest.order = {vb::db::RunSortKey::kSubmitted, true};
  auto page = [&](const vb::db::RunFilter& f) {
    auto r = store->ListRuns(f);
    if (!r.ok() || r->empty()) Die(r.ok() ? vb::Status::Internal("empty page") : r.status(), "list");
    return std::move(r).value();
  };
  auto count = [&](const vb::db::RunFilter& f) {
    auto n = store->CountRuns(f);
    if (!n.ok()) Die(n.status(), "count");
  };
  const double first = median_ms([&] { page(newest); });
  vb::db::RunFilter deep = newest;
  deep.limit = 1000;
  for (int k = 0; k < 10; ++k) deep.after = vb::db::CursorAfter(page(deep).back(), deep.order);  // 10 000 runs in
  deep.limit = 100;
  const double deep_ms = median_ms([&] { page(deep); });
  vb::db::RunFilter longest;
  longest.order = {vb::db::RunSortKey::kDuration, true};
  const double sorted_ms = median_ms([&] { page(longest); });
  vb::db::RunFilter named = newest;
  named.name = "map-7";
  const double named_ms = median_ms([&] { page(named); });
  const double count_ms = median_ms([&] { count(vb::db::RunFilter{}); });
  const double count_named_ms = median_ms([&] { count(named); });
  std::printf("\nlisting %d runs (100 per page, medians of %d): newest first %.2f ms, 100 pages deep %.2f ms, "
              "duration desc %.2f ms, name contains %.2f ms; count all %.2f ms, count by name %.2f ms\n",
              kBatches * kPerBatch, kCalls, first, deep_ms, sorted_ms, named_ms, count_ms, count_named_ms);
}

}  // namespace

int main(int argc, char** argv) {
  const char* tmp = std::getenv("TMPDIR");
  const std::string dir = argc > 1 ? argv[1] : (tmp != nullptr ? tmp : "/tmp");
  std::vector<int> chunk_sizes;
  for (int k = 2; k < argc; ++k) chunk_sizes.push_back(std::max(1, std::atoi(argv[k])));
  if (chunk_sizes.empty()) chunk_sizes = {10'000, 16'384, 65'536};
  const std::string path = dir + "/perf_store.db";

  // Compression on the standard experiments' own runs, as recorded (one trace each, 16384-sample chunks as
  // the run pipeline writes them).
  std::printf("compression of real emulator traces (examples/standard, 12 channels, as recorded):\n");
  for (const char* spec : {"e1", "e2", "e3"}) {
    const Trace t = EmulatorTrace(spec, 0.0);
    const auto chunks = Chunks(t, 16'384);
    auto store = OpenFresh(path);
    const vb::db::Lease run = NewRunningRun(*store);
    for (const auto& ch : chunks) {
      vb::Status s = store->AppendTraceChunk(run, ch);
      if (!s.ok()) Die(s, "append");
    }
    store.reset();
    const auto [stored, raw] = StoredAndRawBytes(path);
    std::printf("  %-3s %8zu samples: %10.0f bytes raw, %9.0f stored, %5.2fx smaller\n", spec, t.samples, raw, stored,
                raw / stored);
  }

  std::printf("\nperf_store: %d-sample traces x %d channels (float64, %.0f MB raw per trace) into %s\n", kSamples,
              kChannels, 8.0 * kSamples * kChannels / 1e6, path.c_str());
  std::printf("one transaction per chunk; %d traces back to back per chunk size, fresh database each; medians\n",
              kRepeats);
  std::printf("targets: ingest >= %.0f M samples/s, read back of 1 M samples < %.0f ms, >= 4x smaller (emulator)\n\n",
              kIngestTarget / 1e6, kReadTargetMs);
  std::printf("%-9s %8s %7s %10s %10s %8s %8s %7s    %s\n", "trace", "chunk", "chunks", "ingest/s", "(cpu)/s",
              "read ms", "(cpu)", "ratio", "ingest ms of each trace");
  const Trace emulator = EmulatorTrace("e1", 20.0);
  const Trace noise = NoiseTrace();
  int met = 0, measured = 0;
  for (const Trace* trace : {&emulator, &noise}) {
    for (int chunk_samples : chunk_sizes) {
      const Figures fig = MeasureTraces(path, *trace, chunk_samples);
      ++measured;
      met += fig.ingest_samples_per_s >= kIngestTarget && fig.read_ms < kReadTargetMs;
    }
  }
  MeasureSustained(path, emulator, 16'384);
  MeasureQueue(path);
  MeasureListing(path);
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((path + suffix).c_str());
  std::printf("\ntargets met for %d of %d configurations\n", met, measured);
  return 0;
}
