// What every benchctl command shares: exit codes scripts can trust, and error printing.
//   0 success; 1 a run failed or was cancelled; 2 the request was refused (bad input, not found, no
//   capable bench, limits, permissions); 3 environment (server unreachable, I/O).
#pragma once

#include <cstdio>

#include "common/status.h"

namespace vb::benchctl {

inline constexpr int kExitOk = 0, kExitRunFailed = 1, kExitBadInput = 2, kExitEnvironment = 3;

inline int ExitFor(const Status& st) {
  switch (st.code()) {
    case StatusCode::kOk: return kExitOk;
    case StatusCode::kInvalidArgument:
    case StatusCode::kNotFound:
    case StatusCode::kAlreadyExists:
    case StatusCode::kOutOfRange:
    case StatusCode::kResourceExhausted:
    case StatusCode::kFailedPrecondition: return kExitBadInput;
    default: return kExitEnvironment;
  }
}

inline int Fail(const Status& st) {
  std::fprintf(stderr, "benchctl: %s\n", st.message().c_str());
  return ExitFor(st);
}

}  // namespace vb::benchctl
