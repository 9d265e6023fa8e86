// The dashboard's static files, embedded at build time (web/embed.cmake; docs/web.md "Assets").
#pragma once

#include <cstddef>
#include <string_view>
#include <vector>

namespace vb::web {

struct Asset {
  const char* url_path;      // "/", "/app.js", "/dygraph.min.js", ...
  const char* content_type;
  const char* data;
  std::size_t size;
  std::string_view body() const { return {data, size}; }
};

// Every embedded file; the order is the build's.
const std::vector<Asset>& Assets();
// The file served at `url_path`, or nullptr.
const Asset* FindAsset(std::string_view url_path);

}  // namespace vb::web
