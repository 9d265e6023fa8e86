#include "client/run_key_json.h"

namespace vb::client {

nlohmann::ordered_json RunKeyJson(const RunKey& key) {
  nlohmann::ordered_json sweep = nlohmann::ordered_json::array();
  for (const auto& c : key.sweep) sweep.push_back({{"field", c.field}, {"value", c.value}});
  return {{"name", key.name}, {"sweep", sweep}, {"repeat", key.repeat}};
}

}  // namespace vb::client
