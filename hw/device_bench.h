// Pieces the USB device benches (hid/, u3/) share: both measure the coil current only, reconnect the same way
// after an unplug, and check a run's supply against what the device declared.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

#include "common/bench_io.h"
#include "common/status.h"
#include "hw/bench.h"
#include "hw/transport.h"

namespace vb::hw {

// A recorded sample with the gate and the coil current; every other channel not measured (NaN).
BenchSample CurrentOnlySample(double t_s, std::int8_t gate, double i_A);
// The measurement a controller sees from such a bench.
void FillCurrentOnlyMeasurement(double t_s, double i_A, double supply_V, Measurement* m);

// After an unplug: reopens the transport and identifies the device again, up to `attempts` times
// (at least once); errors name the bench.
Status Reconnect(Transport& transport, int attempts, const std::function<Status()>& identify,
                 const std::string& bench);

// supply_V in (0, max_supply_V], or FailedPrecondition naming the field and the bench.
Status CheckSupply(double supply_V, double max_supply_V, const std::string& bench);

}  // namespace vb::hw
