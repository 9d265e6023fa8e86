// Compressed trace chunks (db/trace_codec.h, docs/store.md "Trace encoding"): bit-exact round trips of every
// transform on values that must survive bit for bit, corrupt BLOBs refused as DataLoss, and the schema v4
// migration: chunks stored raw by an older build stay readable next to compressed ones.
// The store-level tests at the end (codec 1 written, a v3 file's raw chunks beside new ones) inspect the SQLite
// file itself and stay SQLite-only; the codec-0 layout is read back on both engines in store_test.cc.
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <set>

#include "db/schema.h"
#include "db/sqlite_conn.h"
#include "db/sqlite_store.h"
#include "db/store.h"
#include "db/testing.h"
#include "db/text.h"
#include "db/trace_codec.h"

namespace vb::db {
namespace {

using trace::Codec1;
using trace::Transform;

bool BitEqual(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0);
}

double FromBits(std::uint64_t u) { return std::bit_cast<double>(u); }

// Values whose bits must come back exactly.
std::vector<double> Awkward() {
  return {FromBits(0x7ff8dead0000beefULL),  // quiet NaN with a payload
          FromBits(0xfff0000000000001ULL),  // signalling NaN, negative
          FromBits(0x7ff0000000000001ULL),  // signalling NaN, positive
          std::numeric_limits<double>::quiet_NaN(),
          -0.0,
          0.0,
          std::numeric_limits<double>::infinity(),
          -std::numeric_limits<double>::infinity(),
          std::numeric_limits<double>::denorm_min(),
          -std::numeric_limits<double>::denorm_min(),
          FromBits(0x000fffffffffffffULL),  // largest subnormal
          std::numeric_limits<double>::min(),
          std::numeric_limits<double>::max(),
          -std::numeric_limits<double>::max(),
          1.0,
          -1.0};
}

// Channels shaped like a recorded run, each of which should pick a different transform, plus awkward values.
std::vector<double> PhysicalChannels(std::size_t n, std::vector<std::string>* names) {
  *names = {"t_s", "gate", "i_A", "noise", "awkward", "counter", "walk"};
  std::vector<double> data(names->size() * n);
  std::mt19937_64 rng(7);
  const std::vector<double> awkward = Awkward();
  double count = 0;
  std::uint64_t walk = 0x4000000000100000ULL;  // irregular small steps in the low mantissa bits
  for (std::size_t k = 0; k < n; ++k) {
    const int step = static_cast<int>(rng() % 200) - 100;
    walk += static_cast<std::uint64_t>(static_cast<std::int64_t>(step == 0 ? 1 : step));
    data[6 * n + k] = FromBits(walk);
    data[0 * n + k] = static_cast<double>(k) * 1.2e-5;                      // time
    data[1 * n + k] = (k / 37) % 2 == 0 ? 1.0 : 0.0;                        // gate
    data[2 * n + k] = 0.5 + 0.1 * std::sin(1e-3 * static_cast<double>(k));  // slow current
    data[3 * n + k] = FromBits(rng());                                      // random bits (incl. NaNs)
    data[4 * n + k] = awkward[k % awkward.size()];
    if (k % 37 == 0) count += 1;
    data[5 * n + k] = count;
  }
  return data;
}

TEST(TraceCodecTest, EveryTransformRoundTripsBitExactForAnyLength) {
  Codec1 codec;
  std::set<Transform> used;
  for (std::size_t n : {1u, 2u, 3u, 8u, 100u, 4096u, 4097u, 20000u}) {
    std::vector<std::string> names;
    const std::vector<double> data = PhysicalChannels(n, &names);
    std::string blob;
    ASSERT_TRUE(codec.Encode(data.data(), names.size(), n, &blob).ok());
    for (Transform t : codec.last_transforms()) used.insert(t);
    std::vector<double> back(data.size());
    auto st = codec.Decode(blob.data(), blob.size(), names.size(), n, back.data(), "chunk");
    ASSERT_TRUE(st.ok()) << st.ToString();
    EXPECT_TRUE(BitEqual(back, data)) << n << " samples";
  }
  // Each inverse path was exercised (a test of a transform never chosen would prove nothing).
  EXPECT_EQ(used, (std::set<Transform>{Transform::kNone, Transform::kXor, Transform::kDelta,
                                       Transform::kDeltaOfDelta}));
}

TEST(TraceCodecTest, EachTransformAloneRoundTripsAwkwardValues) {
  // One channel of awkward values in every position relative to its neighbours, forced through each
  // transform by its neighbours' shape: constant run, then the values, then a ramp.
  Codec1 codec;
  std::vector<double> data;
  for (int k = 0; k < 50; ++k) data.push_back(3.0);
  for (double v : Awkward()) data.push_back(v);
  for (double v : Awkward()) data.push_back(v), data.push_back(-0.0);
  for (int k = 0; k < 50; ++k) data.push_back(k * 0.25);
  std::string blob;
  ASSERT_TRUE(codec.Encode(data.data(), 1, data.size(), &blob).ok());
  std::vector<double> back(data.size());
  ASSERT_TRUE(codec.Decode(blob.data(), blob.size(), 1, data.size(), back.data(), "chunk").ok());
  EXPECT_TRUE(BitEqual(back, data));
  // Each transform in turn, chosen by the shape of the channel around the awkward values: the probes (windows
  // at the start, a third, two thirds and the end of the chunk) see only that shape, and the awkward values sit
  // between the first two windows.
  for (int t = 0; t < 4; ++t) {
    std::vector<double> ch;
    std::uint64_t walk = 0x4000000000100000ULL;
    auto pattern = [&](int k) {
      switch (t) {
        case 0:  // subnormals of one byte between zeros: as they are, half the words are 0; any difference is not
          return FromBits(k % 2 == 0 ? static_cast<std::uint64_t>(1 + (k * 37) % 255) : 0);
        case 1:  // random low bits under a fixed top: xor keeps 2 bytes, differences often 3
          return FromBits(0x4000000000000000ULL | ((static_cast<std::uint64_t>(k) * 2654435761ULL) & 0xffff));
        case 2:  // a random walk of irregular small steps: differences 1 byte, xor 2 at byte borders
          walk += static_cast<std::uint64_t>(static_cast<std::int64_t>(1 + (k * 7919) % 100) * (k % 3 == 0 ? -1 : 1));
          return FromBits(walk);
        default: return FromBits(0x4000000000000000ULL + 1000ULL * static_cast<std::uint64_t>(k));  // steady ramp
      }
    };
    int k = 0;
    for (; k < 2000; ++k) ch.push_back(pattern(k));
    ch.insert(ch.end(), data.begin(), data.end());
    for (; k < 40000; ++k) ch.push_back(pattern(k));
    ASSERT_TRUE(codec.Encode(ch.data(), 1, ch.size(), &blob).ok());
    EXPECT_EQ(static_cast<int>(codec.last_transforms()[0]), t);
    std::vector<double> out(ch.size());
    ASSERT_TRUE(codec.Decode(blob.data(), blob.size(), 1, ch.size(), out.data(), "chunk").ok());
    EXPECT_TRUE(BitEqual(out, ch)) << "transform " << t;
  }
}

TEST(TraceCodecTest, PhysicalSignalsCompressAndNoiseDoesNotGrowMuch) {
  Codec1 codec;
  const std::size_t n = 16384;
  std::vector<double> smooth(3 * n);
  for (std::size_t k = 0; k < n; ++k) {
    smooth[k] = static_cast<double>(k) * 1e-5;
    smooth[n + k] = (k / 120) % 2 == 0 ? 24.0 : -0.7;
    smooth[2 * n + k] = 1e-3 * static_cast<double>(k / 50);
  }
  std::string blob;
  ASSERT_TRUE(codec.Encode(smooth.data(), 3, n, &blob).ok());
  EXPECT_LT(blob.size() * 20, smooth.size() * 8) << blob.size();  // > 20x on these shapes
  std::mt19937_64 rng(1);
  std::vector<double> noise(n);
  for (double& v : noise) v = FromBits(rng());
  ASSERT_TRUE(codec.Encode(noise.data(), 1, n, &blob).ok());
  EXPECT_LT(blob.size(), n * 8 + n * 8 / 100) << "incompressible data may grow by < 1 %";
}

TEST(TraceCodecTest, CorruptBlobsAreDataLossNeverACrash) {
  Codec1 codec;
  std::vector<std::string> names;
  const std::size_t n = 3000;
  const std::vector<double> data = PhysicalChannels(n, &names);
  std::string blob;
  ASSERT_TRUE(codec.Encode(data.data(), names.size(), n, &blob).ok());
  std::vector<double> out(data.size());
  auto decode = [&](const std::string& b, std::size_t channels, std::size_t samples) {
    out.assign(channels * samples, 0.0);
    return codec.Decode(b.data(), b.size(), channels, samples, out.data(), "trace of run 1, chunk 0");
  };
  // Truncated, too short for the header, an unknown transform, the wrong shape, trailing bytes.
  for (const std::string& bad : {blob.substr(0, blob.size() - 5), blob.substr(0, 3),
                                 std::string(1, '\x09') + blob.substr(1), blob + "x"}) {
    auto st = decode(bad, names.size(), n);
    EXPECT_EQ(st.code(), StatusCode::kDataLoss) << st.ToString();
    EXPECT_NE(st.message().find("trace of run 1, chunk 0"), std::string::npos) << st.message();
  }
  EXPECT_EQ(decode(blob, names.size(), n + 1).code(), StatusCode::kDataLoss);
  // Flipped bytes inside the frame: either refused, or (if zstd cannot tell) decoded to the right size; never
  // out of bounds (the sanitizer build would say so).
  std::mt19937 rng(3);
  for (int trial = 0; trial < 200; ++trial) {
    std::string b = blob;
    b[2 * names.size() + rng() % (b.size() - 2 * names.size())] ^= static_cast<char>(1 + rng() % 255);
    (void)decode(b, names.size(), n);
  }
}

// ---- through the store ----

void RemoveDbFiles(const std::string& path) {
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) std::remove((path + suffix).c_str());
}

