#include "hw/transport.h"

namespace vb::hw {

const char* IoStatusName(IoStatus s) {
  switch (s) {
    case IoStatus::kOk: return "ok";
    case IoStatus::kTimeout: return "timeout";
    case IoStatus::kDisconnected: return "device disconnected";
    case IoStatus::kError: return "I/O error";
  }
  return "?";
}

Status TransportError(IoStatus s, const char* operation, const Transport& t, int timeout_ms) {
  std::string msg = std::string(operation) + " on " + t.Describe() + ": ";
  if (s == IoStatus::kTimeout)
    msg += "no answer within " + std::to_string(timeout_ms) + " ms";
  else
    msg += IoStatusName(s);
  return Status::Unavailable(std::move(msg));
}

}  // namespace vb::hw
