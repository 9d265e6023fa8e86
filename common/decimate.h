// Min/max decimation of uniformly sampled channels for drawing, and the sample window a time window selects:
// the one decimator the server's GetTrace (max_points, from_s, to_s) and the HTML report use.
//
// The samples k0 <= k < k1 are cut into max_points / 2 buckets of (nearly) equal length; each bucket gives two
// rows, at the times of its first and last sample. Each channel puts its minimum and its maximum over the
// bucket into those two rows, in the order they occurred (a rising edge stays rising), so every peak survives
// and a bucket is narrower than a pixel at the default sizes. A window of at most max_points samples is passed
// through unchanged, one row per sample.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "common/status.h"

namespace vb {

// Samples [k0, k1) of a trace of `total` samples t0_s + k * sample_period_s.
struct SampleWindow {
  std::int64_t k0 = 0;
  std::int64_t k1 = 0;
  std::int64_t count() const { return k1 - k0; }
};

// The samples of [from_s, to_s]; where from_s or to_s falls between two samples, the one outside too (so a
// drawn line reaches the window's edges). to_s <= from_s means to the end. Clamped to the trace. from_s and
// to_s must be finite (the caller checks).
SampleWindow WindowOf(double t0_s, double sample_period_s, std::int64_t total, double from_s, double to_s);

// InvalidArgument naming the field: max_points is 0 (every sample) or 2..kMaxDecimatedPoints; from_s and to_s
// are finite.
inline constexpr std::int64_t kMaxDecimatedPoints = 1'000'000;
Status CheckDecimation(std::int64_t max_points, double from_s, double to_s);

// Fed the window's samples in increasing k (others are ignored), one call per sample; the rows come out as
// buckets complete, to be taken with TakeRows() whenever the caller wants to send them (streaming: only a
// bucket and the rows not yet taken are in memory).
class MinMaxDecimator {
 public:
  // channels: how many values each sample has. max_points >= 2.
  MinMaxDecimator(std::size_t channels, SampleWindow window, std::int64_t max_points, double t0_s,
                  double sample_period_s);

  bool decimating() const { return decimating_; }

  // value(j) is channel j's value of sample k.
  template <class Value>
  void Add(std::int64_t k, Value&& value) {
    if (k < window_.k0 || k >= window_.k1) return;
    if (!decimating_) {
      t_.push_back(TimeOf(k));
      for (std::size_t j = 0; j < rows_.size(); ++j) rows_[j].push_back(value(j));
      return;
    }
    while (k >= end_) NextBucket();
    if (!open_) {
      first_k_ = k;
      for (std::size_t j = 0; j < rows_.size(); ++j) {
        const double v = value(j);
        lo_[j] = hi_[j] = v;
        lo_k_[j] = hi_k_[j] = k;
      }
      open_ = true;
    } else {
      for (std::size_t j = 0; j < rows_.size(); ++j) {
        const double v = value(j);
        // NaN never wins against a number; a number replaces a NaN.
        if (v < lo_[j] || (std::isnan(lo_[j]) && !std::isnan(v))) {
          lo_[j] = v;
          lo_k_[j] = k;
        }
        if (v > hi_[j] || (std::isnan(hi_[j]) && !std::isnan(v))) {
          hi_[j] = v;
          hi_k_[j] = k;
        }
      }
    }
    last_k_ = k;
  }
  // Closes the last bucket (call once, after the last sample).
  void Finish();

  // The rows made so far and not yet taken: times and, per channel, the values (same length as times).
  struct Rows {
    std::vector<double> t_s;
    std::vector<std::vector<double>> values;  // [channel][row]
  };
  Rows TakeRows();
  std::size_t pending_rows() const { return t_.size(); }

 private:
  double TimeOf(std::int64_t k) const { return t0_s_ + static_cast<double>(k) * period_s_; }
  void Flush();
  void NextBucket();

  SampleWindow window_;
  bool decimating_ = false;
  std::int64_t buckets_ = 1, bucket_ = 0, end_ = 0;
  double t0_s_ = 0.0, period_s_ = 0.0;
  bool open_ = false;
  std::int64_t first_k_ = 0, last_k_ = 0;
  std::vector<double> lo_, hi_;
  std::vector<std::int64_t> lo_k_, hi_k_;
  std::vector<double> t_;
  std::vector<std::vector<double>> rows_;
};

// In-memory columns (equal lengths) decimated at once: the report's traces.
MinMaxDecimator::Rows DecimateColumns(const std::vector<const std::vector<double>*>& columns, double t0_s,
                                      double sample_period_s, std::int64_t max_points);

}  // namespace vb
