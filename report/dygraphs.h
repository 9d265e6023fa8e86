// Debian's dygraphs (libjs-dygraphs), embedded at build time (cmake/embed.cmake) so that every report page
// inlines the same chart library the web dashboard serves and stays one self-contained file (docs/report.md).
#pragma once

#include <cstddef>
#include <string_view>
#include <vector>

namespace vb::report {

struct Asset {
  const char* url_path;      // "/dygraph.min.js", "/dygraph.min.css"
  const char* content_type;
  const char* data;
  std::size_t size;
  std::string_view body() const { return {data, size}; }
};

const std::vector<Asset>& Assets();

}  // namespace vb::report
