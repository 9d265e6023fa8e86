// CSV text fields (RFC 4180): a field is quoted, and a quote inside it doubled, so names with commas, quotes
// or line breaks (a spec name is free text) cannot shift or split columns.
#pragma once

#include <cmath>
#include <cstdio>
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

// A number as a CSV field, the one way every CSV writer here says "no value" (docs/cli.md "Missing
// values"): NaN (a run without a reference, an unmeasured metric) is an EMPTY field, which pandas.read_csv reads
// as NaN, Excel and LibreOffice as an empty cell and R's read.csv as NA, where "nan" or "null" would be text in
// Excel. Infinities are "inf" and "-inf" (pandas reads both). `digits` significant digits (%g).
inline void AppendCsvNumber(std::string* out, double v, int digits = 10) {
  if (std::isnan(v)) return;
  if (std::isinf(v)) {
    *out += v > 0 ? "inf" : "-inf";
    return;
  }
  char buf[40];
  const int n = std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  out->append(buf, n > 0 ? static_cast<size_t>(n) : 0);
}
inline std::string CsvNumber(double v, int digits = 10) {
  std::string s;
  AppendCsvNumber(&s, v, digits);
  return s;
}

}  // namespace vb
