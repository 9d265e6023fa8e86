#include "db/trace_writer.h"

#include <algorithm>

namespace vb::db {

Status AppendTrace(Store* store, const Lease& lease, const TraceSource& source, int chunk_samples) {
  if (chunk_samples <= 0) return Status::InvalidArgument("chunk_samples: must be > 0");
  const std::size_t n = source.samples;
  const std::size_t step = static_cast<std::size_t>(chunk_samples);
  TraceChunk chunk;
  chunk.channels = source.channels;
  chunk.sample_period_s = source.sample_period_s;
  int index = 0;
  for (std::size_t start = 0; start < n; start += step, ++index) {
    const std::size_t count = std::min(n - start, step);
    chunk.index = index;
    chunk.t0_s = source.t_s(start);
    chunk.samples = static_cast<std::int32_t>(count);
    chunk.data.resize(source.channels.size() * count);
    for (std::size_t c = 0; c < source.channels.size(); ++c)
      for (std::size_t k = 0; k < count; ++k) chunk.data[c * count + k] = source.value(c, start + k);
    VB_RETURN_IF_ERROR(store->AppendTraceChunk(lease, chunk));
  }
  return Status::Ok();
}

}  // namespace vb::db
