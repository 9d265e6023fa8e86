#include "proto/api_convert.h"

namespace vb::api {

valvebench::v1::RunKey ToProto(const RunKey& key) {
  valvebench::v1::RunKey out;
  out.set_name(key.name);
  for (const auto& c : key.sweep) {
    auto* p = out.add_sweep();
    p->set_field(c.field);
    p->set_value(c.value);
  }
  out.set_repeat(key.repeat);
  return out;
}

RunKey FromProto(const valvebench::v1::RunKey& key) {
  RunKey out{key.name(), {}, key.repeat()};
  for (const auto& c : key.sweep()) out.sweep.push_back({c.field(), c.value()});
  return out;
}

valvebench::v1::RunStatus ToProto(RunStatus s) {
  switch (s) {
    case RunStatus::kQueued: return valvebench::v1::QUEUED;
    case RunStatus::kRunning: return valvebench::v1::RUNNING;
    case RunStatus::kDone: return valvebench::v1::DONE;
    case RunStatus::kFailed: return valvebench::v1::FAILED;
    case RunStatus::kCancelled: return valvebench::v1::CANCELLED;
    case RunStatus::kInterrupted: return valvebench::v1::INTERRUPTED;
  }
  return valvebench::v1::RUN_STATUS_UNSPECIFIED;
}

std::optional<RunStatus> FromProto(valvebench::v1::RunStatus s) {
  switch (s) {
    case valvebench::v1::QUEUED: return RunStatus::kQueued;
    case valvebench::v1::RUNNING: return RunStatus::kRunning;
    case valvebench::v1::DONE: return RunStatus::kDone;
    case valvebench::v1::FAILED: return RunStatus::kFailed;
    case valvebench::v1::CANCELLED: return RunStatus::kCancelled;
    case valvebench::v1::INTERRUPTED: return RunStatus::kInterrupted;
    default: return std::nullopt;
  }
}

valvebench::v1::BenchKind ToProto(BenchKind kind) {
  switch (kind) {
    case BenchKind::kEmulated: return valvebench::v1::BENCH_KIND_EMULATED;
    case BenchKind::kHid: return valvebench::v1::BENCH_KIND_HID;
    case BenchKind::kU3: return valvebench::v1::BENCH_KIND_U3;
  }
  return valvebench::v1::BENCH_KIND_UNSPECIFIED;
}

std::optional<BenchKind> FromProto(valvebench::v1::BenchKind kind) {
  switch (kind) {
    case valvebench::v1::BENCH_KIND_EMULATED: return BenchKind::kEmulated;
    case valvebench::v1::BENCH_KIND_HID: return BenchKind::kHid;
    case valvebench::v1::BENCH_KIND_U3: return BenchKind::kU3;
    default: return std::nullopt;
  }
}

}  // namespace vb::api
