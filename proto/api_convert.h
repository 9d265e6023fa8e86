// Conversions between the API messages and the shared C++ vocabulary (common/), written once for the server
// and the clients.
#pragma once

#include <optional>

#include "common/bench_kind.h"
#include "common/run_key.h"
#include "common/run_status.h"
#include "valvebench/v1/api.pb.h"
#include "valvebench/v1/config.pb.h"

namespace vb::api {

valvebench::v1::RunKey ToProto(const RunKey& key);
RunKey FromProto(const valvebench::v1::RunKey& key);
valvebench::v1::RunStatus ToProto(RunStatus s);
// RUN_STATUS_UNSPECIFIED (a filter's "any") has no RunStatus: nullopt.
std::optional<RunStatus> FromProto(valvebench::v1::RunStatus s);
valvebench::v1::BenchKind ToProto(BenchKind kind);
// BENCH_KIND_UNSPECIFIED (and a value this build does not know) has no BenchKind: nullopt.
std::optional<BenchKind> FromProto(valvebench::v1::BenchKind kind);

}  // namespace vb::api
