// The one min/max decimator (common/decimate.h) and the one trace decoder (common/trace_columns.h,
// proto/trace_chunk.h): peaks survive, rows are bounded, windows respected, bad chunks refused.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "common/decimate.h"
#include "common/trace_columns.h"
#include "proto/trace_chunk.h"

namespace vb {
namespace {

TEST(Decimate, PeaksOfEveryChannelSurviveInBoundedRows) {
  const std::size_t n = 100001;
  std::vector<double> i(n), x(n);
  for (std::size_t k = 0; k < n; ++k) {
    i[k] = std::sin(k * 1e-3);
    x[k] = std::cos(k * 7e-4);
  }
  i[54321] = 5.0;   // a one-sample spike up in one channel ...
  x[12345] = -9.0;  // ... and down in another, elsewhere
  const auto rows = DecimateColumns({&i, &x}, 0.5, 1e-5, 1000);
  ASSERT_EQ(rows.t_s.size(), 1000u) << "500 buckets, two rows each";
  ASSERT_EQ(rows.values.size(), 2u);
  const auto peak = std::max_element(rows.values[0].begin(), rows.values[0].end());
  EXPECT_EQ(*peak, 5.0);
  const double t_peak = rows.t_s[static_cast<std::size_t>(peak - rows.values[0].begin())];
  EXPECT_NEAR(t_peak, 0.5 + 54321e-5, 201e-5) << "within its bucket (~200 samples)";
  EXPECT_EQ(*std::min_element(rows.values[1].begin(), rows.values[1].end()), -9.0);
  EXPECT_TRUE(std::is_sorted(rows.t_s.begin(), rows.t_s.end()));
  EXPECT_DOUBLE_EQ(rows.t_s.front(), 0.5);
  EXPECT_DOUBLE_EQ(rows.t_s.back(), 0.5 + (n - 1) * 1e-5) << "the last bucket reaches the last sample";
}

TEST(Decimate, ExtremesKeepTheirOrderSoAnEdgeStaysAnEdge) {
  std::vector<double> up(1000), down(1000);
  for (std::size_t k = 0; k < up.size(); ++k) {
    up[k] = static_cast<double>(k);
    down[k] = -static_cast<double>(k);
  }
  const auto rows = DecimateColumns({&up, &down}, 0.0, 1.0, 10);
  ASSERT_EQ(rows.t_s.size(), 10u);
  for (std::size_t r = 0; r + 1 < rows.t_s.size(); r += 2) {
    EXPECT_LT(rows.values[0][r], rows.values[0][r + 1]) << "rising: min first, row " << r;
    EXPECT_GT(rows.values[1][r], rows.values[1][r + 1]) << "falling: max first, row " << r;
  }
}

TEST(Decimate, ShortWindowsPassThroughAndNaNNeverHidesANumber) {
  std::vector<double> v = {NAN, 1, 2, NAN, 4};
  const auto whole = DecimateColumns({&v}, 0.0, 0.1, 10);
  ASSERT_EQ(whole.t_s.size(), 5u);
  EXPECT_DOUBLE_EQ(whole.t_s[3], 0.3);
  EXPECT_TRUE(std::isnan(whole.values[0][0]));
  std::vector<double> w(100, NAN);
  w[50] = 3.0;
  const auto rows = DecimateColumns({&w}, 0.0, 1.0, 4);  // 2 buckets: [0, 50) and [50, 100)
  ASSERT_EQ(rows.t_s.size(), 4u);
  EXPECT_EQ(rows.values[0][2], 3.0);
  EXPECT_EQ(rows.values[0][3], 3.0);
}

TEST(Decimate, WindowsAreTheSamplesOfTheTimeSpan) {
  // 1 s at 50 kHz: [0.1, 0.1002] is samples 5000..5010.
  const SampleWindow w = WindowOf(0.0, 2e-5, 50001, 0.1, 0.1002);
  EXPECT_EQ(w.k0, 5000);
  EXPECT_EQ(w.k1, 5011);
  const SampleWindow open_end = WindowOf(0.0, 2e-5, 50001, 0.5, 0.0);
  EXPECT_EQ(open_end.k0, 25000);
  EXPECT_EQ(open_end.k1, 50001) << "to_s <= from_s: to the end";
  const SampleWindow before = WindowOf(1.0, 2e-5, 100, -1e300, 0.5);
  EXPECT_EQ(before.count(), 0) << "a window before the trace is empty";
  const SampleWindow after = WindowOf(0.0, 2e-5, 100, 7.0, 8.0);
  EXPECT_EQ(after.count(), 0);
  EXPECT_EQ(WindowOf(0.0, 2e-5, 100, -1e300, -1e300).count(), 100);
}

TEST(Decimate, BadRequestsNameTheirField) {
  EXPECT_TRUE(CheckDecimation(0, 0, 0).ok());
  EXPECT_TRUE(CheckDecimation(2, 0.1, 0.2).ok());
  for (std::int64_t bad : {std::int64_t{-1}, std::int64_t{1}, kMaxDecimatedPoints + 1}) {
    const Status st = CheckDecimation(bad, 0, 0);
    EXPECT_EQ(st.code(), StatusCode::kInvalidArgument) << bad;
    EXPECT_EQ(st.message().rfind("max_points:", 0), 0u) << st.message();
  }
  EXPECT_EQ(CheckDecimation(0, NAN, 0).message().rfind("from_s:", 0), 0u);
  EXPECT_EQ(CheckDecimation(0, 0, INFINITY).message().rfind("to_s:", 0), 0u);
}

valvebench::v1::TraceChunk Chunk(int index, const std::vector<std::string>& channels,
                                 const std::vector<double>& channel_major, int samples) {
  valvebench::v1::TraceChunk c;
  c.set_index(index);
  c.set_t0_s(0.25);
  c.set_sample_period_s(0.5);
  c.set_samples(samples);
  c.set_total_samples(4);
  for (const auto& ch : channels) c.add_channels(ch);
  c.set_data(std::string(reinterpret_cast<const char*>(channel_major.data()), channel_major.size() * sizeof(double)));
  return c;
}

TEST(TraceDecoder, ChunksBecomeColumnsInOrder) {
  TraceDecoder d;
  ASSERT_TRUE(api::DecodeChunk(Chunk(0, {"t_s", "i_A"}, {0.25, 0.75, 1, 2}, 2), &d).ok());
  ASSERT_TRUE(api::DecodeChunk(Chunk(1, {"t_s", "i_A"}, {1.25, 1.75, 3, 4}, 2), &d).ok());
  const TraceColumns t = d.Take();
  EXPECT_EQ(t.channels, (std::vector<std::string>{"t_s", "i_A"}));
  EXPECT_EQ(*t.Find("i_A"), (std::vector<double>{1, 2, 3, 4}));
  EXPECT_EQ(t.samples(), 4u);
  EXPECT_EQ(t.total_samples, 4);
  EXPECT_DOUBLE_EQ(t.TimeAt(3), 1.75);
  EXPECT_FALSE(t.decimated);
}

TEST(TraceDecoder, KeepsOnlyTheAskedChannelsAndTimedRows) {
  TraceDecoder d({"i_A"});
  auto c = Chunk(0, {"gate", "i_A"}, {0, 1, 5, 6}, 2);
  c.add_t_s(0.0);
  c.add_t_s(9.0);
  c.set_decimated(true);
  ASSERT_TRUE(api::DecodeChunk(c, &d).ok());
  EXPECT_EQ(d.trace().channels, (std::vector<std::string>{"i_A"}));
  EXPECT_EQ(d.trace().Find("gate"), nullptr);
  EXPECT_DOUBLE_EQ(d.trace().TimeAt(1), 9.0);
  EXPECT_TRUE(d.trace().decimated);
}

TEST(TraceDecoder, RefusesChunksOutOfOrderOrOfTheWrongSize) {
  TraceDecoder d;
  EXPECT_EQ(api::DecodeChunk(Chunk(1, {"i_A"}, {1}, 1), &d).code(), StatusCode::kDataLoss);
  EXPECT_EQ(api::DecodeChunk(Chunk(0, {"i_A"}, {1, 2}, 3), &d).code(), StatusCode::kDataLoss);
  ASSERT_TRUE(api::DecodeChunk(Chunk(0, {"i_A"}, {1}, 1), &d).ok());
  EXPECT_EQ(api::DecodeChunk(Chunk(1, {"x_m"}, {1}, 1), &d).code(), StatusCode::kDataLoss) << "channels changed";
  auto timed = Chunk(1, {"i_A"}, {1}, 1);
  timed.add_t_s(1.0);
  EXPECT_EQ(api::DecodeChunk(timed, &d).code(), StatusCode::kDataLoss) << "times on some chunks only";
}

}  // namespace
}  // namespace vb
