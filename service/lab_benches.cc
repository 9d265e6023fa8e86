#include "service/lab_benches.h"

#include <google/protobuf/util/json_util.h>
#include <nlohmann/json.hpp>

#include "common/bench_kind.h"
#include "model/driver.h"

namespace vb::server {

using runs::BenchSetup;

valvebench::v1::BenchInfo DescribeBench(const BenchSetup& b) {
  valvebench::v1::BenchInfo out;
  const bool emulated = b.kind == BenchKind::kEmulated;
  out.set_name(b.name);
  out.set_kind(BenchKindName(b.kind));
  out.set_driver(emulated ? std::string(model::DriverKindName(b.emulated.driver.kind)) : b.caps.driver);
  out.set_model(b.preset);
  out.set_max_supply_v(b.caps.max_supply_V);
  out.set_max_carrier_hz(b.caps.max_carrier_Hz);
  out.set_max_sample_rate_hz(b.caps.max_sample_rate_Hz);
  out.set_max_control_rate_hz(b.caps.max_control_rate_Hz);
  out.set_measures_position(emulated ? b.emulated.plant.has_moving_part : b.caps.measures_position);
  out.set_device(b.device);
  out.set_paced(b.paced);
  out.set_max_current_a(b.safety.max_current_A > 0.0 ? b.safety.max_current_A : b.caps.max_current_A);
  out.set_max_duty(b.safety.max_duty);
  out.set_max_on_time_s(b.safety.max_on_time_s);
  out.set_max_coil_temp_c(b.safety.max_coil_temp_C);
  return out;
}

std::string BenchesJson(const std::vector<BenchSetup>& benches) {
  nlohmann::json a = nlohmann::json::array();
  google::protobuf::util::JsonPrintOptions opt;
  opt.preserve_proto_field_names = true;  // "max_supply_V", as the heartbeats of older builds wrote them
  for (const BenchSetup& b : benches) {
    std::string info;
    (void)google::protobuf::util::MessageToJsonString(DescribeBench(b), &info, opt);
    nlohmann::json entry = nlohmann::json::parse(info);
    entry["bench_class"] = b.bench_class;
    // What admission on another host checks a run against (experiment::CheckCapabilities).
    entry["caps"] = {{"kind", b.caps.kind},
                     {"driver", b.caps.driver},
                     {"max_supply_V", b.caps.max_supply_V},
                     {"min_carrier_Hz", b.caps.min_carrier_Hz},
                     {"max_carrier_Hz", b.caps.max_carrier_Hz},
                     {"max_sample_rate_Hz", b.caps.max_sample_rate_Hz},
                     {"max_control_rate_Hz", b.caps.max_control_rate_Hz},
                     {"measures_position", b.caps.measures_position},
                     {"measures_velocity", b.caps.measures_velocity},
                     {"max_current_A", b.caps.max_current_A},
                     {"device_loops", b.caps.device_loops},
                     {"max_device_loop_Hz", b.caps.max_device_loop_Hz}};
    // What the host that claims a night needs to queue this bench's health check (docs/track.md, "In a lab"):
    // the check's block, and for an emulated bench its model and driver (the run's spec carries them).
    if (b.config.has_health()) {
      std::string health, model, driver;
      (void)google::protobuf::util::MessageToJsonString(b.config.health(), &health, opt);
      entry["health"] = nlohmann::json::parse(health);
      if (b.kind == BenchKind::kEmulated) {
        (void)google::protobuf::util::MessageToJsonString(b.model, &model, opt);
        (void)google::protobuf::util::MessageToJsonString(b.config.driver(), &driver, opt);
        entry["model_spec"] = nlohmann::json::parse(model);
        entry["driver_spec"] = nlohmann::json::parse(driver);
      }
    }
    a.push_back(std::move(entry));
  }
  return a.dump();
}

StatusOr<valvebench::v1::BenchInfo> RegisteredBench(const std::string& bench_json) {
  valvebench::v1::BenchInfo out;
  google::protobuf::util::JsonParseOptions opt;
  opt.ignore_unknown_fields = true;  // bench_class, caps: admission's, not the description's
  if (!google::protobuf::util::JsonStringToMessage(bench_json, &out, opt).ok())
    return Status::InvalidArgument("benches_json: an entry is not a bench description: " + bench_json.substr(0, 200));
  return out;
}

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
      auto kind = ParseBenchKind(b.value("kind", ""));
      if (!kind.ok()) continue;  // a kind this build does not know: no run can be admitted for it here
      s.kind = *kind;
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
      // Its health check, as its host configured it: an entry that does not parse has none here.
      google::protobuf::util::JsonParseOptions in;
      in.ignore_unknown_fields = true;  // a newer host's fields
      if (b.contains("health") && b["health"].is_object() &&
          google::protobuf::util::JsonStringToMessage(b["health"].dump(), s.config.mutable_health(), in).ok()) {
        if (b.contains("model_spec") && b["model_spec"].is_object())
          (void)google::protobuf::util::JsonStringToMessage(b["model_spec"].dump(), &s.model, in);
        if (b.contains("driver_spec") && b["driver_spec"].is_object())
          (void)google::protobuf::util::JsonStringToMessage(b["driver_spec"].dump(), s.config.mutable_driver(), in);
      } else {
        s.config.clear_health();
      }
      if (!s.name.empty() && !s.bench_class.empty()) out.push_back(std::move(s));
    }
  }
  return out;
}

}  // namespace vb::server
