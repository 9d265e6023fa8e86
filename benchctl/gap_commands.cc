#include "benchctl/gap_commands.h"

#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <fstream>
#include <iostream>
#include <sstream>

#include "benchctl/cli_common.h"
#include "client/client.h"
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

namespace {

int DiagnoseAndReport(const gap::Dataset& ds, const Nominal& nominal, const std::string& source,
                      const std::string& json_path, const std::string& emit_model) {
  auto d = gap::Diagnose(ds, nominal.plant);
  if (!d.ok()) return Fail(d.status().WithContext(source));
  if (!emit_model.empty()) {
    if (d->verdict == "unknown")
      return Fail(Status::FailedPrecondition("--emit-model: no candidate in the catalog explains the gap (verdict "
                                             "unknown); not writing a model that claims one"));
    std::vector<std::string> effects;
    std::map<std::string, double> fitted;
    std::string desc = "the nominal model: no significant gap in " + source;
    if (d->chosen >= 0) {
      const auto& row = d->ranking[static_cast<std::size_t>(d->chosen)];
      effects = d->candidates[static_cast<std::size_t>(d->chosen)].effects;
      fitted = row.params;
      desc = "nominal + " + d->verdict + ", fitted by benchctl diagnose on " + source;
    }
    if (auto st = WriteSpec(Improved(nominal.spec, effects, fitted, desc), emit_model); !st.ok()) return Fail(st);
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

std::string TagValue(const valvebench::v1::Run& run, const std::string& key) {
  for (const auto& t : run.tags())
    if (t.rfind(key + ":", 0) == 0) return t.substr(key.size() + 1);
  return "";
}

}  // namespace

int CmdDiagnose(const std::string& dataset_dir, const std::string& model, const std::string& json_path,
                const std::string& emit_model) {
  auto ds = Load(dataset_dir);
  if (!ds.ok()) return Fail(ds.status());
  auto nominal = LoadNominal(model.empty() ? ds->model : model);
  if (!nominal.ok()) return Fail(nominal.status());
  return DiagnoseAndReport(*ds, *nominal, dataset_dir, json_path, emit_model);
}

int RemoteDiagnose(client::Client& c, const std::vector<std::int64_t>& run_ids, const std::string& model,
                   const std::string& json_path, const std::string& emit_model) {
  gap::Dataset ds;
  ds.format = std::string(gap::kFormatValveRuns1);
  double first_start_unix = -1.0;
  for (std::size_t k = 0; k < run_ids.size(); ++k) {
    const std::string where = "run " + std::to_string(run_ids[k]);
    auto run = c.GetRun(run_ids[k]);
    if (!run.ok()) return Fail(run.status().WithContext(where));
    if (run->status() != valvebench::v1::DONE) return Fail(Status::FailedPrecondition(where + ": not done"));
    auto trace = c.GetTrace(run_ids[k]);
    if (!trace.ok()) return Fail(trace.status().WithContext(where));
    if (!trace->columns.count("gate") || !trace->columns.count("i_A"))
      return Fail(Status::InvalidArgument(where + ": the trace has no gate and i_A channels"));
    gap::RunData r;
    r.id = std::to_string(run_ids[k]) + ":" + run->name();
    r.file = where;
    r.supply_V = run->spec().conditions().supply_v();
    r.supply_pressure_Pa = run->spec().conditions().supply_pressure_pa();
    const std::string t_start = TagValue(*run, "t_start_s");
    if (first_start_unix < 0.0) first_start_unix = run->started_unix_s();
    r.t_start_s = !t_start.empty() ? std::stod(t_start) : run->started_unix_s() - first_start_unix;
    const std::string split = TagValue(*run, "split");
    r.split = split == "fit" || split == "holdout" ? split : "";
    r.sample_period_s = trace->sample_period_s;
    r.i_A = trace->columns.at("i_A");
    for (std::size_t j = 0; j < r.i_A.size(); ++j) {
      const double g = trace->columns.at("gate")[j];
      if (g != 0.0 && g != 1.0)
        return Fail(Status::InvalidArgument(where + ": gate[" + std::to_string(j) + "] is " + std::to_string(g) +
                                            "; the diagnosis needs a low-side switch command (0 or 1)"));
      r.gate.push_back(static_cast<std::int8_t>(g));
      r.t_s.push_back(static_cast<double>(j) * r.sample_period_s);
    }
    if (k == 0) ds.model = run->spec().bench().model().preset().empty() ? "taghizadeh2009" : run->spec().bench().model().preset();
    ds.runs.push_back(std::move(r));
  }
  std::stable_sort(ds.runs.begin(), ds.runs.end(),
                   [](const gap::RunData& a, const gap::RunData& b) { return a.t_start_s < b.t_start_s; });
  // A split only if every run has one (as for a manifest); otherwise the diagnosis makes its own.
  const bool all_split = std::all_of(ds.runs.begin(), ds.runs.end(), [](const gap::RunData& r) { return !r.split.empty(); });
  if (!all_split)
    for (auto& r : ds.runs) r.split.clear();
  auto nominal = LoadNominal(model.empty() ? ds.model : model);
  if (!nominal.ok()) return Fail(nominal.status());
  return DiagnoseAndReport(ds, *nominal, "server runs", json_path, emit_model);
}

int RemoteImport(client::Client& c, const std::string& dataset_dir, bool json) {
  auto ds = Load(dataset_dir);
  if (!ds.ok()) return Fail(ds.status());
  valvebench::v1::ImportRunsRequest req;
  std::string name = dataset_dir;
  while (!name.empty() && name.back() == '/') name.pop_back();
  name = name.substr(name.find_last_of('/') == std::string::npos ? 0 : name.find_last_of('/') + 1);
  req.set_dataset(name);
  req.set_model(ds->model);
  req.set_description(ds->description);
  for (const auto& r : ds->runs) {
    auto* out = req.add_runs();
    out->set_id(r.id);
    out->set_supply_v(r.supply_V);
    out->set_supply_pressure_pa(r.supply_pressure_Pa);
    out->set_t_start_s(r.t_start_s);
    out->set_split(r.split);
    out->set_sample_period_s(r.sample_period_s);
    for (auto g : r.gate) out->add_gate(g);
    for (double i : r.i_A) out->add_i_a(i);
    for (double x : r.x_m) out->add_x_m(x);
    for (double v : r.v_coil_V) out->add_v_coil_v(v);
  }
  auto resp = c.ImportRuns(req);
  if (!resp.ok()) return Fail(resp.status().WithContext("import " + name));
  std::string ids;
  for (auto id : resp->run_ids()) {
    if (!ids.empty()) ids += ',';
    ids += std::to_string(id);
  }
  if (json) {
    std::cout << "{\"dataset\": \"" << name << "\", \"batch_id\": " << resp->batch_id() << ", \"run_ids\": [" << ids
              << "]}\n";
  } else {
    std::cout << "imported " << resp->run_ids_size() << " runs of " << name << " as batch " << resp->batch_id()
              << "\ndiagnose them with: benchctl diagnose --runs " << ids << "\n";
  }
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