std::string TempDb(const std::string& name) {
  const std::string path = Cat(::testing::TempDir(), "vb_codec_test_", name, "_", getpid(), ".db");
  RemoveDbFiles(path);
  return path;
}

std::int64_t SubmitAndClaim(Store& store) {
  RunRecord r;
  r.key = NamedRun("a");
  r.controller = "pi_current";
  r.bench_kind = "emulated";
  r.spec_json = "{}";
  std::vector<std::int64_t> ids;
  EXPECT_TRUE(store.SubmitBatch("alice", "b", "{}", {r}, &ids).ok());
  EXPECT_TRUE(store.ClaimNext(db::BenchClaim("emulated", "bench-1")).ok());
  return ids.at(0);
}

TEST(TraceCodecTest, StoreWritesCodec1AndReadsItBackBitExact) {
  const std::string path = TempDb("store_codec1");
  std::vector<std::string> names;
  const std::size_t n = 5000;
  TraceChunk c;
  c.index = 0;
  c.sample_period_s = 1.2e-5;
  c.samples = static_cast<std::int32_t>(n);
  c.data = PhysicalChannels(n, &names);
  c.channels = names;
  std::int64_t id = 0;
  {
    auto store = std::move(OpenSqliteStore(path)).value();
    id = SubmitAndClaim(*store);
    ASSERT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, id), c).ok());
    auto back = store->ReadTrace(id);
    ASSERT_TRUE(back.ok()) << back.status().ToString();
    ASSERT_EQ(back->size(), 1u);
    EXPECT_TRUE(BitEqual((*back)[0].data, c.data));
  }
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* st = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "SELECT codec, length(data) FROM trace_chunks", -1, &st, nullptr), SQLITE_OK);
  ASSERT_EQ(sqlite3_step(st), SQLITE_ROW);
  EXPECT_EQ(sqlite3_column_int(st, 0), 1);
  EXPECT_LT(sqlite3_column_int64(st, 1), static_cast<std::int64_t>(c.data.size() * 8));
  sqlite3_finalize(st);
  // A chunk whose stored BLOB was damaged reads back as DataLoss naming the run and chunk, not garbage.
  ASSERT_EQ(sqlite3_exec(db, "UPDATE trace_chunks SET data = substr(data, 1, length(data) - 10)", nullptr, nullptr,
                         nullptr),
            SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, "UPDATE trace_chunks SET codec = 1", nullptr, nullptr, nullptr), SQLITE_OK);
  sqlite3_close(db);
  auto store = std::move(OpenSqliteStore(path)).value();
  auto back = store->ReadTrace(id);
  ASSERT_FALSE(back.ok());
  EXPECT_EQ(back.status().code(), StatusCode::kDataLoss);
  EXPECT_NE(back.status().message().find(Cat("trace of run ", id, ", chunk 0")), std::string::npos)
      << back.status().message();
  RemoveDbFiles(path);
}

