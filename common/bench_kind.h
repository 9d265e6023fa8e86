// What drives a bench: the emulator, the HID valve driver, or a LabJack U3 (docs/hardware.md). The one
// vocabulary of config `benches[].kind`, spec `bench.kind`, BenchInfo.kind and the bench classes; one
// formatter each way. Names: "emulated", "hid", "u3".
#pragma once

#include <string>
#include <string_view>

#include "common/status.h"

namespace vb {

enum class BenchKind { kEmulated, kHid, kU3 };

const char* BenchKindName(BenchKind kind);
// "" is the default, emulated. InvalidArgument naming `field` and the known kinds otherwise
// ("bench.kind: unknown bench kind 'usb' (known: emulated, hid, u3)").
StatusOr<BenchKind> ParseBenchKind(std::string_view name, std::string_view field = "kind");

// The class runs are matched to benches on (docs/server.md): "emulated:<preset>" for the emulator, the kind
// itself for hardware ("hid", "u3").
std::string BenchClass(BenchKind kind, std::string_view preset);

}  // namespace vb
