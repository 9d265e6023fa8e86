// The door's check of a request head's bytes before cpp-httplib parses them (docs/web.md "Door"): what
// cpp-httplib 0.11.4 would accept but must not, and the one header it would act on at any cost.
//
//  - Range: cpp-httplib parses every range of a Range header and, for a routed answer (HEAD too), builds the
//    whole multipart/byteranges answer in memory: n ranges of "0-" are n copies of the body (issue 34: 2,700
//    ranges on an 8 KiB request made a 354 MB answer from a 100 KB asset). RFC 9110 14.2 lets a server ignore
//    Range, and says it should ignore or refuse many small or overlapping ranges; here exactly one range
//    ("bytes=a-b", "bytes=a-", "bytes=-n", numbers of at most 15 digits) is kept (one range cannot overlap,
//    and its answer is at most the whole body), anything else is removed from the head, so the client gets
//    the whole answer with 200. A download resumed by a browser or curl (one range) still works.
//  - Framing (request smuggling behind a keep-alive proxy): cpp-httplib %-decodes header values
//    ("Content-Length: %32" is 2), skips lines that do not end in CRLF, does not read a GET's body (it would
//    be parsed as the next request) and does not check header names. Refused with 400 here: a bare CR or LF,
//    a folded line (obs-fold), a header name that is not a token, a '%' or anything but digits in
//    Content-Length, a '%' in Transfer-Encoding, a body (Content-Length other than 0, or Transfer-Encoding)
//    on GET, HEAD or OPTIONS, an HTTP/1.1 request without exactly one Host, a version other than HTTP/1.0 or
//    HTTP/1.1.
//  - Accept-Encoding: cpp-httplib prefers brotli, at quality 11 (its slowest, chosen for the client's bytes,
//    not the server's CPU: 0.21 s per asset request without a token, issue 34). The header becomes
//    "Accept-Encoding: gzip" when the client accepts gzip (zlib's default level 6), else it is removed.
#pragma once

#include <string>
#include <string_view>

namespace vb::web {

struct HeadVerdict {
  int status = 0;           // 0: pass on (maybe rewritten); else the HTTP status to refuse with
  std::string message;      // why (no request bytes in it: it goes into a JSON answer as is)
  int ranges_dropped = 0;   // Range header lines removed
  bool encoding_rewritten = false;  // Accept-Encoding replaced by "gzip" (or removed): never brotli
};

// `buf` holds a request head, ended by its first CRLFCRLF, and possibly bytes after it (a body, the next
// request), which are kept as they are. Empty lines before the request line are dropped (RFC 9112 2.2).
HeadVerdict FilterHead(std::string* buf);

// True for "bytes=a-b", "bytes=a-" or "bytes=-n" (a <= b, at most 15 digits each): the one Range kept.
bool SingleByteRange(std::string_view value);

}  // namespace vb::web
