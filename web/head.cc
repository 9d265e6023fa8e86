#include "web/head.h"

#include <algorithm>
#include <cstring>
#include <vector>

namespace vb::web {

namespace {

// RFC 9110 5.6.2: tchar.
bool IsTokenChar(unsigned char c) {
  if (c >= '0' && c <= '9') return true;
  if ((c | 0x20) >= 'a' && (c | 0x20) <= 'z') return true;
  return c != 0 && std::strchr("!#$%&'*+-.^_`|~", c) != nullptr;
}

bool EqualsNoCase(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (size_t k = 0; k < a.size(); ++k) {
    unsigned char x = static_cast<unsigned char>(a[k]), y = static_cast<unsigned char>(b[k]);
    if (x >= 'A' && x <= 'Z') x = static_cast<unsigned char>(x | 0x20);
    if (y >= 'A' && y <= 'Z') y = static_cast<unsigned char>(y | 0x20);
    if (x != y) return false;
  }
  return true;
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t')) s.remove_suffix(1);
  return s;
}

bool Digits(std::string_view s, size_t max_len) {
  if (s.empty() || s.size() > max_len) return false;
  for (char c : s)
    if (c < '0' || c > '9') return false;
  return true;
}

HeadVerdict Refuse(const char* message) {
  HeadVerdict v;
  v.status = 400;
  v.message = message;
  return v;
}

}  // namespace

bool SingleByteRange(std::string_view value) {
  constexpr std::string_view kBytes = "bytes=";
  if (value.substr(0, kBytes.size()) != kBytes) return false;
  const std::string_view spec = value.substr(kBytes.size());
  const size_t dash = spec.find('-');
  if (dash == std::string_view::npos) return false;
  const std::string_view first = spec.substr(0, dash), last = spec.substr(dash + 1);
  if (first.empty()) return Digits(last, 15);  // the last n bytes
  if (!Digits(first, 15)) return false;
  if (last.empty()) return true;
  if (!Digits(last, 15)) return false;
  return std::stoull(std::string(first)) <= std::stoull(std::string(last));
}

HeadVerdict FilterHead(std::string* buf) {
  size_t skip = 0;
  while (buf->compare(skip, 2, "\r\n") == 0) skip += 2;
  if (skip > 0) buf->erase(0, skip);
  const size_t end = buf->find("\r\n\r\n");
  if (end == std::string::npos) return {};
  const std::string_view head(buf->data(), end + 2);  // each line with its CRLF
  std::vector<std::string_view> lines;
  for (size_t pos = 0; pos < head.size();) {
    const size_t eol = head.find("\r\n", pos);
    const std::string_view line = head.substr(pos, eol - pos);
    if (line.find_first_of("\r\n") != std::string_view::npos)
      return Refuse("request head: a bare CR or LF (lines end with CRLF)");
    lines.push_back(line);
    pos = eol + 2;
  }
  // The request line: METHOD SP target SP HTTP/1.x.
  const std::string_view rl = lines.front();
  const size_t sp1 = rl.find(' '), sp2 = rl.rfind(' ');
  if (sp1 == std::string_view::npos || sp2 == sp1 || sp1 == 0)
    return Refuse("request line: must be 'METHOD target HTTP/1.1'");
  const std::string_view method = rl.substr(0, sp1), version = rl.substr(sp2 + 1);
  for (char c : method)
    if (!IsTokenChar(static_cast<unsigned char>(c))) return Refuse("request line: the method is not a token");
  if (version != "HTTP/1.1" && version != "HTTP/1.0")
    return Refuse("request line: the version must be HTTP/1.1 or HTTP/1.0");
  int hosts = 0, ranges = 0;
  bool body = false, gzip = false, rewrite_encoding = false;
  std::vector<size_t> range_lines, encoding_lines;
  for (size_t k = 1; k < lines.size(); ++k) {
    const std::string_view line = lines[k];
    if (line.front() == ' ' || line.front() == '\t')
      return Refuse("request head: a folded header line (obs-fold) is not accepted");
    const size_t colon = line.find(':');
    if (colon == std::string_view::npos || colon == 0) return Refuse("request head: a header line without a name");
    const std::string_view name = line.substr(0, colon), value = Trim(line.substr(colon + 1));
    for (char c : name)
      if (!IsTokenChar(static_cast<unsigned char>(c)))
        return Refuse("request head: a header name that is not a token (RFC 9110 5.1; no space before ':')");
    if (EqualsNoCase(name, "Host")) {
      ++hosts;
    } else if (EqualsNoCase(name, "Content-Length")) {
      if (!Digits(value, 15)) return Refuse("Content-Length: not a number (digits only, no %-escapes)");
      if (value.find_first_not_of('0') != std::string_view::npos) body = true;
    } else if (EqualsNoCase(name, "Transfer-Encoding")) {
      if (value.find('%') != std::string_view::npos)
        return Refuse("Transfer-Encoding: no %-escapes in a framing header");
      body = true;
    } else if (EqualsNoCase(name, "Range")) {
      ++ranges;
      range_lines.push_back(k);
    } else if (EqualsNoCase(name, "Accept-Encoding")) {
      encoding_lines.push_back(k);
      if (value.find("gzip") != std::string_view::npos) gzip = true;
      if (value != "gzip") rewrite_encoding = true;
    }
  }
  if (version == "HTTP/1.1" && hosts == 0) return Refuse("Host: required on an HTTP/1.1 request");
  if (hosts > 1) return Refuse("Host: sent more than once");
  if (body && (method == "GET" || method == "HEAD" || method == "OPTIONS"))
    return Refuse("a GET, HEAD or OPTIONS request has no body (Content-Length must be 0, no Transfer-Encoding)");
  HeadVerdict v;
  std::vector<size_t> drop;
  if (ranges > 1 || (ranges == 1 && !SingleByteRange(Trim(lines[range_lines.front()].substr(
                                        lines[range_lines.front()].find(':') + 1))))) {
    // Several ranges, several Range lines or a malformed one: the head without them (the whole answer, 200).
    drop = range_lines;
    v.ranges_dropped = ranges;
  }
  // Compression: gzip (zlib's default level 6) or none, never brotli: cpp-httplib compresses with brotli at its
  // slowest quality (11), 0.21 s of CPU per asset and 62 s for a chart's JSON, for whoever asks (issue 34).
  if (rewrite_encoding || encoding_lines.size() > 1) {
    drop.insert(drop.end(), encoding_lines.begin(), encoding_lines.end());
    v.encoding_rewritten = true;
  }
  if (drop.empty()) return v;
  std::sort(drop.begin(), drop.end());
  std::string out;
  out.reserve(buf->size());
  size_t next_drop = 0;
  for (size_t k = 0; k < lines.size(); ++k) {
    if (next_drop < drop.size() && drop[next_drop] == k) {
      ++next_drop;
      continue;
    }
    out.append(lines[k]);
    out.append("\r\n");
  }
  if (v.encoding_rewritten && gzip) out.append("Accept-Encoding: gzip\r\n");
  out.append(*buf, end + 2, std::string::npos);  // the blank line's CRLF and whatever follows
  buf->swap(out);
  return v;
}

}  // namespace vb::web
