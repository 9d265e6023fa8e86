// The files every report page inlines, embedded at build time (cmake/embed.cmake, report/CMakeLists.txt): Debian's
// dygraphs (libjs-dygraphs) and the web dashboard's format.js, charts.js and charts.css, so that a report draws
// with the dashboard's chart code and stays one self-contained file (docs/report.md "Chart library").
#pragma once

#include <cstddef>
#include <string_view>
#include <vector>

namespace vb::report {

struct Asset {
  const char* url_path;      // "/dygraph.min.js", "/dygraph.min.css", "/format.js", "/charts.js", "/charts.css"
  const char* content_type;
  const char* data;
  std::size_t size;
  std::string_view body() const { return {data, size}; }
};

const std::vector<Asset>& Assets();

}  // namespace vb::report
