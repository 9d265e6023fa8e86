// A run's key (common/run_key.h) as JSON, one shape for every door: {"name", "sweep": [{"field", "value"}],
// "repeat"} (repeat -1: not repeated). benchctl's run JSON and the web's comparison keys write it with this.
#pragma once

#include <nlohmann/json.hpp>

#include "common/run_key.h"

namespace vb::client {

nlohmann::ordered_json RunKeyJson(const RunKey& key);

}  // namespace vb::client
