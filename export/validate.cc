#include <cctype>
#include <set>

#include "export/run_file.h"

namespace vb::exportfile {
namespace {

// A name both formats accept as is: a MATLAB identifier (letter first, letters, digits, underscores, at most
// 63 characters), which is also a plain HDF5 link name.
bool Identifier(const std::string& s) {
  if (s.empty() || s.size() > 63 || !std::isalpha(static_cast<unsigned char>(s[0]))) return false;
  for (char c : s)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '_') return false;
  return true;
}

Status Names(const std::vector<Value>& values, const std::string& field) {
  std::set<std::string> seen;
  for (size_t k = 0; k < values.size(); ++k) {
    const auto where = field + "[" + std::to_string(k) + "].name";
    if (!Identifier(values[k].name))
      return Status::InvalidArgument(where + ": '" + values[k].name +
                                     "' is not an identifier (letter first, "
                                     "then letters, digits or _, at most 63)");
    if (!seen.insert(values[k].name).second)
      return Status::InvalidArgument(where + ": '" + values[k].name + "' appears twice");
  }
  return Status::Ok();
}

}  // namespace

Status Validate(const RunFile& run) {
  std::set<std::string> seen;
  for (size_t k = 0; k < run.channels.size(); ++k) {
    const auto& c = run.channels[k];
    const auto where = "channels[" + std::to_string(k) + "]";
    if (!Identifier(c.name))
      return Status::InvalidArgument(where + ".name: '" + c.name +
                                     "' is not an identifier (letter first, then "
                                     "letters, digits or _, at most 63)");
    if (!seen.insert(c.name).second) return Status::InvalidArgument(where + ".name: '" + c.name + "' appears twice");
    if (c.values.size() != run.channels[0].values.size())
      return Status::InvalidArgument(where + ".values: " + std::to_string(c.values.size()) + " samples, but " +
                                     run.channels[0].name + " has " + std::to_string(run.channels[0].values.size()));
  }
  if (auto st = Names(run.conditions, "conditions"); !st.ok()) return st;
  return Names(run.metrics, "metrics");
}

}  // namespace vb::exportfile
