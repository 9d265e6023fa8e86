// The web door's limits (docs/web.md "Limits"); web/door.h enforces the connection ones, web/gateway.cc the
// request ones.
#pragma once

#include <cstddef>

namespace vb::web {

struct DoorLimits {
  size_t max_head_bytes = 64 << 10;      // request line + headers
  size_t max_body_bytes = 8 << 20;       // decoded body; chunk framing may add max_body_bytes / 16 on the wire
  double head_timeout_s = 10.0;          // from a head's first byte to its blank line
  double idle_timeout_s = 5.0;           // a kept-alive connection waiting for its next request
  double body_timeout_s = 60.0;          // a whole body, once the head is in
  double handshake_timeout_s = 10.0;     // TLS
  int max_connections = 512;             // open connections in all
  int max_connections_per_client = 128;  // per client address
  int workers = 64;                      // threads running requests (an SSE stream holds one)
  int max_workers_per_client = 0;        // requests one address runs at once; 0 = workers / 4 (the rest wait)
  double write_grace_s = 5.0;            // a reader may keep the server waiting this long to write, then
  double min_write_rate = 16 * 1024.0;   // must have taken this many bytes/s of the time it kept it waiting
  int max_requests_per_connection = 1000;
};

}  // namespace vb::web
