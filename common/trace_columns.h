// A stored trace as columns by channel name, and the one decoder that builds it from trace chunks (the
// store's, or GetTrace's on the wire through proto/trace_chunk.h): order, channel and size checks in one place.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "common/status.h"

namespace vb {

struct TraceColumns {
  double t0_s = 0.0;
  double sample_period_s = 0.0;
  std::vector<std::string> channels;                   // in the stored order (kept ones only)
  std::map<std::string, std::vector<double>> columns;  // by channel name
  // Rows that are not uniformly spaced (GetTrace with max_points > 0): each row's time. Empty: row k is at
  // t0_s + k * sample_period_s.
  std::vector<double> t_s;
  std::int64_t total_samples = 0;  // the stored trace's length, whatever window or decimation was asked
  bool decimated = false;          // rows are min/max pairs of buckets (common/decimate.h), not samples

  std::size_t samples() const { return columns.empty() ? 0 : columns.begin()->second.size(); }
  double TimeAt(std::size_t row) const {
    return t_s.empty() ? t0_s + static_cast<double>(row) * sample_period_s : t_s[row];
  }
  // The column of a channel, or null.
  const std::vector<double>* Find(const std::string& channel) const {
    auto it = columns.find(channel);
    return it == columns.end() ? nullptr : &it->second;
  }
};

// One chunk as decoded values: `data` is channels.size() * samples values, channel-major; `t_s` is null or
// `samples` times.
struct ChunkView {
  std::int32_t index = 0;
  double t0_s = 0.0;
  double sample_period_s = 0.0;
  std::int32_t samples = 0;
  std::int64_t total_samples = 0;
  const std::vector<std::string>* channels = nullptr;
  const double* data = nullptr;
  const double* t_s = nullptr;
  bool decimated = false;
};

class TraceDecoder {
 public:
  // only: keep just these channels (empty = every channel).
  explicit TraceDecoder(std::vector<std::string> only = {}) : only_(std::move(only)) {}

  // Appends a chunk. DataLoss when chunks come out of order (index), change their channels, or carry a time
  // column of another length.
  Status Add(const ChunkView& c);
  // Chunk count so far.
  std::int32_t chunks() const { return next_index_; }
  const TraceColumns& trace() const { return trace_; }
  TraceColumns Take() { return std::move(trace_); }
  // Forgets the rows decoded so far, keeps the position and the header (streaming a trace chunk by chunk).
  void DropRows();

 private:
  std::vector<std::string> only_;
  std::vector<int> keep_;          // chunk channel index -> kept (1) or not
  std::vector<std::string> wire_channels_;
  std::int32_t next_index_ = 0;
  bool rows_seen_ = false;
  bool timed_ = false;             // the first chunk with rows carried times: every chunk with rows must
  TraceColumns trace_;
};

}  // namespace vb
