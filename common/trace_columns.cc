#include "common/trace_columns.h"

#include <algorithm>

namespace vb {

Status TraceDecoder::Add(const ChunkView& c) {
  const std::string where = "trace chunk " + std::to_string(c.index);
  if (c.index != next_index_)
    return Status::DataLoss(where + " arrived, expected " + std::to_string(next_index_));
  if (c.channels == nullptr || c.samples < 0) return Status::DataLoss(where + ": no channels or negative samples");
  if (next_index_ == 0) {
    wire_channels_ = *c.channels;
    trace_.t0_s = c.t0_s;
    trace_.sample_period_s = c.sample_period_s;
    trace_.total_samples = c.total_samples;
    trace_.decimated = c.decimated;
    keep_.clear();
    for (const auto& name : wire_channels_) {
      const bool kept = only_.empty() || std::find(only_.begin(), only_.end(), name) != only_.end();
      keep_.push_back(kept ? 1 : 0);
      if (!kept) continue;
      trace_.channels.push_back(name);
      auto& col = trace_.columns[name];
      if (!c.decimated && c.t_s == nullptr && c.total_samples > 0) col.reserve(static_cast<std::size_t>(c.total_samples));
    }
  } else if (*c.channels != wire_channels_) {
    return Status::DataLoss(where + ": its channels differ from chunk 0's");
  }
  const bool timed = c.t_s != nullptr;
  const auto n = static_cast<std::size_t>(c.samples);
  if (n > 0) {
    if (rows_seen_ && timed != timed_) return Status::DataLoss(where + ": times given on some chunks only");
    timed_ = timed;
    rows_seen_ = true;
  }
  if (n > 0 && c.data == nullptr) return Status::DataLoss(where + ": no data for " + std::to_string(n) + " samples");
  for (std::size_t ch = 0; ch < wire_channels_.size(); ++ch) {
    if (!keep_[ch]) continue;
    auto& col = trace_.columns[wire_channels_[ch]];
    col.insert(col.end(), c.data + ch * n, c.data + (ch + 1) * n);
  }
  if (timed) trace_.t_s.insert(trace_.t_s.end(), c.t_s, c.t_s + n);
  ++next_index_;
  return Status::Ok();
}

void TraceDecoder::DropRows() {
  for (auto& [name, col] : trace_.columns) col.clear();
  trace_.t_s.clear();
}

}  // namespace vb
