#include "gap/improved_model.h"

#include <google/protobuf/util/json_util.h>

namespace vb::gap {
namespace {

bool IsDriverValue(const std::string& name) { return name.rfind("driver.", 0) == 0; }

// The base spec plus fitted values: "R" -> params["R"], "eddy_currents.R_p" -> that effect's params.
valvebench::v1::ModelSpec WithPlantValues(valvebench::v1::ModelSpec spec, const std::vector<std::string>& effects,
                                          const std::map<std::string, double>& fitted,
                                          const std::string& description) {
  auto effect_entry = [&](const std::string& name) {
    for (auto& e : *spec.mutable_effects())
      if (e.name() == name) return &e;
    auto* e = spec.add_effects();
    e->set_name(name);
    return e;
  };
  for (const auto& e : effects) effect_entry(e);
  for (const auto& [name, v] : fitted) {
    if (IsDriverValue(name)) continue;  // WithValues writes the driver
    const auto dot = name.find('.');
    if (dot == std::string::npos)
      (*spec.mutable_params())[name] = v;
    else
      (*effect_entry(name.substr(0, dot))->mutable_params())[name.substr(dot + 1)] = v;
  }
  spec.set_description(description);
  return spec;
}

}  // namespace

valvebench::v1::ModelSpec WithValues(valvebench::v1::ModelSpec spec, const std::vector<std::string>& effects,
                                     const std::map<std::string, double>& values,
                                     const model::DriverParams& driver_base, const std::string& description) {
  spec = WithPlantValues(std::move(spec), effects, values, description);
  bool driver_fitted = false;
  for (const auto& [name, v] : values) driver_fitted = driver_fitted || IsDriverValue(name);
  if (driver_fitted || spec.has_identified_driver()) {
    auto* d = spec.mutable_identified_driver();
    d->set_kind(std::string(model::DriverKindName(driver_base.kind)));
    (*d->mutable_params())["diode_drop_V"] = driver_base.diode_drop_V;
    for (const auto& [name, v] : values)
      if (IsDriverValue(name)) (*d->mutable_params())[name.substr(7)] = v;
  }
  return spec;
}

StatusOr<valvebench::v1::ModelSpec> ImprovedModel(const Diagnosis& d, const valvebench::v1::ModelSpec& nominal,
                                                  const model::DriverParams& driver_in, const std::string& fitted_by) {
  if (d.verdict_kind == VerdictKind::kUnknown)
    return Status::FailedPrecondition("no candidate in the catalog explains the gap (verdict unknown); the "
                                      "diagnosis stands, no model written");
  if (d.verdict_kind == VerdictKind::kUndetermined)
    return Status::FailedPrecondition("the reference was not identified well enough to tell (verdict undetermined); "
                                      "the diagnosis stands, no model written");
  // The model the diagnosis started from; with a reference: as identified there.
  valvebench::v1::ModelSpec base = nominal;
  model::DriverParams driver = driver_in;
  if (d.has_reference) {
    std::vector<std::string> ref_effects;
    for (const auto& [name, v] : d.reference.params) {
      const auto dot = name.find('.');
      if (dot != std::string::npos && !IsDriverValue(name)) ref_effects.push_back(name.substr(0, dot));
      if (name == "driver.diode_drop_V") driver.diode_drop_V = v;
    }
    base = WithValues(base, ref_effects, d.reference.params, driver_in, "");
  }
  std::vector<std::string> effects;
  std::map<std::string, double> fitted;
  std::string desc = "the nominal model: no significant gap (" + fitted_by + ")";
  if (d.chosen >= 0) {
    const auto k = static_cast<std::size_t>(d.chosen);
    effects = d.candidates[k].effects;
    fitted = d.ranking[k].params;
    for (const auto& [name, v] : d.candidates[k].fixed) fitted[name] = v;
    desc = "nominal + " + d.verdict + ", fitted by " + fitted_by;
  }
  return WithValues(base, effects, fitted, driver, desc);
}

std::string ModelSpecJson(const valvebench::v1::ModelSpec& spec) {
  std::string text;
  google::protobuf::util::JsonPrintOptions o;
  o.add_whitespace = true;
  o.preserve_proto_field_names = true;
  (void)google::protobuf::util::MessageToJsonString(spec, &text, o);
  return text;
}

}  // namespace vb::gap
