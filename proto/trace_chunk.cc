#include "proto/trace_chunk.h"

#include <cstring>
#include <vector>

namespace vb::api {

Status DecodeChunk(const valvebench::v1::TraceChunk& chunk, TraceDecoder* decoder) {
  const std::string where = "trace chunk " + std::to_string(chunk.index());
  if (chunk.samples() < 0) return Status::DataLoss(where + ": negative samples");
  const auto n = static_cast<std::size_t>(chunk.samples());
  const std::vector<std::string> channels(chunk.channels().begin(), chunk.channels().end());
  if (chunk.data().size() != n * channels.size() * sizeof(double))
    return Status::DataLoss(where + ": data size does not match samples x channels");
  if (chunk.t_s_size() != 0 && static_cast<std::size_t>(chunk.t_s_size()) != n)
    return Status::DataLoss(where + ": " + std::to_string(chunk.t_s_size()) + " times for " + std::to_string(n) +
                            " samples");
  std::vector<double> values(n * channels.size());
  if (!values.empty()) std::memcpy(values.data(), chunk.data().data(), values.size() * sizeof(double));
  ChunkView view;
  view.index = chunk.index();
  view.t0_s = chunk.t0_s();
  view.sample_period_s = chunk.sample_period_s();
  view.samples = chunk.samples();
  view.total_samples = chunk.total_samples();
  view.channels = &channels;
  view.data = values.data();
  view.t_s = chunk.t_s_size() != 0 ? chunk.t_s().data() : nullptr;
  view.decimated = chunk.decimated();
  return decoder->Add(view);
}

}  // namespace vb::api
