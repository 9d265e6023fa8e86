#include "benchctl/gap_commands.h"

#include <google/protobuf/util/json_util.h>

#include <fstream>
#include <iostream>
#include <sstream>

#include "benchctl/cli_common.h"
#include "experiment/spec.h"
#include "gap/diagnose.h"
#include "gap/identify.h"
#include "model/params.h"

namespace vb::benchctl {
namespace {

struct Nominal {
  valvebench::v1::ModelSpec spec;  // what the improved model extends
  model::PlantParams plant;
};

// A preset name, or a model file (ModelSpec JSON, e.g. one written by --emit-model or identify --out).
StatusOr<Nominal> LoadNominal(const std::string& which) {
  Nominal n;
  auto preset = model::Preset(which);
  if (preset.ok()) {
    n.spec.set_preset(which);
    n.plant = *preset;
    return n;
  }
  std::ifstream in(which);
  if (!in) return Status::InvalidArgument("--model: '" + which + "' is neither a preset nor a readable file");
  std::stringstream ss;
  ss << in.rdbuf();
  auto st = google::protobuf::util::JsonStringToMessage(ss.str(), &n.spec);
  if (!st.ok()) return Status::InvalidArgument(which + ": " + std::string(st.message()));
  auto plant = experiment::BuildPlant(n.spec);
  if (!plant.ok()) return plant.status().WithContext(which);
  n.plant = *plant;
  return n;
}

// The base spec plus fitted values: "R" -> params["R"], "eddy_currents.R_p" -> that effect's params.
valvebench::v1::ModelSpec Improved(valvebench::v1::ModelSpec spec, const std::vector<std::string>& effects,
                                   const std::map<std::string, double>& fitted, const std::string& description) {
  auto effect_entry = [&](const std::string& name) {
    for (auto& e : *spec.mutable_effects())
      if (e.name() == name) return &e;
    auto* e = spec.add_effects();
    e->set_name(name);
    return e;
  };
  for (const auto& e : effects) effect_entry(e);
  for (const auto& [name, v] : fitted) {
    const auto dot = name.find('.');
    if (dot == std::string::npos)
      (*spec.mutable_params())[name] = v;
    else
      (*effect_entry(name.substr(0, dot))->mutable_params())[name.substr(dot + 1)] = v;
  }
  spec.set_description(description);
  return spec;
}

Status WriteSpec(const valvebench::v1::ModelSpec& spec, const std::string& path) {
  std::string text;
  google::protobuf::util::JsonPrintOptions o;
  o.add_whitespace = true;
  o.preserve_proto_field_names = true;
  auto st = google::protobuf::util::MessageToJsonString(spec, &text, o);
  if (!st.ok()) return Status::Internal(std::string(st.message()));
  std::ofstream out(path);
  out << text;
  if (!out) return Status::Unavailable(path + ": cannot write");
  return Status::Ok();
}

StatusOr<gap::Dataset> Load(const std::string& dir) { return gap::LoadDataset(dir, model::PresetNames()); }

}  // namespace

int CmdDiagnose(const std::string& dataset_dir, const std::string& model, const std::string& json_path,
                const std::string& emit_model) {
  auto ds = Load(dataset_dir);
  if (!ds.ok()) return Fail(ds.status());
  auto nominal = LoadNominal(model.empty() ? ds->model : model);
  if (!nominal.ok()) return Fail(nominal.status());
  auto d = gap::Diagnose(*ds, nominal->plant);
  if (!d.ok()) return Fail(d.status().WithContext(dataset_dir));
  if (!emit_model.empty()) {
    if (d->verdict == "unknown")
      return Fail(Status::FailedPrecondition("--emit-model: no candidate in the catalog explains the gap (verdict "
                                             "unknown); not writing a model that claims one"));
    std::vector<std::string> effects;
    std::map<std::string, double> fitted;
    std::string desc = "the nominal model: no significant gap in " + dataset_dir;
    if (d->chosen >= 0) {
      const auto& row = d->ranking[static_cast<std::size_t>(d->chosen)];
      effects = d->candidates[static_cast<std::size_t>(d->chosen)].effects;
      fitted = row.params;
      desc = "nominal + " + d->verdict + ", fitted by benchctl diagnose on " + dataset_dir;
    }
    if (auto st = WriteSpec(Improved(nominal->spec, effects, fitted, desc), emit_model); !st.ok()) return Fail(st);
  }
  if (json_path == "-") {
    std::cout << gap::DiagnosisJson(*d) << "\n";
    return kExitOk;
  }
  if (!json_path.empty()) {
    std::ofstream out(json_path);
    out << gap::DiagnosisJson(*d) << "\n";
    if (!out) return Fail(Status::Unavailable(json_path + ": cannot write"));
  }
  std::cout << gap::DiagnosisReport(*d);
  if (!emit_model.empty()) std::cout << "improved model written to " << emit_model << "\n";
  return kExitOk;
}

int CmdIdentify(const std::string& dataset_dir, const std::string& model, const std::vector<std::string>& params,
                const std::string& out_path, bool json) {
  auto ds = Load(dataset_dir);
  if (!ds.ok()) return Fail(ds.status());
  auto nominal = LoadNominal(model.empty() ? ds->model : model);
  if (!nominal.ok()) return Fail(nominal.status());
  auto id = gap::Identify(*ds, nominal->plant, params);
  if (!id.ok()) return Fail(id.status());
  if (!out_path.empty()) {
    auto st = WriteSpec(Improved(nominal->spec, {}, id->fit.params, {}), out_path);
    if (!st.ok()) return Fail(st);
  }
  if (json) {
    std::cout << gap::IdentificationJson(*id) << "\n";
  } else {
    std::cout << gap::IdentificationReport(*id);
    if (!out_path.empty()) std::cout << "identified model written to " << out_path << "\n";
  }
  return kExitOk;
}

}  // namespace vb::benchctl
