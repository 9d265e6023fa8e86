#include "common/decimate.h"

#include <algorithm>
#include <string>

namespace vb {

SampleWindow WindowOf(double t0_s, double sample_period_s, std::int64_t total, double from_s, double to_s) {
  SampleWindow w{0, std::max<std::int64_t>(0, total)};
  if (!(sample_period_s > 0.0) || w.k1 == 0) return w;
  const double n = static_cast<double>(w.k1);
  // Within a billionth of a sample a time is on the sample (0.5 s / 20 us is 24999.999999999996 in doubles).
  constexpr double kOnSample = 1e-9;
  w.k0 = static_cast<std::int64_t>(std::clamp(std::floor((from_s - t0_s) / sample_period_s + kOnSample), 0.0, n));
  if (to_s > from_s)
    w.k1 = static_cast<std::int64_t>(
        std::clamp(std::ceil((to_s - t0_s) / sample_period_s - kOnSample) + 1, 0.0, n));
  w.k1 = std::max(w.k1, w.k0);
  return w;
}

Status CheckDecimation(std::int64_t max_points, double from_s, double to_s) {
  if (max_points < 0 || max_points == 1 || max_points > kMaxDecimatedPoints)
    return Status::InvalidArgument("max_points: must be 0 (every sample) or 2.." + std::to_string(kMaxDecimatedPoints) +
                                   ", got " + std::to_string(max_points));
  if (!std::isfinite(from_s)) return Status::InvalidArgument("from_s: must be a finite time in seconds");
  if (!std::isfinite(to_s)) return Status::InvalidArgument("to_s: must be a finite time in seconds");
  return Status::Ok();
}

MinMaxDecimator::MinMaxDecimator(std::size_t channels, SampleWindow window, std::int64_t max_points, double t0_s,
                                 double sample_period_s)
    : window_(window), t0_s_(t0_s), period_s_(sample_period_s) {
  const std::int64_t limit = std::max<std::int64_t>(2, max_points);
  decimating_ = window.count() > limit;
  buckets_ = std::max<std::int64_t>(1, limit / 2);
  bucket_ = 0;
  end_ = window_.k0 + window_.count() / buckets_;
  lo_.assign(channels, 0.0);
  hi_.assign(channels, 0.0);
  lo_k_.assign(channels, 0);
  hi_k_.assign(channels, 0);
  rows_.assign(channels, {});
}

void MinMaxDecimator::Flush() {
  if (!open_) return;
  t_.push_back(TimeOf(first_k_));
  t_.push_back(TimeOf(last_k_));
  for (std::size_t j = 0; j < rows_.size(); ++j) {
    const bool min_first = lo_k_[j] <= hi_k_[j];
    rows_[j].push_back(min_first ? lo_[j] : hi_[j]);
    rows_[j].push_back(min_first ? hi_[j] : lo_[j]);
  }
  open_ = false;
}

void MinMaxDecimator::NextBucket() {
  Flush();
  ++bucket_;
  // Bucket b holds [k0 + count * b / buckets, k0 + count * (b + 1) / buckets); past the last: the window's end.
  end_ = bucket_ >= buckets_ ? window_.k1 + 1 : window_.k0 + window_.count() * (bucket_ + 1) / buckets_;
}

void MinMaxDecimator::Finish() { Flush(); }

MinMaxDecimator::Rows MinMaxDecimator::TakeRows() {
  Rows out;
  out.t_s.swap(t_);
  out.values.resize(rows_.size());
  for (std::size_t j = 0; j < rows_.size(); ++j) out.values[j].swap(rows_[j]);
  return out;
}

MinMaxDecimator::Rows DecimateColumns(const std::vector<const std::vector<double>*>& columns, double t0_s,
                                      double sample_period_s, std::int64_t max_points) {
  std::size_t n = columns.empty() ? 0 : columns[0]->size();
  for (const auto* c : columns) n = std::min(n, c->size());
  MinMaxDecimator d(columns.size(), {0, static_cast<std::int64_t>(n)}, max_points, t0_s, sample_period_s);
  for (std::size_t k = 0; k < n; ++k) d.Add(static_cast<std::int64_t>(k), [&](std::size_t j) { return (*columns[j])[k]; });
  d.Finish();
  return d.TakeRows();
}

}  // namespace vb
