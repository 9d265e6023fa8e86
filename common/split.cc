#include "common/split.h"

#include <string>

namespace vb {

const char* SplitName(Split split) {
  switch (split) {
    case Split::kNone: return "";
    case Split::kFit: return "fit";
    case Split::kHoldout: return "holdout";
  }
  return "";
}

StatusOr<Split> ParseSplit(std::string_view name) {
  for (Split s : {Split::kNone, Split::kFit, Split::kHoldout})
    if (name == SplitName(s)) return s;
  std::string msg = "'";
  msg.append(name);
  msg += "' is not fit or holdout";
  return Status::InvalidArgument(std::move(msg));
}

}  // namespace vb
