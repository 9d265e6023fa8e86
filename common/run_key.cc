#include "common/run_key.h"

#include "common/format.h"

namespace vb {

std::string RunKey::CaseName() const {
  std::string out = name;
  for (const auto& c : sweep) out.append(" sweep:").append(c.field).append("=").append(FormatNumber(c.value));
  return out;
}

std::string RunKey::DisplayName() const {
  std::string out = CaseName();
  if (repeat >= 0) out.append(" repeat:").append(std::to_string(repeat));
  return out;
}

}  // namespace vb
