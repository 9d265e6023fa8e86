// How a TraceChunk is stored in a trace_chunks row (docs/store.md, "Trace encoding").
//
//   data     BLOB: channels.size() * samples IEEE-754 binary64 values, little-endian, channel-major (all samples
//            of channel 0, then all of channel 1, ...), exactly TraceChunk::data; no header, no compression.
//            Bit-exact: NaN payloads, signed zeros and infinities come back as they went in.
//   channels TEXT: the channel names joined by '\n' (names are non-empty, unique, without '\n').
//   samples, t0, period: their own columns.
//
// Internal to db/.
#pragma once

#include <bit>
#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "common/status.h"
#include "db/store.h"

namespace vb::db::trace {

inline constexpr bool kNativeIsLittleEndian = std::endian::native == std::endian::little;
static_assert(kNativeIsLittleEndian || std::endian::native == std::endian::big, "mixed-endian hosts unsupported");
static_assert(sizeof(double) == 8, "binary64 doubles required");

// Checks a chunk on its own (shape, names, times); messages start with "trace chunk <index>: ".
Status ValidateChunk(const TraceChunk& chunk);

std::string JoinChannels(const std::vector<std::string>& channels);
std::vector<std::string> SplitChannels(std::string_view joined);

// The BLOB bytes for `values`. On little-endian hosts the in-memory array already is the encoding and the
// store binds it directly (no copy); this is the big-endian path.
std::string EncodeValues(const std::vector<double>& values);
// DataLoss unless a stored BLOB of `size` bytes holds exactly `expected_values` float64s. `what` names the chunk.
Status CheckSize(std::size_t size, std::size_t expected_values, std::string_view what);
// Turns values read verbatim from a BLOB into native doubles (nothing to do on little-endian hosts).
void FromLittleEndian(std::vector<double>* values);

}  // namespace vb::db::trace
