#include "benchctl/gap_commands.h"

#include <google/protobuf/util/json_util.h>

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>
#include <optional>

#include <unistd.h>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "benchctl/cli_common.h"
#include "benchctl/backend.h"
#include "client/client.h"
#include "experiment/spec.h"
#include "gap/diagnose.h"
#include "gap/hold.h"
#include "gap/import_request.h"
#include "gap/stored_runs.h"
#include "gap/suggest.h"
#include "gap/identify.h"
#include "gap/track.h"
#include "gap/improved_model.h"
#include "gap/moving_valve.h"
#include "gap/scope_csv.h"
#include "gap/readings_csv.h"
#include "model/driver.h"
#include "model/params.h"

namespace vb::benchctl {
namespace {

struct Nominal {
  valvebench::v1::ModelSpec spec;  // what the improved model extends
  model::PlantParams plant;
  std::optional<model::DriverParams> driver;  // the driver the model was identified with, if it says
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
  if (n.spec.has_identified_driver()) {
    auto d = experiment::BuildDriver(n.spec.identified_driver());
    if (!d.ok()) return d.status().WithContext(which + ": identified_driver");
    n.driver = *d;
  }
  return n;
}

// The model a dataset is diagnosed against: --model, else the dataset's (a preset or its model file).
StatusOr<Nominal> NominalFor(const gap::Dataset& ds, const std::string& model) {
  if (!model.empty()) return LoadNominal(model);
  return LoadNominal(ds.model_file.empty() ? ds.model : ds.model_file);
}

using gap::WithValues;  // the one model builder (gap/improved_model.h), shared with the server's DiagnoseRuns

Status WriteSpec(const valvebench::v1::ModelSpec& spec, const std::string& path) {
  std::ofstream out(path);
  out << gap::ModelSpecJson(spec);
  if (!out) return Status::Unavailable(path + ": cannot write");
  return Status::Ok();
}

StatusOr<gap::Dataset> Load(const std::string& dir) {
  auto ds = gap::LoadDataset(dir, model::PresetNames());
  if (ds.ok())
    for (const auto& w : ds->warnings) std::fprintf(stderr, "benchctl: warning: %s\n", w.c_str());
  return ds;
}

// Parses --params / --reference-params SPEC lists and --fix NAME=V lists.
StatusOr<gap::IdentifyOptions> IdentifyOptionsFrom(const std::vector<std::string>& params,
                                                   const std::vector<std::string>& fixed,
                                                   gap::IdentifyOptions::Global global, const std::string& flag) {
  gap::IdentifyOptions o;
  for (const auto& p : params) {
    auto spec = gap::ParseParamSpec(p, flag);
    if (!spec.ok()) return spec.status();
    o.params.push_back(*spec);
  }
  for (const auto& f : fixed) {
    auto v = gap::ParseFixed(f, "--fix");
    if (!v.ok()) return v.status();
    o.fixed.push_back(*v);
  }
  o.global = global;
  return o;
}

// What a reference session is fitted for when the user names nothing: R, the inductance of a coil with one
// (held or constant-law), and the sense chain's offset.
std::vector<std::string> DefaultReferenceParams(const gap::Dataset& ds, const model::PlantParams& plant) {
  std::vector<std::string> out = {"R"};
  bool held = !ds.runs.empty();
  for (const auto& r : ds.runs) held = held && std::isfinite(r.stroke_m);
  if ((plant.law == model::InductanceLaw::kConstant || held) && plant.inductance_stroke_m.empty()) out.push_back("L");
  out.push_back("sensor_offset.offset_A");
  return out;
}

}  // namespace

namespace {

// Where the diagnosis goes: JSON on stdout (json_stdout) or the text report; JSON also into json_out; the
// improved model into model_out.
struct DiagnoseOutput {
  bool json_stdout = false;
  std::string json_out;
  std::string model_out;
  std::string suggest_out;  // the next experiment's spec (docs/gap.md, "The next experiment")
};

int DiagnoseAndReport(const gap::Dataset& ds_in, const Nominal& nominal, const std::string& source,
                      const DiagnoseOutput& o, gap::DiagnoseOptions options) {
  gap::Dataset ds_copy;
  const gap::Dataset* ds = &ds_in;
  if (nominal.driver) {  // the model's identified driver replaces the dataset's declared one
    ds_copy = ds_in;
    ds_copy.driver = *nominal.driver;
    ds = &ds_copy;
  }
  if (isatty(STDERR_FILENO))  // progress is for people at a terminal; scripts get stdout alone
    std::fprintf(stderr, "benchctl: diagnosing %zu runs of %s against %s ...\n", ds->runs.size(), source.c_str(),
                 options.model_name.c_str());
  if (isatty(STDERR_FILENO)) {
    // Honest progress: one line per fitted candidate, overwritten in place.
    options.attribution.progress = [](const std::string& name, int done, int total) {
      std::fprintf(stderr, "\rbenchctl: fitted %d of %d candidates (%s)\033[K", done, total, name.c_str());
      if (done == total) std::fprintf(stderr, "\n");
    };
  }
  auto d = gap::Diagnose(*ds, nominal.plant, options);
  if (!d.ok()) return Fail(d.status().WithContext(source));
  std::optional<gap::Suggestion> suggestion;
  if (!o.suggest_out.empty()) {
    auto s = gap::SuggestNextRuns(*ds, nominal.plant, *d);
    if (!s.ok()) return Fail(s.status().WithContext("--suggest"));
    suggestion = std::move(*s);
    if (!suggestion->runs.empty()) {
      std::ofstream out(o.suggest_out);
      out << gap::SuggestionSpecJson(*suggestion, "next-experiment", nominal.spec.preset().empty() ? model::kDefaultPreset
                                                                                                   : nominal.spec.preset());
      out.close();
      if (!out) return Fail(Status::Unavailable(o.suggest_out + ": cannot write"));
    }
  }
  if (!o.json_out.empty()) {
    std::ofstream out(o.json_out);
    out << gap::DiagnosisJson(*d) << "\n";
    out.close();
    if (!out) return Fail(Status::Unavailable(o.json_out + ": cannot write"));
  }
  if (o.json_stdout) {
    if (suggestion) {
      auto j = nlohmann::ordered_json::parse(gap::DiagnosisJson(*d));
      j["suggestion"] = nlohmann::ordered_json::parse(gap::SuggestionJson(*suggestion));
      std::cout << j.dump(2) << "\n";
    } else {
      std::cout << gap::DiagnosisJson(*d) << "\n";
    }
  } else {
    std::cout << gap::DiagnosisReport(*d);
    if (suggestion) {
      std::cout << gap::SuggestionReport(*suggestion);
      if (!suggestion->runs.empty())
        std::cout << "  spec written to " << o.suggest_out << " (benchctl run " << o.suggest_out << ")\n";
    }
  }
  if (o.model_out.empty()) return kExitOk;
  auto improved = gap::ImprovedModel(*d, nominal.spec, ds->driver, "benchctl diagnose on " + source);
  if (!improved.ok())
    return Fail(improved.status().WithContext("--model-out"));
  if (auto st = WriteSpec(*improved, o.model_out); !st.ok()) return Fail(st);
  if (!o.json_stdout) std::cout << "improved model written to " << o.model_out << "\n";
  return kExitOk;
}


}  // namespace

namespace {

// A stored run, from the local store or a server (the same fields either way), as the diagnosis takes it.
StatusOr<gap::StoredRun> FetchStoredRun(Backend& backend, std::int64_t id) {
  const std::string where = "run " + std::to_string(id);
  auto run = backend.GetRun(id);
  if (!run.ok()) return run.status().WithContext(where);
  if (!run->ok()) return Status::FailedPrecondition(where + ": not done");
  const valvebench::v1::ExperimentSpec spec = run->spec.value_or(valvebench::v1::ExperimentSpec{});
  auto trace = backend.GetTrace(id);
  if (!trace.ok()) return trace.status().WithContext(where);
  if (!trace->columns.count("gate") || !trace->columns.count("i_A"))
    return Status::InvalidArgument(where + ": the trace has no gate and i_A channels");
  gap::StoredRun s = gap::StoredRunOf(id, run->key, spec, run->started_unix_s, run->t_start_s, run->split);
  s.sample_period_s = trace->sample_period_s;
  s.gate = std::move(trace->columns.at("gate"));
  s.i_A = std::move(trace->columns.at("i_A"));
  return s;
}

// Stored runs are diagnosed by the service (DiagnoseRuns), the server's or the local one: the same diagnosis the
// web page and Python get (issue 40: one diagnosis of stored runs).
int StoredDiagnose(Backend& backend, const std::vector<std::int64_t>& run_ids, const std::string& model,
                   const DiagnoseOutput& out) {
  valvebench::v1::DiagnoseRunsRequest req;
  for (std::int64_t id : run_ids) req.add_run_ids(id);
  if (!model.empty()) {
    if (model::Preset(model).ok()) {
      req.set_model(model);
    } else {  // a model file: its spec travels (values, identified driver)
      auto nominal = LoadNominal(model);
      if (!nominal.ok()) return Fail(nominal.status());
      *req.mutable_model_spec() = nominal->spec;
    }
  }
  req.set_suggest(!out.suggest_out.empty());
  if (isatty(STDERR_FILENO))
    std::fprintf(stderr, "benchctl: diagnosing %zu stored runs on the %s (seconds to a minute) ...\n", run_ids.size(),
                 backend.Where().c_str());
  auto resp = backend.DiagnoseRuns(req);
  if (!resp.ok()) return Fail(resp.status().WithContext("stored runs (" + backend.Where() + ")"));
  auto write = [](const std::string& path, const std::string& text) {
    std::ofstream f(path);
    f << text;
    f.close();
    return f ? Status::Ok() : Status::Unavailable(path + ": cannot write");
  };
  if (!out.suggest_out.empty() && !resp->suggestion_spec_json().empty())
    if (auto st = write(out.suggest_out, resp->suggestion_spec_json()); !st.ok()) return Fail(st);
  if (!out.json_out.empty())
    if (auto st = write(out.json_out, resp->report_json() + "\n"); !st.ok()) return Fail(st);
  if (out.json_stdout) {
    if (req.suggest()) {
      auto j = nlohmann::ordered_json::parse(resp->report_json());
      j["suggestion"] = nlohmann::ordered_json::parse(resp->suggestion_json());
      std::cout << j.dump(2) << "\n";
    } else {
      std::cout << resp->report_json() << "\n";
    }
  } else {
    std::cout << resp->report();
    if (req.suggest()) {
      std::cout << resp->suggestion_report();
      if (!resp->suggestion_spec_json().empty())
        std::cout << "  spec written to " << out.suggest_out << " (benchctl run " << out.suggest_out << ")\n";
    }
  }
  if (out.model_out.empty()) return kExitOk;
  if (resp->improved_model_json().empty()) {
    const auto j = nlohmann::json::parse(resp->report_json(), nullptr, false);
    const std::string verdict = j.is_object() ? j.value("verdict", std::string("?")) : std::string("?");
    return Fail(Status::FailedPrecondition("--model-out: no effect was attributed (verdict " + verdict +
                                           "); the diagnosis stands, no model written"));
  }
  if (auto st = write(out.model_out, resp->improved_model_json()); !st.ok()) return Fail(st);
  if (!out.json_stdout) std::cout << "improved model written to " << out.model_out << "\n";
  return kExitOk;
}

int ImportDataset(Backend& backend, const std::string& dataset_dir, bool json) {
  auto ds = Load(dataset_dir);
  if (!ds.ok()) return Fail(ds.status());
  valvebench::v1::ImportRunsRequest req;
  std::string name = dataset_dir;
  while (!name.empty() && name.back() == '/') name.pop_back();
  name = name.substr(name.find_last_of('/') == std::string::npos ? 0 : name.find_last_of('/') + 1);
  if (auto st = gap::FillImportRequest(*ds, name, &req); !st.ok()) return Fail(st);
  auto resp = backend.Import(req);
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

}  // namespace

GapCli::GapCli(CLI::App* app, SharedOptions shared) : shared_(shared) {
  auto server_opts = [&](CLI::App* sub) {
    AddServerOptions(sub, shared_);
  };
  diagnose_ = app->add_subcommand("diagnose", "where and why measured runs differ from the model (valve-runs/1, /2)");
  diagnose_->add_option("dataset", dataset_dir_, "dataset directory (manifest.json and its files)");
  diagnose_->add_option("--runs", runs_, "diagnose these stored runs instead (the server's, or the local store's)")
      ->delimiter(',');
  diagnose_->add_flag("--local", local_, "--runs: the local store, even if a server is configured");
  diagnose_->add_option("--db", *shared_.store_path, "local store (default $VALVEBENCH_DB or ~/.local/share/valvebench/local.db)");
  server_opts(diagnose_);
  diagnose_->add_option("--model", model_, "preset name or model file (ModelSpec JSON); default: the dataset's");
  diagnose_->add_option("--reference", reference_dir_,
                        "a reference session of the same device: diagnose what changed since it");
  diagnose_->add_option("--reference-params", reference_params_,
                        "parameters identified on the reference (default: R, L of a coil, sensor_offset.offset_A)")
      ->delimiter(',');
  // --json takes an optional value only so that the old `--json FILE` keeps working (Diagnose()).
  diagnose_->add_option("--json", json_path_, "the diagnosis as JSON on stdout")->expected(0, 1)->type_name("");
  diagnose_->add_option("--json-out", json_out_, "also write the diagnosis as JSON to FILE (for report --diagnosis)");
  diagnose_->add_option("--model-out", model_out_,
                        "write the improved model (ModelSpec JSON: --model and an emulated bench load it)");
  diagnose_->add_option("--emit-model", emit_model_, "old name of --model-out");
  diagnose_->add_option("--add-runs", add_runs_,
                        "add these stored runs (the local store's or the server's) to the dataset as holdout runs, "
                        "e.g. the ones --suggest proposed")
      ->delimiter(',');
  diagnose_->add_option("--suggest", suggest_out_,
                        "when the leading candidates are confusable, write the runs that would separate them best "
                        "(an experiment spec: benchctl run FILE) and list them");

  identify_ = app->add_subcommand("identify", "fit a device's parameters to measured runs (seed 000 sec. 4)");
  identify_->add_option("dataset", dataset_dir_, "dataset directory (valve-runs/1 or /2)")->required();
  identify_->add_option("--params", params_,
                        "parameters to fit: NAME[=LO:HI][@START], e.g. R=5:200,L=0.01:2,sensor_offset.offset_A; "
                        "without it, a moving valve's switch-on runs are identified from scratch")
      ->delimiter(',');
  identify_->add_option("--fix", fixed_, "parameters held at a value: NAME=VALUE,...")->delimiter(',');
  identify_->add_flag("--global", global_, "a global search before the local fit (default: when a box spans > 3.5x or crosses 0)");
  identify_->add_flag("--no-global", no_global_, "local fit only (from the start values), no global search first");
  identify_->add_option("--model", model_, "preset name or model file (ModelSpec JSON); default: the dataset's");
  identify_->add_option("--model-out", model_out_, "write the identified model (ModelSpec JSON: --model loads it)");
  identify_->add_option("--out", out_path_, "old name of --model-out");
  identify_->add_flag("--json", *shared_.json, "machine-readable output on stdout");

  convert_ = app->add_subcommand("convert", "readings CSV (one periodic steady-state reading per row) -> valve-runs/2 datasets; with --channel, a scope capture -> one run of a dataset");
  convert_->add_option("csv", csv_path_, "the readings file (docs/real-data.md gives its columns)")->required();
  convert_->add_option("outdir", out_dir_, "where the datasets go, one directory per session")->required();
  convert_->add_option("--shunt-ohm", shunt_ohm_, "sense resistor in the switch's source path [ohm]")->capture_default_str();
  convert_->add_option("--amp-ref-ohm", amp_ref_ohm_, "amplifier gain = 1 + amp_feedback_ohm / this [ohm]")->capture_default_str();
  convert_->add_option("--adc-lsb-V", adc_lsb_V_, "the ADC's step at its input [V]")->capture_default_str();
  convert_->add_option("--averaged", averaged_, "PWM periods averaged into one reading")->capture_default_str();
  convert_->add_option("--model", convert_model_, "model the datasets name (preset, or NAME.json beside them)")->capture_default_str();
  convert_->add_flag("--json", *shared_.json, "machine-readable output on stdout");
  // A scope's CSV export of one switch-on capture (gap/scope_csv.h): one run appended to OUTDIR's dataset.
  convert_->add_option("--channel", scope_channel_, "scope CSV: the current's column (name or 1-based index); "
                                                    "with it, CSV is one scope capture and OUTDIR one dataset");
  convert_->add_option("--time-column", scope_time_column_, "scope CSV: the time column [s] (default: the first)");
  convert_->add_option("--probe-A-per-V", scope_probe_A_per_V_, "scope CSV: a current probe's scale (instead of --shunt-ohm)");
  convert_->add_option("--gate-channel", scope_gate_channel_, "scope CSV: the gate drive's column (its rising edge)");
  convert_->add_option("--gate-threshold-V", scope_gate_threshold_V_, "scope CSV: gate high above this (default: mid-range)");
  convert_->add_option("--trigger-s", scope_trigger_s_, "scope CSV: the gate's rising edge in the time column (instead of --gate-channel)");
  convert_->add_option("--supply-V", scope_supply_V_, "scope CSV: the supply during the capture [V]");
  convert_->add_option("--pressure-Pa", scope_pressure_Pa_, "scope CSV: the supply pressure (gauge) [Pa]");
  convert_->add_option("--run-id", scope_run_id_, "scope CSV: the run's id (default: the file name)");
  convert_->add_option("--split", scope_split_, "scope CSV: fit or holdout");
  convert_->add_option("--t-start-s", scope_t_start_s_, "scope CSV: when the capture was taken [s] (default: after the last run)");
  convert_->add_option("--device", scope_device_, "scope CSV: the device's name (a new dataset)");
  convert_->add_option("--noise-A", scope_noise_A_, "scope CSV: white noise of one sweep [A] (declared in a new dataset)");
  convert_->add_option("--lsb-A", scope_lsb_A_, "scope CSV: the capture's resolution [A] (declared in a new dataset)");

  import_ = app->add_subcommand("import", "store a dataset's waveform runs on the server");
  import_->add_option("dataset", dataset_dir_, "dataset directory (manifest.json and its files)")->required();
  import_->add_flag("--json", *shared_.json, "machine-readable output on stdout");
  import_->add_flag("--local", local_, "the local store, even if a server is configured");
  import_->add_option("--db", *shared_.store_path, "local store");
  server_opts(import_);

  track_ = app->add_subcommand("track", "a bench's valve tracked session by session: each determined parameter's "
                                        "value, control limits and the first session flagged (docs/track.md)");
  track_->add_option("sessions", track_dirs_, "switch-on session directories (valve-runs/2), in time order")
      ->required()
      ->expected(2, -1);
  track_->add_option("--model", model_, "preset name or model file (ModelSpec JSON); default: the first session's");
  track_->add_option("--limit", track_limits_, "declared limits: NAME=VALUE,... (e.g. R=70): the drift's projected "
                                               "crossing is reported")
      ->delimiter(',')
      ->allow_extra_args(false);
  track_->add_option("--arl0", track_arl0_, "the detector's in-control run length per parameter, in sessions "
                                            "(sets the CUSUM's interval)")
      ->capture_default_str();
  track_->add_option("--reference", track_reference_, "sessions that form the reference before monitoring starts "
                                                      "(fewer: earlier flags, more false ones; docs/track.md)")
      ->capture_default_str();
  track_->add_flag("--json", *shared_.json, "machine-readable output on stdout");

  health_ = app->add_subcommand("health", "each bench's valve tracked from its nightly health checks (the server's "
                                          "or the local store's runs tagged health): as track, per bench");
  health_->add_option("bench", health_bench_, "the bench (default: every bench with health checks stored)");
  health_->add_option("--model", model_, "preset name or model file (ModelSpec JSON); default: the checks' own");
  health_->add_option("--limit", track_limits_, "declared limits: NAME=VALUE,... (e.g. R=70)")
      ->delimiter(',')
      ->allow_extra_args(false);
  health_->add_option("--arl0", track_arl0_, "the detector's in-control run length per parameter, in nights")
      ->capture_default_str();
  health_->add_flag("--json", *shared_.json, "machine-readable output on stdout");
  health_->add_flag("--recompute", health_recompute_, "identify every stored check here again instead of reading "
                                                      "the tracking the server's nights kept");
  health_->add_flag("--local", local_, "the local store, even if a server is configured");
  health_->add_option("--db", *shared_.store_path, "local store");
  server_opts(health_);
}

bool GapCli::parsed() const {
  return diagnose_->parsed() || identify_->parsed() || convert_->parsed() || import_->parsed() || track_->parsed() ||
         health_->parsed();
}

int GapCli::Run(const ClientFactory& make_client) {
  if (diagnose_->parsed()) return Diagnose(make_client);
  if (identify_->parsed()) return Identify();
  if (convert_->parsed()) return Convert();
  if (track_->parsed()) return Track();
  if (health_->parsed()) return Health(make_client);
  return Import(make_client);
}

std::string GapCli::ModelOut(const std::string& old, const char* old_flag) const {
  if (old.empty()) return model_out_;
  std::fprintf(stderr, "benchctl: note: %s FILE is now --model-out FILE\n", old_flag);
  return model_out_.empty() ? old : model_out_;
}

int GapCli::Diagnose(const ClientFactory& make_client) {
  DiagnoseOutput out;
  out.json_stdout = diagnose_->count("--json") > 0 || *shared_.json;
  out.json_out = json_out_;
  if (!json_path_.empty() && json_path_ != "-") {
    namespace fs = std::filesystem;
    std::error_code ec;
    if (dataset_dir_.empty() && runs_.empty() && fs::is_directory(json_path_, ec)) {
      dataset_dir_ = json_path_;  // `diagnose --json DIR`: the flag took the dataset as its value
    } else {  // the old spelling `--json FILE`: the file, and the report on stdout as before
      std::fprintf(stderr, "benchctl: note: `diagnose --json FILE` is now `--json-out FILE` (--json alone: JSON on "
                           "stdout, as everywhere)\n");
      out.json_stdout = *shared_.json;
      if (out.json_out.empty()) out.json_out = json_path_;
    }
  }
  out.model_out = ModelOut(emit_model_, "--emit-model");
  out.suggest_out = suggest_out_;
  if (!runs_.empty()) {
    if (!dataset_dir_.empty()) return Fail(Status::InvalidArgument("diagnose: give a dataset directory or --runs, not both"));
    if (!reference_dir_.empty()) return Fail(Status::InvalidArgument("--reference: works on dataset directories, not --runs"));
    auto backend = ChooseBackend(local_ ? "" : *shared_.server, *shared_.store_path, make_client);
    return StoredDiagnose(*backend, runs_, model_, out);
  }
  if (dataset_dir_.empty()) return Fail(Status::InvalidArgument("diagnose: give a dataset directory or --runs ID,..."));
  auto ds = Load(dataset_dir_);
  if (!ds.ok()) return Fail(ds.status());
  if (!add_runs_.empty()) {
    // Runs made since the session (e.g. the ones --suggest proposed), as holdout runs after its end: they test
    // each candidate's prediction where the candidates disagree (docs/gap.md, "The next experiment").
    auto backend = ChooseBackend(local_ ? "" : *shared_.server, *shared_.store_path, make_client);
    double t = 0.0;
    for (const auto& r : ds->runs)
      if (std::isfinite(r.t_start_s) && !r.t_s.empty()) t = std::max(t, r.t_start_s + r.t_s.back());
    for (std::int64_t id : add_runs_) {
      auto fetched = FetchStoredRun(*backend, id);
      if (!fetched.ok()) return Fail(fetched.status().WithContext("--add-runs"));
      auto one = gap::DatasetOfStoredRuns({std::move(*fetched)});
      if (!one.ok()) return Fail(one.status().WithContext("--add-runs"));
      gap::RunData r = std::move(one->runs.front());
      r.split = Split::kHoldout;
      r.t_start_s = t + 1.0;
      t = r.t_start_s + (r.t_s.empty() ? 0.0 : r.t_s.back());
      ds->runs.push_back(std::move(r));
    }
  }
  auto nominal = NominalFor(*ds, model_);
  if (!nominal.ok()) return Fail(nominal.status());
  gap::DiagnoseOptions options;
  options.model_name = !model_.empty() ? model_ : ds->model;
  gap::Dataset reference;
  if (!reference_dir_.empty()) {
    auto ref = Load(reference_dir_);
    if (!ref.ok()) return Fail(ref.status().WithContext("--reference"));
    reference = std::move(*ref);
    if (nominal->driver) reference.driver = *nominal->driver;
    // A moving valve's switch-on runs with no --reference-params: the reference is identified from scratch.
    const bool scratch = reference_params_.empty() && gap::IsSwitchOnSession(reference, nominal->plant);
    const auto names = !reference_params_.empty() ? reference_params_
                       : scratch                  ? std::vector<std::string>{}
                                                  : DefaultReferenceParams(reference, nominal->plant);
    auto fit = scratch ? StatusOr<gap::IdentifyOptions>(gap::IdentifyOptions{})
                       : IdentifyOptionsFrom(names, {}, gap::IdentifyOptions::Global::kAuto, "--reference-params");
    if (!fit.ok()) return Fail(fit.status());
    if (scratch) {
      fit->scratch_progress = [](const std::string& line) {
        std::fprintf(stderr, "benchctl: reference: %s\n", line.c_str());
      };
    }
    options.reference = &reference;
    options.reference_fit = *fit;
  }
  return DiagnoseAndReport(*ds, *nominal, dataset_dir_, out, options);
}

int GapCli::Identify() {
  auto ds = Load(dataset_dir_);
  if (!ds.ok()) return Fail(ds.status());
  auto nominal = NominalFor(*ds, model_);
  if (!nominal.ok()) return Fail(nominal.status());
  if (nominal->driver) ds->driver = *nominal->driver;
  if (global_ && no_global_) return Fail(Status::InvalidArgument("identify: --global and --no-global exclude each other"));
  if (params_.empty() && fixed_.empty() && gap::IsSwitchOnSession(*ds, nominal->plant)) {
    // A moving valve seen through its switch-on current: identified from scratch (docs/real-data.md, "Moving valves").
    gap::MovingIdentifyOptions mo;
    mo.progress = [](const std::string& line) { std::fprintf(stderr, "benchctl: identify: %s\n", line.c_str()); };
    std::fprintf(stderr, "benchctl: identifying a moving valve from scratch on %zu runs of %s (model family %s)\n",
                 ds->runs.size(), dataset_dir_.c_str(), ds->model.c_str());
    auto id = gap::IdentifyMovingValve(*ds, nominal->plant, mo);
    if (!id.ok()) return Fail(id.status());
    const std::string model_out = ModelOut(out_path_, "identify --out");
    if (!model_out.empty()) {
      auto spec = WithValues(nominal->spec, id->effects, id->values, ds->driver,
                             "identified from scratch by benchctl identify on " + dataset_dir_);
      if (auto st = WriteSpec(spec, model_out); !st.ok()) return Fail(st);
    }
    if (*shared_.json) {
      std::cout << gap::MovingIdentificationJson(*id) << "\n";
    } else {
      std::cout << gap::MovingIdentificationReport(*id);
      if (!model_out.empty()) std::cout << "identified model written to " << model_out << "\n";
    }
    return kExitOk;
  }
  auto options = IdentifyOptionsFrom(params_, fixed_,
                                     global_      ? gap::IdentifyOptions::Global::kOn
                                     : no_global_ ? gap::IdentifyOptions::Global::kOff
                                                  : gap::IdentifyOptions::Global::kAuto,
                                     "--params");
  if (!options.ok()) return Fail(options.status());
  if (isatty(STDERR_FILENO))
    std::fprintf(stderr, "benchctl: identifying %zu parameters on %zu runs of %s%s ...\n", options->params.size(),
               ds->runs.size(), dataset_dir_.c_str(), "");
  const std::string model_out = ModelOut(out_path_, "identify --out");
  auto id = gap::Identify(*ds, nominal->plant, *options);
  if (!id.ok()) return Fail(id.status());
  if (!model_out.empty()) {
    std::map<std::string, double> values = id->fit.params;
    for (const auto& [name, v] : id->fixed) values[name] = v;
    auto spec = WithValues(nominal->spec, id->candidate.effects, values, ds->driver,
                           "identified by benchctl identify on " + dataset_dir_);
    if (auto st = WriteSpec(spec, model_out); !st.ok()) return Fail(st);
  }
  if (*shared_.json) {
    std::cout << gap::IdentificationJson(*id) << "\n";
  } else {
    std::cout << gap::IdentificationReport(*id);
    if (!model_out.empty()) std::cout << "identified model written to " << model_out << "\n";
  }
  return kExitOk;
}

int GapCli::Convert() {
  if (!scope_channel_.empty()) {
    gap::ScopeCsvOptions so;
    so.current_channel = scope_channel_;
    so.time_column = scope_time_column_;
    so.shunt_ohm = convert_->count("--shunt-ohm") > 0 ? shunt_ohm_ : 0.0;
    so.probe_A_per_V = scope_probe_A_per_V_;
    so.gate_channel = scope_gate_channel_;
    so.gate_threshold_V = scope_gate_threshold_V_;
    so.trigger_s = scope_trigger_s_;
    so.supply_V = scope_supply_V_;
    so.supply_pressure_Pa = scope_pressure_Pa_;
    so.run_id = scope_run_id_;
    so.split = scope_split_;
    so.t_start_s = scope_t_start_s_;
    so.device = scope_device_;
    so.model = convert_->count("--model") > 0 ? convert_model_ : model::kDefaultPreset;
    so.noise_A = scope_noise_A_;
    so.averaged = convert_->count("--averaged") > 0 ? averaged_ : 0;
    so.lsb_A = scope_lsb_A_;
    auto run = gap::ConvertScopeCsv(csv_path_, out_dir_, so);
    if (!run.ok()) return Fail(run.status());
    if (*shared_.json) {
      nlohmann::ordered_json j = {{"directory", run->directory}, {"run", run->run_id}, {"file", run->file},
                                  {"samples", run->samples}, {"sample_period_s", run->sample_period_s},
                                  {"gate_on_s", run->gate_on_s}};
      j["offset_removed_A"] = run->cleaning.offset_A;
      j["spike_samples_masked"] = run->cleaning.spike_samples;
      j["spike_A"] = run->cleaning.spike_A;
      j["inverted"] = run->cleaning.inverted;
      std::cout << j.dump(2) << "\n";
    } else {
      std::printf("run %s: %zu samples every %.6g s, gate on at %.6g s, written to %s\n", run->run_id.c_str(),
                  run->samples, run->sample_period_s, run->gate_on_s, run->directory.c_str());
      if (!run->cleaning.note.empty()) std::printf("  %s\n", run->cleaning.note.c_str());
    }
    return kExitOk;
  }
  gap::ReadingsCsvOptions o;
  o.shunt_ohm = shunt_ohm_;
  o.amp_ref_ohm = amp_ref_ohm_;
  o.adc_lsb_V = adc_lsb_V_;
  o.averaged = averaged_;
  o.model = convert_model_;
  auto sessions = gap::ConvertReadingsCsv(csv_path_, out_dir_, o);
  if (!sessions.ok()) return Fail(sessions.status());
  if (*shared_.json) {
    nlohmann::ordered_json j = nlohmann::ordered_json::array();
    for (const auto& s : *sessions)
      j.push_back({{"directory", s.directory}, {"device", s.device}, {"supply_V", s.supply_V}, {"temp_C", s.temp_C},
                   {"stroke_m", s.stroke_m}, {"runs", s.runs}, {"readings", s.readings}});
    std::cout << j.dump(2) << "\n";
    return kExitOk;
  }
  std::printf("%-44s %-12s %8s %9s %5s %9s\n", "dataset", "device", "temp [C]", "stroke[mm]", "runs", "readings");
  for (const auto& s : *sessions)
    std::printf("%-44s %-12s %8.1f %9.2f %5d %9d\n", s.directory.c_str(), s.device.c_str(), s.temp_C, s.stroke_m * 1e3,
                s.runs, s.readings);
  std::printf("%zu sessions written to %s\n", sessions->size(), out_dir_.c_str());
  return kExitOk;
}

int GapCli::Import(const ClientFactory& make_client) {
  auto backend = ChooseBackend(local_ ? "" : *shared_.server, *shared_.store_path, make_client);
  return ImportDataset(*backend, dataset_dir_, *shared_.json);
}

StatusOr<gap::Tracking> GapCli::TrackValve(std::vector<gap::TrackSession>* sessions) {
  auto nominal = NominalFor(sessions->front().dataset, model_);
  if (!nominal.ok()) return nominal.status();
  for (auto& s : *sessions) {
    if (nominal->driver) s.dataset.driver = *nominal->driver;
    s.holds = gap::TakeHoldRuns(&s.dataset);  // measured beside the identification (gap/hold.h)
    if (!gap::IsSwitchOnSession(s.dataset, nominal->plant))
      return Status::InvalidArgument("track: " + s.name + " is not a switch-on session of a moving valve "
                                     "(waveform runs from rest with one gate step, a reluctance-law family)");
  }
  gap::TrackOptions o;
  if (!(track_arl0_ > 1.0) || !std::isfinite(track_arl0_))
    return Status::InvalidArgument("--arl0: the in-control run length must be a number of sessions above 1 (got " +
                                   std::to_string(track_arl0_) + ")");
  o.target_arl0_sessions = track_arl0_;
  if (track_reference_ < 2)
    return Status::InvalidArgument("--reference: at least 2 sessions form a reference (got " +
                                   std::to_string(track_reference_) + ")");
  o.min_reference = track_reference_;
  for (const auto& l : track_limits_) {
    auto v = gap::ParseFixed(l, "--limit");
    if (!v.ok()) return v.status();
    o.limits[v->first] = v->second;
  }
  o.progress = [](const std::string& line) { std::fprintf(stderr, "benchctl: track: %s\n", line.c_str()); };
  auto t = gap::TrackSessions(*sessions, nominal->plant, o);
  if (!t.ok()) return t.status();
  for (const auto& [name, value] : o.limits) {
    bool known = false;
    for (const auto& p : t->parameters) known = known || p.name == name;
    if (!known) std::fprintf(stderr, "benchctl: warning: --limit %s: no tracked parameter has that name\n", name.c_str());
  }
  return t;
}

// Exit 0: every session tracked and nothing flagged; 1: a parameter flagged (the valve changed); 2: bad input.
int GapCli::Track() {
  std::vector<gap::TrackSession> sessions;
  for (const auto& dir : track_dirs_) {
    auto ds = Load(dir);
    if (!ds.ok()) return Fail(ds.status().WithContext("track"));
    std::string name = std::filesystem::path(dir).lexically_normal().filename().string();
    if (name.empty()) name = std::filesystem::path(dir).lexically_normal().parent_path().filename().string();
    sessions.push_back({name, std::move(*ds), {}});
  }
  // Sessions named alike (night1/session, night2/session) are told apart by their parent directory.
  std::map<std::string, int> seen;
  for (const auto& s : sessions) ++seen[s.name];
  for (std::size_t i = 0; i < sessions.size(); ++i)
    if (seen[sessions[i].name] > 1) {
      const auto path = std::filesystem::path(track_dirs_[i]).lexically_normal();
      const auto dir = path.filename().empty() ? path.parent_path() : path;
      sessions[i].name = dir.parent_path().filename().string() + "/" + dir.filename().string();
    }
  auto t = TrackValve(&sessions);
  if (!t.ok()) return Fail(t.status());
  if (*shared_.json) std::cout << gap::TrackingJson(*t) << "\n";
  else std::cout << gap::TrackingReport(*t);
  return t->flags.empty() ? kExitOk : kExitRunFailed;
}

// Each bench's nightly health checks (server/health_check.h: runs tagged "health:<bench>" and "night:<date>"),
// one session per night in date order, tracked as `track` tracks directories. Exit 0: nothing flagged on any
// bench; 1: a parameter flagged; 2: bad input or no checks stored.
int GapCli::Health(const ClientFactory& make_client) {
  auto backend = ChooseBackend(local_ ? "" : *shared_.server, *shared_.store_path, make_client);
  // The tracking the service's nights kept (GetBenchHealth): each night identified once, by the server. Without
  // it (no nights with checks stored, --local, --recompute), the stored checks are identified here.
  // --limit, --arl0 and --model change the tracking: the checks are then identified here with them.
  const bool options_given = !track_limits_.empty() || track_arl0_ != gap::TrackOptions{}.target_arl0_sessions ||
                             !model_.empty();
  if (!health_recompute_ && !options_given) {
    auto served = backend->BenchHealth(health_bench_);
    if (served.ok() && served->benches_size() > 0) {
      Json out = {{"source", "the server's nights"}, {"benches", Json::array()}, {"flags", Json::array()}};
      bool flagged = false;
      for (const auto& b : served->benches()) {
        Json entry = {{"bench", b.bench()}, {"nights", b.nights_size()}};
        if (b.tracking_json().empty()) {
          std::string why;
          for (const auto& n : b.notes()) why += (why.empty() ? "" : "; ") + n;
          entry["error"] = why;
          if (!*shared_.json) std::cout << "== bench " << b.bench() << ": " << why << "\n";
          out["benches"].push_back(std::move(entry));
          continue;
        }
        const Json one = Json::parse(b.tracking_json());
        for (auto& [k, v] : one.items()) entry[k] = v;
        for (const auto& f : one["flags"]) {
          Json g = {{"bench", b.bench()}};
          for (auto& [k, v] : f.items()) g[k] = v;
          out["flags"].push_back(g);
          flagged = true;
        }
        out["benches"].push_back(std::move(entry));
        if (!*shared_.json)
          std::cout << "== bench " << b.bench() << " (" << b.nights_size() << " nights, as the server's nights tracked "
                    << "them) ==\n" << b.report() << "\n";
      }
      if (*shared_.json) std::cout << out.dump(2) << "\n";
      return flagged ? kExitRunFailed : kExitOk;
    }
    if (!served.ok() && served.status().code() != StatusCode::kNotFound) return Fail(served.status().WithContext("health"));
    std::fprintf(stderr, "benchctl: health: no tracking kept by the nights at %s; identifying the stored checks here\n",
                 backend->Where().c_str());
  }
  RunFilter filter;
  filter.status = RunStatus::kDone;
  filter.tag = health_bench_.empty() ? "health" : "health:" + health_bench_;
  filter.limit = 1000;
  bool more = false;
  auto listed = backend->ListRuns(filter, &more);
  if (!listed.ok()) return Fail(listed.status().WithContext("health"));
  if (listed->empty())
    return Fail(Status::NotFound("health: no health checks stored " +
                                 (health_bench_.empty() ? std::string("for any bench") : "for bench " + health_bench_) +
                                 " at " + backend->Where() + " (a bench's \"health\" block in the server config)"));
  if (more)
    std::fprintf(stderr, "benchctl: health: more than %d checks stored; the newest %d are tracked\n", filter.limit,
                 filter.limit);
  // bench -> night (date) -> run ids.
  std::map<std::string, std::map<std::string, std::vector<std::int64_t>>> nights;
  for (const auto& r : *listed) {
    std::string date;
    for (const auto& t : r.tags)
      if (t.rfind("night:", 0) == 0) date = t.substr(6);
    if (date.empty() || r.bench.empty()) continue;
    nights[r.bench][date].push_back(r.id);
  }
  Json out = {{"source", "identified here"}, {"benches", Json::array()}, {"flags", Json::array()}};
  bool flagged = false;
  for (auto& [bench, by_night] : nights) {
    if (by_night.size() < 2) {
      std::fprintf(stderr, "benchctl: health: %s: %zu night stored; tracking needs two\n", bench.c_str(),
                   by_night.size());
      out["benches"].push_back({{"bench", bench}, {"nights", by_night.size()}, {"error", "tracking needs two nights"}});
      continue;
    }
    std::vector<gap::TrackSession> sessions;
    for (auto& [date, ids] : by_night) {
      std::sort(ids.begin(), ids.end());
      std::vector<gap::StoredRun> stored;
      for (std::int64_t id : ids) {
        auto one = FetchStoredRun(*backend, id);
        if (!one.ok()) return Fail(one.status().WithContext("health " + bench));
        stored.push_back(std::move(*one));
      }
      auto ds = gap::DatasetOfStoredRuns(std::move(stored));
      if (!ds.ok()) return Fail(ds.status().WithContext("health " + bench + " night " + date));
      sessions.push_back({date, std::move(*ds), {}});
    }
    std::fprintf(stderr, "benchctl: health: %s: %zu nights, %s to %s\n", bench.c_str(), sessions.size(),
                 sessions.front().name.c_str(), sessions.back().name.c_str());
    auto t = TrackValve(&sessions);
    if (!t.ok()) return Fail(t.status().WithContext("health " + bench));
    flagged = flagged || !t->flags.empty();
    if (*shared_.json) {
      Json one = Json::parse(gap::TrackingJson(*t));
      Json entry = {{"bench", bench}, {"nights", sessions.size()}};
      for (auto& [k, v] : one.items()) entry[k] = v;
      for (const auto& f : one["flags"]) {
        Json g = {{"bench", bench}};
        for (auto& [k, v] : f.items()) g[k] = v;
        out["flags"].push_back(g);
      }
      out["benches"].push_back(std::move(entry));
    } else {
      std::cout << "== bench " << bench << " (" << sessions.size() << " nights) ==\n" << gap::TrackingReport(*t) << "\n";
    }
  }
  if (*shared_.json) std::cout << out.dump(2) << "\n";
  return flagged ? kExitRunFailed : kExitOk;
}

}  // namespace vb::benchctl
