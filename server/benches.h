// The bench a run executes on, built from its configuration: an EmulatedBench (the configured plant), or a
// hardware bench (HidBench over hidapi, U3Bench over libusb) opened for the run, so an unplugged and
// replugged device is found again by the next run. The worker wraps it in the safety interlocks.
#pragma once

#include <memory>

#include "experiment/spec.h"
#include "hw/bench.h"
#include "server/config.h"

namespace vb::server {

// Unavailable naming the device when it cannot be opened (not attached, no permission, no USB bus).
StatusOr<std::unique_ptr<hw::Bench>> OpenBench(const BenchSetup& setup, const experiment::Experiment& e);

}  // namespace vb::server
