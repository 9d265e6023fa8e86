// Trace ingest and read-back speed of the SQLite store (db/store.h) on a real file: a 1 M-sample trace of
// 12 float64 channels appended in chunks (one transaction per chunk, as a worker does), then read back whole.
// Prints figures; targets (docs/store.md): ingest >= 5 M samples/s, read back of 1 M samples < 100 ms.
// A "sample" is one instant of all 12 channels (12 values, 96 bytes).
//
// Usage: perf_store [DIR [CHUNK_SAMPLES...]]   (database DIR/perf_store.db, default $TMPDIR or /tmp, removed
//        after; chunk sizes default to 1000 10000 65536 100000)
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

#include <unistd.h>

#include "db/store.h"
#include "db/text.h"

namespace {

using Clock = std::chrono::steady_clock;

constexpr int kSamples = 1'000'000;
constexpr int kChannels = 12;
constexpr int kRepeats = 5;
constexpr double kIngestTarget = 5e6;   // samples/s
constexpr double kReadTargetMs = 100;   // for kSamples

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

void Die(const vb::Status& s, const char* what) {
  std::fprintf(stderr, "perf_store: %s: %s\n", what, s.ToString().c_str());
  std::exit(3);
}

// The chunks of one trace, generated before timing (a slow sine plus noise per channel: realistic values,
// not zeros that some layer could shortcut).
std::vector<vb::db::TraceChunk> MakeTrace(int chunk_samples) {
  std::vector<std::string> channels;
  for (int c = 0; c < kChannels; ++c) channels.push_back(vb::db::Cat("ch", c));
  std::mt19937_64 rng(42);
  std::normal_distribution<double> noise(0.0, 1e-3);
  std::vector<vb::db::TraceChunk> chunks;
  const double period = 1e-5;
  for (int start = 0, idx = 0; start < kSamples; start += chunk_samples, ++idx) {
    vb::db::TraceChunk ch;
    ch.index = idx;
    ch.t0_s = start * period;
    ch.sample_period_s = period;
    ch.samples = std::min(chunk_samples, kSamples - start);
    ch.channels = channels;
    ch.data.resize(static_cast<std::size_t>(kChannels) * ch.samples);
    for (int c = 0; c < kChannels; ++c) {
      for (int k = 0; k < ch.samples; ++k) {
        ch.data[static_cast<std::size_t>(c) * ch.samples + k] = std::sin(1e-3 * (start + k) + c) + noise(rng);
      }
    }
    chunks.push_back(std::move(ch));
  }
  return chunks;
}

std::int64_t NewRunningRun(vb::db::Store& store) {
  vb::db::RunRecord r;
  r.key = vb::NamedRun("perf");
  r.controller = "pi_current";
  r.bench_kind = "emulated";
  r.spec_json = "{}";
  std::vector<std::int64_t> ids;
  auto b = store.SubmitBatch("perf", "perf", "{}", {r}, &ids);
  if (!b.ok()) Die(b.status(), "submit");
  auto c = store.ClaimNext("emulated", "perf-bench");
  if (!c.ok()) Die(c.status(), "claim");
  return ids[0];
}


std::unique_ptr<vb::db::Store> OpenFresh(const std::string& path) {
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((path + suffix).c_str());
  auto opened = vb::db::Store::Open(path);
  if (!opened.ok()) Die(opened.status(), "open");
  return std::move(opened).value();
}

struct Figures {
  double ingest_samples_per_s;  // median over the traces
  double read_ms;               // median
};

// kRepeats traces of kSamples in `chunk_samples` chunks, one after the other, into a fresh database.
Figures MeasureTraces(const std::string& path, int chunk_samples) {
  const auto chunks = MakeTrace(chunk_samples);
  auto store = OpenFresh(path);
  sync();  // start with no dirty pages left over from the previous configuration
  std::vector<double> ingest_s, read_s;
  for (int rep = 0; rep < kRepeats; ++rep) {
    const std::int64_t run = NewRunningRun(*store);
    const auto t0 = Clock::now();
    for (const auto& ch : chunks) {
      vb::Status s = store->AppendTraceChunk(run, ch);
      if (!s.ok()) Die(s, "append");
    }
    const auto t1 = Clock::now();
    auto back = store->ReadTrace(run);
    const auto t2 = Clock::now();
    if (!back.ok()) Die(back.status(), "read");
    ingest_s.push_back(Seconds(t1 - t0));
    read_s.push_back(Seconds(t2 - t1));
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
  const Figures fig{kSamples / Median(ingest_s), 1e3 * Median(read_s)};
  std::printf("%14d %8zu %18.3g %8.0f %14.1f   ", chunk_samples, chunks.size(), fig.ingest_samples_per_s,
              8.0 * kChannels * fig.ingest_samples_per_s / 1e6, fig.read_ms);
  for (double s : ingest_s) std::printf(" %.0f", 1e3 * s);
  std::printf("%s\n", fig.ingest_samples_per_s >= kIngestTarget && fig.read_ms < kReadTargetMs
                          ? ""
                          : "   (misses a target)");
  return fig;
}

// Sustained: kRepeats traces appended back to back with nothing in between, then the Store closed, which
// waits for the last checkpoint: every sample is then in the database file and fsynced. Disk-bound.
void MeasureSustained(const std::string& path, int chunk_samples) {
  const auto chunks = MakeTrace(chunk_samples);
  auto store = OpenFresh(path);
  sync();
  std::vector<std::int64_t> runs;
  for (int rep = 0; rep < kRepeats; ++rep) runs.push_back(NewRunningRun(*store));
  const auto t0 = Clock::now();
  for (std::int64_t run : runs) {
    for (const auto& ch : chunks) {
      vb::Status s = store->AppendTraceChunk(run, ch);
      if (!s.ok()) Die(s, "append");
    }
  }
  const auto t1 = Clock::now();
  store.reset();
  const auto t2 = Clock::now();
  const double samples = static_cast<double>(kSamples) * kRepeats;
  std::printf("\nsustained, %d traces of %d-sample chunks back to back: %.3g samples/s until the last append "
              "returned,\n  %.3g samples/s until closed (all checkpointed into the database file and fsynced)\n",
              kRepeats, chunk_samples, samples / Seconds(t1 - t0), samples / Seconds(t2 - t0));
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
    auto c = store->ClaimNext("emulated", "perf-bench");
    if (!c.ok() || !c->has_value()) Die(c.ok() ? vb::Status::Internal("queue empty") : c.status(), "claim");
    vb::Status f = store->Finish((*c)->id, vb::db::RunStatus::kDone, "", {{"rmse_A", 0.01}, {"effort_J", 1.0}});
    if (!f.ok()) Die(f, "finish");
  }
  const auto q2 = Clock::now();
  std::printf("\nqueue (%d runs, one transaction each): submit %.0f runs/s, claim + finish %.0f runs/s\n", kQueueRuns,
              kQueueRuns / Seconds(q1 - q0), kQueueRuns / Seconds(q2 - q1));
}

}  // namespace

