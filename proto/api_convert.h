// Conversions between the API messages and the shared C++ vocabulary (common/), written once for the server
// and the clients.
#pragma once

#include <optional>

#include "common/run_key.h"
#include "common/run_status.h"
#include "valvebench/v1/api.pb.h"

namespace vb::api {

valvebench::v1::RunKey ToProto(const RunKey& key);
RunKey FromProto(const valvebench::v1::RunKey& key);
valvebench::v1::RunStatus ToProto(RunStatus s);
// RUN_STATUS_UNSPECIFIED (a filter's "any") has no RunStatus: nullopt.
std::optional<RunStatus> FromProto(valvebench::v1::RunStatus s);

}  // namespace vb::api
