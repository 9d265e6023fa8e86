#include "common/bench_kind.h"

#include <string>

namespace vb {

const char* BenchKindName(BenchKind kind) {
  switch (kind) {
    case BenchKind::kEmulated: return "emulated";
    case BenchKind::kHid: return "hid";
    case BenchKind::kU3: return "u3";
  }
  return "emulated";
}

StatusOr<BenchKind> ParseBenchKind(std::string_view name, std::string_view field) {
  if (name.empty()) return BenchKind::kEmulated;
  for (BenchKind k : {BenchKind::kEmulated, BenchKind::kHid, BenchKind::kU3})
    if (name == BenchKindName(k)) return k;
  return Status::InvalidArgument(std::string(field) + ": unknown bench kind '" + std::string(name) +
                                 "' (known: emulated, hid, u3)");
}

std::string BenchClass(BenchKind kind, std::string_view preset) {
  if (kind != BenchKind::kEmulated) return BenchKindName(kind);
  return std::string(BenchKindName(kind)) + ":" + std::string(preset);
}

}  // namespace vb
