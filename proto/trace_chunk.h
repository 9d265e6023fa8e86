// GetTrace's chunks (api.proto TraceChunk) read into the one trace decoder (common/trace_columns.h): what the
// C++ client, the web gateway and benchctl call instead of taking the bytes apart themselves.
#pragma once

#include "common/status.h"
#include "common/trace_columns.h"
#include "valvebench/v1/api.pb.h"

namespace vb::api {

// Appends one received chunk: `data` is little-endian float64, channel-major (api.proto); `t_s`, when given,
// has one time per sample. DataLoss when the sizes do not match or chunks come out of order.
Status DecodeChunk(const valvebench::v1::TraceChunk& chunk, TraceDecoder* decoder);

}  // namespace vb::api
