// benchctl's hardware commands: `benches --local` (the embedded emulator and the USB devices this machine
// sees), and the attached-device table `benches` prints for a server too.
#pragma once

#include "valvebench/v1/api.pb.h"

namespace vb::benchctl {

// Exit 0 also when there is no USB bus: that is a clean answer ("no USB bus on this machine").
int CmdBenchesLocal(bool json);
void PrintAttached(const valvebench::v1::ListBenchesResponse& r);

}  // namespace vb::benchctl
