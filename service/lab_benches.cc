#include "service/lab_benches.h"

#include <google/protobuf/util/json_util.h>
#include <nlohmann/json.hpp>

#include "common/bench_kind.h"
#include "proto/api_convert.h"
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

valvebench::v1::BenchCapabilities CapabilitiesToProto(const hw::Capabilities& c) {
  valvebench::v1::BenchCapabilities out;
  if (auto kind = ParseBenchKind(c.kind); !c.kind.empty() && kind.ok()) out.set_kind(api::ToProto(*kind));
  out.set_driver(c.driver);
  out.set_max_supply_v(c.max_supply_V);
  out.set_min_carrier_hz(c.min_carrier_Hz);
  out.set_max_carrier_hz(c.max_carrier_Hz);
  out.set_max_sample_rate_hz(c.max_sample_rate_Hz);
  out.set_max_control_rate_hz(c.max_control_rate_Hz);
  out.set_measures_position(c.measures_position);
  out.set_measures_velocity(c.measures_velocity);
  out.set_max_current_a(c.max_current_A);
  for (const auto& l : c.device_loops) out.add_device_loops(l);
  out.set_max_device_loop_hz(c.max_device_loop_Hz);
  return out;
}

hw::Capabilities CapabilitiesFromProto(const valvebench::v1::BenchCapabilities& c) {
  hw::Capabilities out;
  if (auto kind = api::FromProto(c.kind())) out.kind = BenchKindName(*kind);
  out.driver = c.driver();
  out.max_supply_V = c.max_supply_v();
  out.min_carrier_Hz = c.min_carrier_hz();
  out.max_carrier_Hz = c.max_carrier_hz();
  out.max_sample_rate_Hz = c.max_sample_rate_hz();
  out.max_control_rate_Hz = c.max_control_rate_hz();
  out.measures_position = c.measures_position();
  out.measures_velocity = c.measures_velocity();
  out.max_current_A = c.max_current_a();
  out.device_loops.assign(c.device_loops().begin(), c.device_loops().end());
  out.max_device_loop_Hz = c.max_device_loop_hz();
  return out;
}

valvebench::v1::BenchRegistration RegistrationOf(const BenchSetup& b) {
  valvebench::v1::BenchRegistration out;
  out.set_bench_class(b.bench_class);
  *out.mutable_caps() = CapabilitiesToProto(b.caps);
  // What the host that claims a night needs to queue this bench's health check (docs/track.md, "In a lab"):
  // the check's block, and for an emulated bench its model and driver (the run's spec carries them).
  if (b.config.has_health()) {
    *out.mutable_health() = b.config.health();
    if (b.kind == BenchKind::kEmulated) {
      *out.mutable_model_spec() = b.model;
      *out.mutable_driver_spec() = b.config.driver();
    }
  }
  return out;
}

std::string BenchesJson(const std::vector<BenchSetup>& benches) {
  nlohmann::json a = nlohmann::json::array();
  google::protobuf::util::JsonPrintOptions opt;
  opt.preserve_proto_field_names = true;  // "max_supply_V", as the heartbeats of older builds wrote them
  for (const BenchSetup& b : benches) {
    std::string info, registration;
    (void)google::protobuf::util::MessageToJsonString(DescribeBench(b), &info, opt);
    (void)google::protobuf::util::MessageToJsonString(RegistrationOf(b), &registration, opt);
    nlohmann::json entry = nlohmann::json::parse(info);
    entry.update(nlohmann::json::parse(registration));  // the two messages' fields side by side
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

std::optional<BenchSetup> RegisteredSetup(const std::string& bench_json) {
  google::protobuf::util::JsonParseOptions in;
  in.ignore_unknown_fields = true;  // the description's fields beside the registration's, a newer host's fields
  valvebench::v1::BenchInfo info;
  valvebench::v1::BenchRegistration reg;
  if (!google::protobuf::util::JsonStringToMessage(bench_json, &info, in).ok() ||
      !google::protobuf::util::JsonStringToMessage(bench_json, &reg, in).ok() || !reg.has_caps())
    return std::nullopt;  // not a registration, or written by an older build (no capabilities)
  BenchSetup s;
  s.name = info.name();
  // The typed kind; a heartbeat of a build before it has the kind only as the description's text.
  if (auto kind = api::FromProto(reg.caps().kind())) {
    s.kind = *kind;
  } else if (auto named = ParseBenchKind(info.kind()); named.ok() && !info.kind().empty()) {
    s.kind = *named;
  } else {
    return std::nullopt;  // a kind this build does not know: no run can be admitted for it here
  }
  s.bench_class = reg.bench_class();
  s.preset = info.model();
  s.paced = info.paced();
  s.device = info.device();
  s.caps = CapabilitiesFromProto(reg.caps());
  if (s.caps.kind.empty()) s.caps.kind = BenchKindName(s.kind);
  if (reg.has_health()) {
    *s.config.mutable_health() = reg.health();
    s.model = reg.model_spec();
    *s.config.mutable_driver() = reg.driver_spec();
  }
  if (s.name.empty() || s.bench_class.empty()) return std::nullopt;
  return s;
}

std::vector<BenchSetup> OtherHostsBenches(const std::vector<db::HostRecord>& hosts, const std::string& own_host) {
  std::vector<BenchSetup> out;
  for (const auto& h : hosts) {
    if (h.name == own_host) continue;
    const auto benches = nlohmann::json::parse(h.benches_json, nullptr, false);
    if (!benches.is_array()) continue;
    for (const auto& b : benches)
      if (auto s = RegisteredSetup(b.dump())) out.push_back(std::move(*s));
  }
  return out;
}

}  // namespace vb::server
