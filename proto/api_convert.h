// Conversions between the API messages and the shared C++ vocabulary (common/), written once for the server
// and the clients.
#pragma once

#include "common/run_key.h"
#include "valvebench/v1/api.pb.h"

namespace vb::api {

valvebench::v1::RunKey ToProto(const RunKey& key);
RunKey FromProto(const valvebench::v1::RunKey& key);

}  // namespace vb::api
