// CSV text fields (RFC 4180): a field is quoted, and a quote inside it doubled, so names with commas, quotes
// or line breaks (a spec name is free text) cannot shift or split columns.
#pragma once

#include <string>
#include <string_view>

namespace vb {

inline std::string CsvQuoted(std::string_view s) {
  std::string out;
  out.reserve(s.size() + 2);
  out.push_back('"');
  for (char c : s) {
    if (c == '"') out.push_back('"');
    out.push_back(c);
  }
  out.push_back('"');
  return out;
}

}  // namespace vb