TEST(TraceCodecTest, Version3RawTracesStayReadableAfterTheMigrationBesideNewCompressedChunks) {
  const std::string path = TempDb("v3_to_v4");
  {
    auto conn = sql::Connection::Open(path);
    ASSERT_TRUE(conn.ok());
    auto v = schema::Migrate(&*conn, schema::Migrations().first(3), path);
    ASSERT_TRUE(v.ok()) << v.status().ToString();
    ASSERT_EQ(*v, 3);
  }
  // A version-3 file as the previous build wrote it: one run with one raw chunk (little-endian float64,
  // channel-major; the bytes written here by hand, as that build wrote them).
  const std::vector<double> old_values = {1.0, -0.0, FromBits(0x7ff8dead0000beefULL),
                                          std::numeric_limits<double>::denorm_min(), 2.5, 3.5};
  {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
    ASSERT_EQ(sqlite3_exec(db,
                           "INSERT INTO batches (id, submitter, name, spec_json, created) VALUES (1, 'u', 'b', '{}', 0);"
                           "INSERT INTO runs (id, batch_id, name, controller, bench_kind, requested_bench, "
                           "bench_name, spec_json, submitter, priority, status, requeue_on_interrupt, submitted) "
                           "VALUES (1, 1, 'old', 'pi_current', 'emulated', '', 'b1', '{}', 'u', 0, 'running', 1, 0)",
                           nullptr, nullptr, nullptr),
              SQLITE_OK);
    std::string le;
    for (double v : old_values) {
      const std::uint64_t u = std::bit_cast<std::uint64_t>(v);
      for (int b = 0; b < 8; ++b) le.push_back(static_cast<char>(u >> (8 * b)));
    }
    sqlite3_stmt* st = nullptr;
    ASSERT_EQ(sqlite3_prepare_v2(db, "INSERT INTO trace_chunks (run_id, idx, t0, period, samples, channels, data) "
                                     "VALUES (1, 0, 0.0, 0.001, 3, 'a\nb', ?1)",
                                 -1, &st, nullptr),
              SQLITE_OK);
    sqlite3_bind_blob(st, 1, le.data(), static_cast<int>(le.size()), SQLITE_TRANSIENT);
    ASSERT_EQ(sqlite3_step(st), SQLITE_DONE);
    sqlite3_finalize(st);
    sqlite3_close(db);
  }
  auto opened = OpenSqliteStore(path);
  ASSERT_TRUE(opened.ok()) << opened.status().ToString();
  auto& store = *opened;
  EXPECT_EQ(store->schema_version(), schema::CurrentVersion());
  // The same run goes on with a new chunk: compressed, and the trace reads back whole, both codecs in one.
  TraceChunk next;
  next.index = 1;
  next.t0_s = 0.003;
  next.sample_period_s = 0.001;
  next.samples = 2;
  next.channels = {"a", "b"};
  next.data = {-std::numeric_limits<double>::infinity(), 7.0, FromBits(0xfff0000000000001ULL), 8.0};
  ASSERT_TRUE(store->AppendTraceChunk(vb::db::testing::CurrentLease(store, 1), next).ok());
  auto back = store->ReadTrace(1);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ASSERT_EQ(back->size(), 2u);
  EXPECT_EQ((*back)[0].channels, (std::vector<std::string>{"a", "b"}));
  EXPECT_TRUE(BitEqual((*back)[0].data, old_values));
  EXPECT_TRUE(BitEqual((*back)[1].data, next.data));
  store.reset();
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  sqlite3_stmt* st = nullptr;
  ASSERT_EQ(sqlite3_prepare_v2(db, "SELECT group_concat(codec) FROM (SELECT codec FROM trace_chunks ORDER BY idx)",
                               -1, &st, nullptr),
            SQLITE_OK);
  ASSERT_EQ(sqlite3_step(st), SQLITE_ROW);
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(st, 0)), "0,1");  // the old chunk as it was
  sqlite3_finalize(st);
  sqlite3_close(db);
  RemoveDbFiles(path);
}

}  // namespace
}  // namespace vb::db
