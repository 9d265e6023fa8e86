// The door's checks that need no route (web/gateway.h): UTF-8, JSON depth, the bearer header, an upload's CSV
// header, a served report's CSP, the import's temporary directories, and gRPC codes as HTTP statuses.
#include <fmt/format.h>
#include <openssl/evp.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <set>
#include <string>

#include <signal.h>
#include <unistd.h>

#include "web/gateway.h"

namespace vb::web {

int HttpStatusFor(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK: return 200;
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::OUT_OF_RANGE: return 400;
    case grpc::StatusCode::UNAUTHENTICATED: return 401;
    case grpc::StatusCode::PERMISSION_DENIED: return 403;
    case grpc::StatusCode::NOT_FOUND: return 404;
    case grpc::StatusCode::ALREADY_EXISTS:
    case grpc::StatusCode::FAILED_PRECONDITION:
    case grpc::StatusCode::ABORTED: return 409;
    case grpc::StatusCode::RESOURCE_EXHAUSTED: return 429;
    case grpc::StatusCode::CANCELLED: return 499;
    case grpc::StatusCode::UNIMPLEMENTED: return 501;
    case grpc::StatusCode::UNAVAILABLE: return 503;
    case grpc::StatusCode::DEADLINE_EXCEEDED: return 504;
    default: return 500;
  }
}

bool ValidUtf8(std::string_view s) {
  size_t k = 0;
  const size_t n = s.size();
  while (k < n) {
    const auto c = static_cast<unsigned char>(s[k]);
    if (c < 0x80) {
      ++k;
      continue;
    }
    size_t len;
    std::uint32_t cp;
    if ((c & 0xE0) == 0xC0) {
      len = 2;
      cp = c & 0x1F;
    } else if ((c & 0xF0) == 0xE0) {
      len = 3;
      cp = c & 0x0F;
    } else if ((c & 0xF8) == 0xF0) {
      len = 4;
      cp = c & 0x07;
    } else {
      return false;
    }
    if (k + len > n) return false;
    for (size_t j = 1; j < len; ++j) {
      const auto d = static_cast<unsigned char>(s[k + j]);
      if ((d & 0xC0) != 0x80) return false;
      cp = (cp << 6) | (d & 0x3F);
    }
    // Overlong forms, UTF-16 surrogates and code points past U+10FFFF are not UTF-8.
    if ((len == 2 && cp < 0x80) || (len == 3 && cp < 0x800) || (len == 4 && cp < 0x10000) || cp > 0x10FFFF ||
        (cp >= 0xD800 && cp <= 0xDFFF))
      return false;
    k += len;
  }
  return true;
}

int JsonDepth(std::string_view s) {
  int depth = 0, max_depth = 0;
  bool in_string = false, escaped = false;
  for (const char c : s) {
    if (in_string) {
      if (escaped) {
        escaped = false;
      } else if (c == '\\') {
        escaped = true;
      } else if (c == '"') {
        in_string = false;
      }
      continue;
    }
    if (c == '"') {
      in_string = true;
    } else if (c == '[' || c == '{') {
      max_depth = std::max(max_depth, ++depth);
    } else if (c == ']' || c == '}') {
      --depth;
    }
  }
  return max_depth;
}

std::string BearerTokenOf(std::string_view header, std::string* problem) {
  constexpr std::string_view kBearer = "Bearer ";
  if (header.substr(0, kBearer.size()) != kBearer) {
    *problem = "Authorization: must be 'Bearer <token>'";
    return "";
  }
  const std::string_view t = header.substr(kBearer.size());
  if (t.empty() || t.size() > 4096) {
    *problem = "Authorization: the bearer token must be 1-4096 characters";
    return "";
  }
  for (const char c : t) {
    if (c < 0x21 || c > 0x7e) {
      *problem = "Authorization: the bearer token must be visible ASCII characters (no space, tab, control or "
                 "non-ASCII byte)";
      return "";
    }
  }
  return std::string(t);
}

std::string CsvHeaderProblem(std::string_view text) {
  if (text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);  // UTF-8 BOM
  std::string_view header = text.substr(0, text.find('\n'));
  if (!header.empty() && header.back() == '\r') header.remove_suffix(1);
  std::set<std::string_view> names;
  size_t count = 0;
  for (size_t start = 0;;) {
    const size_t comma = header.find(',', start);
    const std::string_view name =
        header.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start);
    if (++count > kMaxCsvColumns)
      return fmt::format("more than {} columns in the header (a run has at most 5 known ones: t_s, gate, i_A, "
                         "x_m, v_coil_V)",
                         kMaxCsvColumns);
    if (!name.empty() && !names.insert(name).second)
      return "column " + std::string(name.substr(0, 40)) + (name.size() > 40 ? "..." : "") +
             " appears twice in the header";
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return "";
}

std::string ReportCsp(std::string_view html) {
  std::string hashes;
  constexpr std::string_view kOpen = "<script>", kClose = "</script>";
  for (size_t at = html.find(kOpen); at != std::string_view::npos; at = html.find(kOpen, at)) {
    const size_t begin = at + kOpen.size();
    const size_t end = html.find(kClose, begin);
    if (end == std::string_view::npos) break;
    unsigned char digest[EVP_MAX_MD_SIZE];
    unsigned int len = 0;
    EVP_Digest(html.data() + begin, end - begin, digest, &len, EVP_sha256(), nullptr);
    unsigned char b64[4 * ((EVP_MAX_MD_SIZE + 2) / 3) + 1];
    const int n = EVP_EncodeBlock(b64, digest, static_cast<int>(len));
    hashes += " 'sha256-" + std::string(reinterpret_cast<const char*>(b64), static_cast<size_t>(n)) + "'";
    at = end + kClose.size();
  }
  return "default-src 'none'; script-src" + (hashes.empty() ? std::string(" 'none'") : hashes) +
         "; style-src 'unsafe-inline'; img-src data:; frame-ancestors 'none'; base-uri 'none'; form-action 'none'";
}

int RemoveStaleImports() {
  std::error_code ec;
  std::filesystem::path dir = std::filesystem::temp_directory_path(ec);
  if (ec) dir = "/tmp";
  int removed = 0;
  constexpr std::string_view kPrefix = "valvebench-import-";
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (name.rfind(kPrefix, 0) != 0) continue;
    const std::string rest = name.substr(kPrefix.size());
    const size_t dash = rest.find('-');
    bool stale = false;
    if (dash != std::string::npos && dash > 0 && rest.find_first_not_of("0123456789") == dash) {
      // valvebench-import-PID-XXXXXX: stale when that process is gone (another server's upload is left alone).
      const long pid = std::strtol(rest.c_str(), nullptr, 10);
      stale = pid > 0 && ::kill(static_cast<pid_t>(pid), 0) != 0 && errno == ESRCH;
    } else {
      // The older name without a process id: stale after an hour (an import takes seconds).
      std::error_code tec;
      const auto t = std::filesystem::last_write_time(e.path(), tec);
      stale = !tec && std::filesystem::file_time_type::clock::now() - t > std::chrono::hours(1);
    }
    if (!stale) continue;
    std::error_code rec;
    if (std::filesystem::remove_all(e.path(), rec) > 0 && !rec) ++removed;
  }
  return removed;
}

}  // namespace vb::web
