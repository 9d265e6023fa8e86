// Writes a uniformly sampled multi-channel trace into the store as consecutive chunks. Neutral about where
// the samples come from (the experiment's Trace, a dataset, a device), so db/ depends on nothing above it.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "db/store.h"

namespace vb::db {

struct TraceSource {
  std::vector<std::string> channels;
  double sample_period_s = 0.0;
  std::size_t samples = 0;
  std::function<double(std::size_t k)> t_s;                      // time of sample k
  std::function<double(std::size_t channel, std::size_t k)> value;
};

inline constexpr int kDefaultChunkSamples = 16384;  // small BLOBs read back fast (docs/perf.md)

Status AppendTrace(Store* store, const Lease& lease, const TraceSource& source,
                   int chunk_samples = kDefaultChunkSamples);

// Any recorded trace with ChannelNames(), size(), t_s[k], sample_period_s and Value(channel, k) -- such as
// experiment::Trace -- without db/ depending on the layer that defines it.
template <typename RecordedTrace>
Status AppendRecordedTrace(Store* store, const Lease& lease, const RecordedTrace& trace) {
  TraceSource src;
  src.channels = RecordedTrace::ChannelNames();
  src.sample_period_s = trace.sample_period_s;
  src.samples = trace.size();
  src.t_s = [&](std::size_t k) { return trace.t_s[k]; };
  src.value = [&](std::size_t c, std::size_t k) { return trace.Value(c, k); };
  return AppendTrace(store, lease, src);
}

}  // namespace vb::db
