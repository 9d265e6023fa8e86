// benchctl benches: the benches a backend offers and the USB devices its machine sees, one renderer for both
// backends (the local one: the embedded emulator and this machine's devices; the remote one: the server's).
#pragma once

#include "benchctl/backend.h"
#include "valvebench/v1/api.pb.h"

namespace vb::benchctl {

// The local backend's answer: the embedded emulator `run --local` drives and the devices this machine sees.
// No USB bus is a clean answer ("no USB bus on this machine"), not an error.
valvebench::v1::ListBenchesResponse LocalBenches();
// benches [--local]: the one rendering (a table, or protobuf JSON with every field written).
int CmdBenches(Backend& backend, bool json);

}  // namespace vb::benchctl
