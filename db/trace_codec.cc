#include "db/trace_codec.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdint>
#include <cstring>
#include <unordered_set>

#include <zstd.h>

#include "common/format.h"
#include "db/text.h"

namespace vb::db::trace {
namespace {

std::uint64_t Swap(std::uint64_t v) { return __builtin_bswap64(v); }

std::uint64_t ZigZag(std::uint64_t d) { return (d << 1) ^ (0 - (d >> 63)); }
std::uint64_t UnZigZag(std::uint64_t z) { return (z >> 1) ^ (0 - (z & 1)); }

std::uint64_t Word(const double* p, std::size_t k) { return std::bit_cast<std::uint64_t>(p[k]); }

// Bytes up to the most significant non-zero one: a proxy for what zstd keeps of a shuffled word.
int SignificantBytes(std::uint64_t u) { return u == 0 ? 0 : 8 - std::countl_zero(u) / 8; }

template <Transform T>
struct Forward {
  std::uint64_t prev = 0, prev_d = 0;
  std::uint64_t operator()(std::uint64_t x) {
    std::uint64_t u;
    if constexpr (T == Transform::kNone) {
      u = x;
    } else if constexpr (T == Transform::kXor) {
      u = x ^ prev;
    } else if constexpr (T == Transform::kDelta) {
      u = ZigZag(x - prev);
    } else {
      const std::uint64_t d = x - prev;
      u = ZigZag(d - prev_d);
      prev_d = d;
    }
    prev = x;
    return u;
  }
};

// The probes: kProbes windows of kProbeLength consecutive words spread over the chunk (the whole chunk when it
// is short). Deciding on probes keeps the choice to a few per cent of the encoding time.
constexpr std::size_t kProbes = 4;
constexpr std::size_t kProbeLength = 1024;

template <typename Fn>
void ForEachProbeWindow(std::size_t n, Fn fn) {
  if (n <= kProbes * kProbeLength) {
    fn(std::size_t{0}, n);
    return;
  }
  for (std::size_t p = 0; p < kProbes; ++p) fn(p * (n - kProbeLength) / (kProbes - 1), kProbeLength);
}

// The transform that leaves the fewest significant bytes in the probes (ties: the simplest).
Transform Choose(const double* w, std::size_t n) {
  std::uint64_t cost[4] = {0, 0, 0, 0};
  ForEachProbeWindow(n, [&](std::size_t start, std::size_t len) {
    std::uint64_t prev = start > 0 ? Word(w, start - 1) : 0;
    std::uint64_t prev_d = start > 1 ? prev - Word(w, start - 2) : prev;
    for (std::size_t k = start; k < start + len; ++k) {
      const std::uint64_t x = Word(w, k);
      const std::uint64_t d = x - prev;
      cost[0] += SignificantBytes(x);
      cost[1] += SignificantBytes(x ^ prev);
      cost[2] += SignificantBytes(ZigZag(d));
      cost[3] += SignificantBytes(ZigZag(d - prev_d));
      prev = x;
      prev_d = d;
    }
  });
  int best = 0;
  for (int t = 1; t < 4; ++t)
    if (cost[t] < cost[best]) best = t;
  return static_cast<Transform>(best);
}

// Byte planes whose probed bytes look random (order-0 entropy above kRawPlaneBits per byte) are stored as they
// are, outside zstd: zstd would spend most of a chunk's time failing to compress them (noise in the low
// mantissa bytes of any computed or measured value), and reading them back is a plain copy.
constexpr double kRawPlaneBits = 7.5;

template <Transform T>
std::uint8_t RawPlaneMask(const double* w, std::size_t n) {
  std::uint32_t hist[8][256] = {};
  std::size_t total = 0;
  ForEachProbeWindow(n, [&](std::size_t start, std::size_t len) {
    Forward<T> f;
    if (start > 0) {  // the transform's state as it is at `start`
      if (start > 1) (void)f(Word(w, start - 2));
      (void)f(Word(w, start - 1));
    }
    for (std::size_t k = start; k < start + len; ++k) {
      const std::uint64_t u = f(Word(w, k));
      for (int b = 0; b < 8; ++b) ++hist[b][(u >> (8 * b)) & 0xff];
    }
    total += len;
  });
  if (total < 256) return 0;  // too few bytes to tell; zstd is cheap on a short chunk anyway
  std::uint8_t mask = 0;
  for (int b = 0; b < 8; ++b) {
    double bits = 0.0;
    for (std::uint32_t count : hist[b]) {
      if (count == 0) continue;
      const double p = static_cast<double>(count) / static_cast<double>(total);
      bits -= p * std::log2(p);
    }
    if (bits > kRawPlaneBits) mask = static_cast<std::uint8_t>(mask | (1u << b));
  }
  return mask;
}

std::uint8_t RawPlaneMaskFor(Transform t, const double* w, std::size_t n) {
  switch (t) {
    case Transform::kNone: return RawPlaneMask<Transform::kNone>(w, n);
    case Transform::kXor: return RawPlaneMask<Transform::kXor>(w, n);
    case Transform::kDelta: return RawPlaneMask<Transform::kDelta>(w, n);
    case Transform::kDeltaOfDelta: return RawPlaneMask<Transform::kDeltaOfDelta>(w, n);
  }
  return 0;
}

// Transposes an 8x8 byte matrix held in 8 words (byte b of x[i] <-> byte i of x[b]): three rounds of masked
// swaps of 4x4, 2x2 and 1x1 blocks. Its own inverse.
inline void Transpose8x8(std::uint64_t* x) {
  for (int i = 0; i < 4; ++i) {
    const std::uint64_t t = ((x[i] >> 32) ^ x[i + 4]) & 0x00000000FFFFFFFFULL;
    x[i] ^= t << 32;
    x[i + 4] ^= t;
  }
  for (int i : {0, 1, 4, 5}) {
    const std::uint64_t t = ((x[i] >> 16) ^ x[i + 2]) & 0x0000FFFF0000FFFFULL;
    x[i] ^= t << 16;
    x[i + 2] ^= t;
  }
  for (int i : {0, 2, 4, 6}) {
    const std::uint64_t t = ((x[i] >> 8) ^ x[i + 1]) & 0x00FF00FF00FF00FFULL;
    x[i] ^= t << 8;
    x[i + 1] ^= t;
  }
}

// Words -> 8 byte planes: eight words at a time by a transpose and eight 8-byte stores (byte order of a word
// in memory is the host's, hence little-endian hosts only; others take the byte loop), the rest byte by byte.
void Scatter(const std::uint64_t* words, std::size_t n, std::uint8_t* const* planes) {
  std::size_t k = 0;
  if constexpr (kNativeIsLittleEndian) {
    for (; k + 8 <= n; k += 8) {
      std::uint64_t x[8];
      std::memcpy(x, words + k, sizeof x);
      Transpose8x8(x);
      for (int b = 0; b < 8; ++b) std::memcpy(planes[b] + k, &x[b], 8);
    }
  }
  for (; k < n; ++k)
    for (int b = 0; b < 8; ++b) planes[b][k] = static_cast<std::uint8_t>(words[k] >> (8 * b));
}

void Gather(const std::uint8_t* const* planes, std::size_t n, std::uint64_t* words) {
  std::size_t k = 0;
  if constexpr (kNativeIsLittleEndian) {
    for (; k + 8 <= n; k += 8) {
      std::uint64_t x[8];
      for (int b = 0; b < 8; ++b) std::memcpy(&x[b], planes[b] + k, 8);
      Transpose8x8(x);
      std::memcpy(words + k, x, sizeof x);
    }
  }
  for (; k < n; ++k) {
    std::uint64_t u = 0;
    for (int b = 0; b < 8; ++b) u |= static_cast<std::uint64_t>(planes[b][k]) << (8 * b);
    words[k] = u;
  }
}

// Encoding a channel: the transform (sequential: each word depends on the previous) into `words`, then the
// byte shuffle. Decoding is the mirror image. Two passes over a chunk's channel (at most 512 KiB at the
// default chunk size) that stays in cache.
template <Transform T>
void ForwardChannel(const double* w, std::size_t n, std::uint64_t* words, std::uint8_t* const* planes) {
  Forward<T> f;
  for (std::size_t k = 0; k < n; ++k) words[k] = f(Word(w, k));
  Scatter(words, n, planes);
}

template <Transform T>
void InverseChannel(const std::uint8_t* const* planes, std::size_t n, double* out) {
  auto* words = reinterpret_cast<std::uint64_t*>(out);  // the output buffer holds the words first
  Gather(planes, n, words);
  if constexpr (T == Transform::kNone) return;
  std::uint64_t prev = 0, prev_d = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const std::uint64_t u = words[k];
    std::uint64_t x;
    if constexpr (T == Transform::kXor) {
      x = u ^ prev;
    } else if constexpr (T == Transform::kDelta) {
      x = prev + UnZigZag(u);
    } else {
      const std::uint64_t d = prev_d + UnZigZag(u);
      x = prev + d;
      prev_d = d;
    }
    prev = x;
    words[k] = x;
  }
}

int PopCount(std::uint8_t m) { return std::popcount(static_cast<unsigned>(m)); }

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

Codec1::Codec1(int zstd_level) : level_(zstd_level) {}

Codec1::~Codec1() {
  ZSTD_freeCCtx(cctx_);
  ZSTD_freeDCtx(dctx_);
}

Status Codec1::Encode(const double* data, std::size_t channels, std::size_t samples, std::string* out) {
  const std::size_t n = samples;
  if (cctx_ == nullptr && (cctx_ = ZSTD_createCCtx()) == nullptr) return Status::ResourceExhausted("zstd: no memory");
  transforms_.resize(channels);
  std::vector<std::uint8_t> masks(channels);
  std::size_t raw_planes = 0;
  for (std::size_t c = 0; c < channels; ++c) {
    transforms_[c] = Choose(data + c * n, n);
    masks[c] = RawPlaneMaskFor(transforms_[c], data + c * n, n);
    raw_planes += static_cast<std::size_t>(PopCount(masks[c]));
  }
  const std::size_t header = 2 * channels;
  const std::size_t packed = (8 * channels - raw_planes) * n;
  out->resize(header + raw_planes * n + ZSTD_compressBound(packed));
  auto* o = reinterpret_cast<std::uint8_t*>(out->data());
  shuffled_.resize(packed);
  words_.resize(n);
  std::size_t raw_at = header, packed_at = 0;
  for (std::size_t c = 0; c < channels; ++c) {
    o[2 * c] = static_cast<std::uint8_t>(transforms_[c]);
    o[2 * c + 1] = masks[c];
    std::uint8_t* planes[8];
    for (int b = 0; b < 8; ++b) {
      if ((masks[c] >> b) & 1u) {
        planes[b] = o + raw_at;
        raw_at += n;
      } else {
        planes[b] = shuffled_.data() + packed_at;
        packed_at += n;
      }
    }
    const double* w = data + c * n;
    switch (transforms_[c]) {
      case Transform::kNone: ForwardChannel<Transform::kNone>(w, n, words_.data(), planes); break;
      case Transform::kXor: ForwardChannel<Transform::kXor>(w, n, words_.data(), planes); break;
      case Transform::kDelta: ForwardChannel<Transform::kDelta>(w, n, words_.data(), planes); break;
      case Transform::kDeltaOfDelta: ForwardChannel<Transform::kDeltaOfDelta>(w, n, words_.data(), planes); break;
    }
  }
  const std::size_t frame = ZSTD_compressCCtx(cctx_, o + raw_at, out->size() - raw_at, shuffled_.data(), packed,
                                              level_);
  if (ZSTD_isError(frame)) return Status::Internal(Cat("zstd compression failed: ", ZSTD_getErrorName(frame)));
  out->resize(raw_at + frame);
  return Status::Ok();
}

Status Codec1::Decode(const void* blob, std::size_t size, std::size_t channels, std::size_t samples, double* out,
                      std::string_view what) {
  const std::size_t n = samples;
  const auto* bytes = static_cast<const std::uint8_t*>(blob);
  const std::size_t header = 2 * channels;
  if (size < header) {
    return Status::DataLoss(Cat(what, ": compressed data is ", size, " bytes, shorter than its ", header,
                                "-byte header"));
  }
  std::size_t raw_planes = 0;
  for (std::size_t c = 0; c < channels; ++c) {
    if (bytes[2 * c] > static_cast<std::uint8_t>(Transform::kDeltaOfDelta)) {
      return Status::DataLoss(Cat(what, ": channel ", c, " has unknown transform ", static_cast<int>(bytes[2 * c])));
    }
    raw_planes += static_cast<std::size_t>(PopCount(bytes[2 * c + 1]));
  }
  const std::size_t frame_at = header + raw_planes * n;
  if (size < frame_at) {
    return Status::DataLoss(Cat(what, ": compressed data is ", size, " bytes, shorter than its ", raw_planes,
                                " stored byte planes (", frame_at, " bytes)"));
  }
  const std::size_t packed = (8 * channels - raw_planes) * n;
  const void* frame = bytes + frame_at;
  const std::size_t frame_size = size - frame_at;
  const unsigned long long content = ZSTD_getFrameContentSize(frame, frame_size);
  if (content != packed) {
    return Status::DataLoss(Cat(what, ": compressed data does not hold the ", packed, " bytes its header promises (",
                                channels, " channels x ", samples, " samples)"));
  }
  if (ZSTD_findFrameCompressedSize(frame, frame_size) != frame_size) {
    return Status::DataLoss(Cat(what, ": compressed data is not exactly one zstd frame"));
  }
  if (dctx_ == nullptr && (dctx_ = ZSTD_createDCtx()) == nullptr) return Status::ResourceExhausted("zstd: no memory");
  shuffled_.resize(packed);
  const std::size_t got = ZSTD_decompressDCtx(dctx_, shuffled_.data(), packed, frame, frame_size);
  if (ZSTD_isError(got) || got != packed) {
    return Status::DataLoss(Cat(what, ": compressed data is corrupt (",
                                ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short", ")"));
  }
  std::size_t raw_at = header, packed_at = 0;
  for (std::size_t c = 0; c < channels; ++c) {
    const std::uint8_t mask = bytes[2 * c + 1];
    const std::uint8_t* planes[8];
    for (int b = 0; b < 8; ++b) {
      if ((mask >> b) & 1u) {
        planes[b] = bytes + raw_at;
        raw_at += n;
      } else {
        planes[b] = shuffled_.data() + packed_at;
        packed_at += n;
      }
    }
    double* o = out + c * n;
    switch (static_cast<Transform>(bytes[2 * c])) {
      case Transform::kNone: InverseChannel<Transform::kNone>(planes, n, o); break;
      case Transform::kXor: InverseChannel<Transform::kXor>(planes, n, o); break;
      case Transform::kDelta: InverseChannel<Transform::kDelta>(planes, n, o); break;
      case Transform::kDeltaOfDelta: InverseChannel<Transform::kDeltaOfDelta>(planes, n, o); break;
    }
  }
  return Status::Ok();
}

}  // namespace vb::db::trace
