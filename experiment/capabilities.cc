#include "common/format.h"
#include "experiment/capabilities.h"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>


namespace vb::experiment {

namespace {

// Every PWM carrier the controller section asks for, with its field path ("controller.pi_current.carrier_Hz").
// A carrier_Hz left at 0 means the 20 kHz default (docs/spec.md); a frequency_Hz of 0 a constant gate level.
void Carriers(const google::protobuf::Message& m, const std::string& path,
              std::vector<std::pair<std::string, double>>* out) {
  const auto* d = m.GetDescriptor();
  const auto* r = m.GetReflection();
  for (int k = 0; k < d->field_count(); ++k) {
    const auto* f = d->field(k);
    const std::string p = path + "." + f->name();
    if (f->cpp_type() == google::protobuf::FieldDescriptor::CPPTYPE_MESSAGE) {
      if (f->is_repeated()) {
        for (int j = 0; j < r->FieldSize(m, f); ++j)
          Carriers(r->GetRepeatedMessage(m, f, j), p + "[" + std::to_string(j) + "]", out);
      } else if (r->HasField(m, f)) {
        Carriers(r->GetMessage(m, f), p, out);
      }
      continue;
    }
    if (f->cpp_type() != google::protobuf::FieldDescriptor::CPPTYPE_DOUBLE || f->is_repeated()) continue;
    const double v = r->GetDouble(m, f);
    if (f->name() == "carrier_Hz") out->emplace_back(p, v > 0.0 ? v : 20e3);
    if ((f->name() == "frequency_Hz" || f->name() == "min_frequency_Hz" || f->name() == "max_frequency_Hz") && v > 0.0)
      out->emplace_back(p, v);
  }
}

}  // namespace

Status CheckCapabilities(const Experiment& e, const hw::Capabilities& caps) {
  auto refuse = [&](const std::string& what) {
    return Status::FailedPrecondition(what + " (bench kind " + caps.kind + ")");
  };
  if (e.run.supply_V > caps.max_supply_V)
    return refuse("conditions.supply_V: " + FormatNumber(e.run.supply_V) + " V exceeds the bench's " + FormatNumber(caps.max_supply_V) +
                  " V");
  if (e.run.sample_rate_Hz > caps.max_sample_rate_Hz)
    return refuse("recording.rate_Hz: " + FormatNumber(e.run.sample_rate_Hz) + " Hz exceeds the bench's " +
                  FormatNumber(caps.max_sample_rate_Hz) + " Hz");
  if (e.controller != nullptr && e.controller->period_s() > 0.0 && caps.max_control_rate_Hz > 0.0) {
    const double rate = 1.0 / e.controller->period_s();
    if (rate > caps.max_control_rate_Hz * (1.0 + 1e-9)) {
      std::string hint;
      if (!caps.device_loops.empty()) {
        hint = "; its firmware runs these loops on-device:";
        for (const auto& l : caps.device_loops) hint += " " + l;
      }
      return refuse("controller: its loop runs at " + FormatNumber(rate) + " Hz, faster than the bench's host loop of " +
                    FormatNumber(caps.max_control_rate_Hz) + " Hz" + hint);
    }
  }
  if (e.controlled == ControlledVariable::kPosition && !caps.measures_position)
    return refuse("controller: it controls the position, and the bench does not measure it");
  if (!e.spec.bench().driver().kind().empty() && !caps.driver.empty() && caps.driver != "internal_electronics" &&
      std::string(model::DriverKindName(e.driver.kind)) != caps.driver)
    return refuse("bench.driver.kind: the spec needs " + std::string(model::DriverKindName(e.driver.kind)) +
                  ", the bench has " + caps.driver);
  std::vector<std::pair<std::string, double>> carriers;
  Carriers(e.spec.controller(), "controller", &carriers);
  for (const auto& [path, f] : carriers)
    if (f < caps.min_carrier_Hz || f > caps.max_carrier_Hz)
      return refuse(path + ": " + FormatNumber(f) + " Hz is outside the bench's PWM range [" + FormatNumber(caps.min_carrier_Hz) +
                    ", " + FormatNumber(caps.max_carrier_Hz) + "] Hz");
  return Status::Ok();
}

}  // namespace vb::experiment