int main(int argc, char** argv) {
  const char* tmp = std::getenv("TMPDIR");
  const std::string dir = argc > 1 ? argv[1] : (tmp != nullptr ? tmp : "/tmp");
  std::vector<int> chunk_sizes;
  for (int k = 2; k < argc; ++k) chunk_sizes.push_back(std::max(1, std::atoi(argv[k])));
  if (chunk_sizes.empty()) chunk_sizes = {1'000, 10'000, 65'536};
  const std::string path = dir + "/perf_store.db";

  std::printf("perf_store: %d samples x %d channels (float64, %.0f MB per trace) into %s\n", kSamples, kChannels,
              8.0 * kSamples * kChannels / 1e6, path.c_str());
  std::printf("one transaction per chunk; %d traces back to back per chunk size, fresh database each; medians\n",
              kRepeats);
  std::printf("targets: ingest >= %.0f M samples/s, read back < %.0f ms\n\n", kIngestTarget / 1e6, kReadTargetMs);
  std::printf("%14s %8s %18s %8s %14s    %s\n", "chunk samples", "chunks", "ingest samples/s", "MB/s",
              "read back ms", "ingest ms of each trace");
  int met = 0;
  for (int chunk_samples : chunk_sizes) {
    const Figures fig = MeasureTraces(path, chunk_samples);
    met += fig.ingest_samples_per_s >= kIngestTarget && fig.read_ms < kReadTargetMs;
  }
  MeasureSustained(path, 65'536);
  MeasureQueue(path);
  for (const char* suffix : {"", "-wal", "-shm"}) std::remove((path + suffix).c_str());
  std::printf("\ntargets met for %d of %zu chunk sizes\n", met, chunk_sizes.size());
  return 0;
}
