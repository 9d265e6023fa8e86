// A run's key (common/run_key.h) as JSON, one shape for every door: {"name", "sweep": [{"field", "value"}],
// "repeat"} (repeat -1: not repeated). benchctl's run JSON and the web's comparison keys write it with this, and
// `benchctl compare RESULTS.json` reads it back with RunKeyFromJson.
#pragma once

#include <nlohmann/json.hpp>

#include <string>

#include "common/run_key.h"
#include "common/status.h"

namespace vb::client {

nlohmann::ordered_json RunKeyJson(const RunKey& key);

// RunKeyJson's shape read back: "name" a string, "sweep" an array of {"field": a string, "value": a number},
// "repeat" an integer; a member left out keeps its default (the name: `default_name`). Anything else is
// InvalidArgument naming the member under `where` ("results.json: [3].key.sweep[1].value: not a number").
StatusOr<RunKey> RunKeyFromJson(const nlohmann::json& j, const std::string& where, const std::string& default_name);

}  // namespace vb::client
