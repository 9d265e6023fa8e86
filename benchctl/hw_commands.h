// benchctl benches: the benches a service offers and the USB devices its machine sees (ListBenches), one renderer
// whichever service answers (--local: the local service's emulator and this machine's devices).
#pragma once

#include "benchctl/backend.h"
#include "valvebench/v1/api.pb.h"

namespace vb::benchctl {

// benches [--local]: the one rendering (a table, or protobuf JSON with every field written).
int CmdBenches(Backend& backend, bool json);

}  // namespace vb::benchctl
