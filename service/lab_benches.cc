#include "service/lab_benches.h"

#include <nlohmann/json.hpp>

namespace vb::server {

using runs::BenchSetup;

std::vector<BenchSetup> OtherHostsBenches(const std::vector<db::HostRecord>& hosts, const std::string& own_host) {
  std::vector<BenchSetup> out;
  for (const auto& h : hosts) {
    if (h.name == own_host) continue;
    const auto benches = nlohmann::json::parse(h.benches_json, nullptr, false);
    if (!benches.is_array()) continue;
    for (const auto& b : benches) {
      if (!b.is_object() || !b.contains("caps") || !b["caps"].is_object()) continue;  // written by an older build
      const auto& c = b["caps"];
      BenchSetup s;
      s.name = b.value("name", "");
      s.kind = b.value("kind", "");
      s.bench_class = b.value("bench_class", "");
      s.preset = b.value("model", "");
      s.paced = b.value("paced", false);
      s.device = b.value("device", "");
      s.caps.kind = c.value("kind", "");
      s.caps.driver = c.value("driver", "");
      s.caps.max_supply_V = c.value("max_supply_V", 0.0);
      s.caps.min_carrier_Hz = c.value("min_carrier_Hz", 0.0);
      s.caps.max_carrier_Hz = c.value("max_carrier_Hz", 0.0);
      s.caps.max_sample_rate_Hz = c.value("max_sample_rate_Hz", 0.0);
      s.caps.max_control_rate_Hz = c.value("max_control_rate_Hz", 0.0);
      s.caps.measures_position = c.value("measures_position", false);
      s.caps.measures_velocity = c.value("measures_velocity", false);
      s.caps.max_current_A = c.value("max_current_A", 0.0);
      if (c.contains("device_loops") && c["device_loops"].is_array())
        for (const auto& l : c["device_loops"])
          if (l.is_string()) s.caps.device_loops.push_back(l.get<std::string>());
      s.caps.max_device_loop_Hz = c.value("max_device_loop_Hz", 0.0);
      if (!s.name.empty() && !s.bench_class.empty()) out.push_back(std::move(s));
    }
  }
  return out;
}

}  // namespace vb::server
