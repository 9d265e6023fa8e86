// Helpers for fuzz targets whose code under test reads files: a private scratch directory (on /dev/shm when
// there is one) and the input split into files.
#pragma once

#include <stdlib.h>

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <string_view>
#include <vector>

namespace vb::fuzz {

// A directory of this process's own, created once, removed by nobody (the OS's tmp cleaning does).
inline const std::filesystem::path& ScratchDir() {
  static const std::filesystem::path dir = [] {
    const char* base = std::filesystem::is_directory("/dev/shm") ? "/dev/shm" : "/tmp";
    std::string templ = std::string(base) + "/vbfuzz-XXXXXX";
    if (mkdtemp(templ.data()) == nullptr) abort();
    return std::filesystem::path(templ);
  }();
  return dir;
}

// Empties `dir` (creating it if needed).
inline void ResetDir(const std::filesystem::path& dir) {
  std::error_code ec;
  std::filesystem::remove_all(dir, ec);
  std::filesystem::create_directories(dir);
}

inline void WriteFile(const std::filesystem::path& path, std::string_view bytes) {
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// Splits the input at every line "%%" (the line break before it belongs to the separator).
inline std::vector<std::string_view> SplitParts(const std::uint8_t* data, std::size_t size) {
  const std::string_view all(reinterpret_cast<const char*>(data), size);
  constexpr std::string_view kSep = "\n%%\n";
  std::vector<std::string_view> parts;
  std::size_t pos = 0;
  while (true) {
    const std::size_t at = all.find(kSep, pos);
    if (at == std::string_view::npos) {
      parts.push_back(all.substr(pos));
      return parts;
    }
    parts.push_back(all.substr(pos, at - pos));
    pos = at + kSep.size();
  }
}

}  // namespace vb::fuzz
