#include "db/trace_codec.h"

#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstring>
#include <unordered_set>

#include "common/format.h"
#include "db/text.h"

namespace vb::db::trace {
namespace {

std::uint64_t Swap(std::uint64_t v) { return __builtin_bswap64(v); }

}  // namespace

Status ValidateChunk(const TraceChunk& c) {
  const std::string where = Cat("trace chunk ", c.index, ": ");
  if (c.index < 0) return Status::InvalidArgument(where + "index must be >= 0");
  if (c.samples <= 0) return Status::InvalidArgument(Cat(where, "samples must be > 0, got ", c.samples));
  if (c.channels.empty()) return Status::InvalidArgument(where + "channels must not be empty");
  std::unordered_set<std::string_view> seen;
  for (std::size_t k = 0; k < c.channels.size(); ++k) {
    const std::string& name = c.channels[k];
    const std::string field = Cat(where, "channels[", k, "]");
    if (name.empty()) return Status::InvalidArgument(field + " must not be empty");
    if (name.find('\n') != std::string::npos) return Status::InvalidArgument(field + " must not contain a newline");
    if (!seen.insert(name).second) return Status::InvalidArgument(Cat(field, ": duplicate channel \"", name, "\""));
  }
  const std::uint64_t expected = static_cast<std::uint64_t>(c.channels.size()) * static_cast<std::uint64_t>(c.samples);
  if (expected != c.data.size()) {
    return Status::InvalidArgument(Cat(where, "channels.size() * samples != data.size() (", c.channels.size(), " * ",
                                       c.samples, " = ", expected, ", data has ", c.data.size(), " values)"));
  }
  if (!std::isfinite(c.t0_s)) return Status::InvalidArgument(Cat(where, "t0_s must be finite, got ", FormatExact(c.t0_s)));
  if (!std::isfinite(c.sample_period_s) || c.sample_period_s <= 0) {
    return Status::InvalidArgument(Cat(where, "sample_period_s must be finite and > 0, got ", FormatExact(c.sample_period_s)));
  }
  return Status::Ok();
}

std::string JoinChannels(const std::vector<std::string>& channels) {
  std::string out;
  for (std::size_t k = 0; k < channels.size(); ++k) {
    if (k > 0) out += '\n';
    out += channels[k];
  }
  return out;
}

std::vector<std::string> SplitChannels(std::string_view joined) {
  std::vector<std::string> out;
  if (joined.empty()) return out;
  std::size_t start = 0;
  while (true) {
    const std::size_t nl = joined.find('\n', start);
    if (nl == std::string_view::npos) {
      out.emplace_back(joined.substr(start));
      return out;
    }
    out.emplace_back(joined.substr(start, nl - start));
    start = nl + 1;
  }
}

std::string EncodeValues(const std::vector<double>& values) {
  std::string out(values.size() * 8, '\0');
  if constexpr (kNativeIsLittleEndian) {
    if (!values.empty()) std::memcpy(out.data(), values.data(), out.size());
  } else {
    for (std::size_t k = 0; k < values.size(); ++k) {
      const std::uint64_t le = Swap(std::bit_cast<std::uint64_t>(values[k]));
      std::memcpy(out.data() + 8 * k, &le, 8);
    }
  }
  return out;
}

Status CheckSize(std::size_t size, std::size_t expected_values, std::string_view what) {
  if (size == 8 * expected_values) return Status::Ok();
  return Status::DataLoss(Cat(what, ": data is ", size, " bytes, expected ", 8 * expected_values, " (",
                              expected_values, " float64 values)"));
}

void FromLittleEndian(std::vector<double>* values) {
  if constexpr (!kNativeIsLittleEndian) {
    for (double& v : *values) v = std::bit_cast<double>(Swap(std::bit_cast<std::uint64_t>(v)));
  }
}

}  // namespace vb::db::trace
