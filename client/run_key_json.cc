#include "client/run_key_json.h"

namespace vb::client {

nlohmann::ordered_json RunKeyJson(const RunKey& key) {
  nlohmann::ordered_json sweep = nlohmann::ordered_json::array();
  for (const auto& c : key.sweep) sweep.push_back({{"field", c.field}, {"value", c.value}});
  return {{"name", key.name}, {"sweep", sweep}, {"repeat", key.repeat}};
}

StatusOr<RunKey> RunKeyFromJson(const nlohmann::json& j, const std::string& where, const std::string& default_name) {
  auto bad = [&](const std::string& member, const std::string& what) {
    return Status::InvalidArgument(where + member + ": " + what);
  };
  if (!j.is_object()) return bad("", "not an object (a run's key: name, sweep, repeat)");
  RunKey key = NamedRun(default_name);
  if (j.contains("name")) {
    if (!j["name"].is_string()) return bad(".name", "not a string");
    key.name = j["name"].get<std::string>();
  }
  if (j.contains("repeat")) {
    if (!j["repeat"].is_number_integer() || j["repeat"].get<long long>() < -1 ||
        j["repeat"].get<long long>() > 1000000)
      return bad(".repeat", "not a repeat index (an integer, -1 when not repeated)");
    key.repeat = j["repeat"].get<int>();
  }
  if (j.contains("sweep")) {
    if (!j["sweep"].is_array()) return bad(".sweep", "not an array of {field, value}");
    for (std::size_t i = 0; i < j["sweep"].size(); ++i) {
      const auto& c = j["sweep"][i];
      const std::string at = ".sweep[" + std::to_string(i) + "]";
      if (!c.is_object()) return bad(at, "not an object {field, value}");
      if (!c.contains("field") || !c["field"].is_string() || c["field"].get<std::string>().empty())
        return bad(at + ".field", "missing or not a field path");
      if (!c.contains("value") || !c["value"].is_number()) return bad(at + ".value", "missing or not a number");
      key.sweep.push_back({c["field"].get<std::string>(), c["value"].get<double>()});
    }
  }
  return key;
}

}  // namespace vb::client
