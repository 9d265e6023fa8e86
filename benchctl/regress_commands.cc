// benchctl baseline / regress / nights (docs/regress.md).
#include "benchctl/regress_commands.h"

#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "benchctl/backend.h"
#include "benchctl/cli_common.h"
#include "proto/api_convert.h"
#include "experiment/spec.h"
#include "gap/text_wrap.h"
#include "regress/compare.h"
#include "regress/suite.h"

namespace vb::benchctl {
namespace {

namespace v1 = valvebench::v1;
using regress::Json;


std::string Where(const std::string& server) { return server.empty() ? "local" : "server " + server; }

// What regress compares, from the runs of a batch wherever they are stored.
std::vector<regress::RunMetrics> ToRunMetrics(const std::vector<RunView>& runs) {
  std::vector<regress::RunMetrics> out;
  for (const auto& r : runs) {
    regress::RunMetrics m;
    m.run_id = r.id;
    m.name = r.key.DisplayName();
    m.case_name = r.key.CaseName();
    m.ok = r.ok();
    m.reason = m.ok ? "" : RunStatusName(r.status) + (r.reason.empty() ? std::string() : ": " + r.reason);
    m.metrics = r.metrics;
    out.push_back(std::move(m));
  }
  return out;
}

struct SuiteOutcome {
  std::int64_t batch_id = 0;
  std::vector<regress::RunMetrics> runs;
};

// Runs the expanded suite as one batch on the backend, waits for every run, and reads the runs back.
StatusOr<SuiteOutcome> RunSuite(const regress::LoadedSuite& suite, std::uint64_t seed, Backend& backend) {
  auto runs = regress::ExpandSuite(suite.suite, seed);
  if (!runs.ok()) return runs.status();
  std::vector<v1::ExperimentSpec> specs;
  std::vector<RunKey> keys;
  for (auto& r : *runs) {
    if (!backend.serves_hardware() && regress::BenchClassOf(r.spec).rfind("emulated", 0) != 0)
      return Status::FailedPrecondition("experiments[" + std::to_string(r.entry) + "].bench_class: '" +
                                        regress::BenchClassOf(r.spec) + "' needs a server (--server ADDR)");
    specs.push_back(r.spec);
    keys.push_back(r.key);
  }
  std::string suite_json;
  google::protobuf::util::JsonPrintOptions o;
  o.preserve_proto_field_names = true;
  (void)google::protobuf::util::MessageToJsonString(suite.suite, &suite_json, o);
  auto batch = backend.RunBatch(specs, keys, suite.suite.name(), suite_json);
  if (!batch.ok()) return batch.status().WithContext(suite.path.empty() ? suite.suite.name() : suite.path);
  SuiteOutcome out;
  out.batch_id = *batch;
  auto stored = backend.Runs(*batch, {});
  if (!stored.ok()) return stored.status();
  out.runs = ToRunMetrics(*stored);
  return out;
}

bool LooksLikeFile(const std::string& arg) {
  return arg.find('/') != std::string::npos || (arg.size() > 5 && arg.compare(arg.size() - 5, 5, ".json") == 0);
}

// --baseline NAME|FILE: a baseline file wherever the suite runs (CI keeps its baseline in the repository), or
// a name in the store of the service that runs the suite (the server's with --server, else the local store).
StatusOr<regress::Baseline> LoadBaselineArg(const std::string& arg, int version, Backend& backend) {
  if (LooksLikeFile(arg)) {
    std::ifstream in(arg);
    if (!in) return Status::NotFound("--baseline: cannot open the baseline file '" + arg + "'");
    Json j;
    try {
      j = Json::parse(in);
    } catch (const Json::exception& e) {
      return Status::InvalidArgument("--baseline " + arg + ": not JSON: " + e.what());
    }
    auto b = regress::BaselineFromJson(j);
    if (!b.ok()) return b.status().WithContext("--baseline " + arg);
    return b;
  }
  auto rec = backend.GetBaseline(arg, version);
  if (!rec.ok()) {
    if (rec.status().code() == StatusCode::kNotFound)
      return Status::NotFound("--baseline: " + rec.status().message() + " (create it: benchctl baseline set " + arg +
                              " --suite SUITE, or --batch B)");
    return rec.status();
  }
  return rec;
}

std::string Time(double unix_s) {
  const std::time_t t = static_cast<std::time_t>(unix_s);
  std::tm tm{};
  localtime_r(&t, &tm);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%d %H:%M:%S", &tm);
  return buf;
}

Status WriteFile(const std::string& path, const std::string& text) {
  std::ofstream out(path);
  out << text;
  out.close();
  if (!out) return Status::Unavailable(path + ": cannot write");
  return Status::Ok();
}

}  // namespace

RegressCli::RegressCli(CLI::App* app, SharedOptions shared) : shared_(shared) {
  auto common = [this](CLI::App* sub, bool with_db = true) {
    sub->add_flag("--json", *shared_.json, "machine-readable output on stdout");
    AddServerOptions(sub, shared_);
    if (with_db)
      sub->add_option("--db", *shared_.store_path,
                      "local store holding baselines and regression results (without --server)");
  };
  baseline_ = app->add_subcommand("baseline", "named, versioned metric baselines for regress");
  baseline_->require_subcommand(1);
  baseline_set_ = baseline_->add_subcommand("set", "store a baseline (a new version if NAME exists)");
  baseline_set_->add_option("name", name_, "baseline name")->required();
  baseline_set_->add_option("--batch", batch_, "from the runs of this batch (local store, or --server's)");
  baseline_set_->add_option("--suite", suite_path_, "run this suite now and take its values");
  baseline_set_->add_option("--seed", seed_, "with --suite: jitter seed (default: the suite's)");
  baseline_set_->add_option("--note", note_, "stored with the baseline");
  baseline_set_->add_flag("--local", local_, "batch/suite on the embedded emulator and local store");
  common(baseline_set_);
  baseline_list_ = baseline_->add_subcommand("list", "every baseline and version (the server's, or the local store's)");
  baseline_list_->add_flag("--local", local_, "the local store's, even if a server is configured");
  common(baseline_list_);
  baseline_show_ = baseline_->add_subcommand("show", "one baseline's values (--json: the baseline file format)");
  baseline_show_->add_option("name", name_, "baseline name")->required();
  baseline_show_->add_option("--version", version_, "an older version (default: the newest)");
  baseline_show_->add_flag("--local", local_, "the local store's, even if a server is configured");
  common(baseline_show_);

  regress_ = app->add_subcommand("regress", "run a suite and compare it with a baseline (exit 1 on a regression)");
  regress_->add_option("suite", suite_path_, "suite file (protobuf JSON, proto/valvebench/v1/suite.proto)")
      ->required();
  regress_->add_option("--baseline", baseline_arg_,
                       "baseline JSON file, or a name in the store the suite runs on (the server's with --server)")
      ->required();
  regress_->add_option("--baseline-version", version_, "compare with this version (default: the newest)");
  regress_->add_flag("--local", local_, "run on the embedded emulator");
  regress_->add_option("--junit", junit_path_, "write JUnit XML here");
  regress_->add_option("--seed", seed_, "jitter seed (default: the suite's seed)");
  common(regress_);

  nights_ = app->add_subcommand("nights", "the server's scheduled regression nights, newest first (exit 1 if the "
                                          "latest did not pass)");
  nights_->add_option("--limit", limit_, "how many nights (1-1000, default 10)");
  nights_->add_option("--junit", junit_path_,
                      "write the nights as JUnit XML here (a testcase per night; a regressed night's failure "
                      "message starts with its cause)");
  common(nights_, /*with_db=*/false);  // nights are the server's: its scheduler runs them into its own store
}

bool RegressCli::parsed() const { return baseline_->parsed() || regress_->parsed() || nights_->parsed(); }

int RegressCli::Run(const ClientFactory& make_client) {
  const bool json = *shared_.json;
  const std::string server = local_ ? "" : *shared_.server;
  const std::string& store_path = *shared_.store_path;

  if (baseline_set_->parsed()) {
    if ((batch_ != 0) == !suite_path_.empty())
      return Fail(Status::InvalidArgument("baseline set: give exactly one of --batch B and --suite SUITE"));
    // The baseline is kept by the service that has its runs: the server's store with --server, else the
    // local one (docs/regress.md, "Where baselines live").
    auto backend = ChooseBackend(server, store_path, make_client,
                                 {/*execute=*/!suite_path_.empty(), /*keep_traces=*/false});
    if (auto st = backend->RecordsKept(); !st.ok()) return Fail(st);
    std::vector<regress::RunMetrics> runs;
    std::string source;
    if (!suite_path_.empty()) {
      auto suite = regress::LoadSuite(suite_path_);
      if (!suite.ok()) return Fail(suite.status());
      const std::uint64_t seed = seed_ != 0 ? seed_ : (suite->suite.seed() != 0 ? suite->suite.seed() : 1);
      auto out = RunSuite(*suite, seed, *backend);
      if (!out.ok()) return Fail(out.status());
      runs = std::move(out->runs);
      source = "suite " + suite->suite.name() + " (" + Where(server) + " batch " + std::to_string(out->batch_id) +
               ", seed " + std::to_string(seed) + ")";
    } else {
      auto r = backend->Runs(batch_, {});
      if (!r.ok()) return Fail(r.status().WithContext("--batch"));
      runs = ToRunMetrics(*r);
      source = Where(server) + " batch " + std::to_string(batch_);
    }
    const regress::Measured m = regress::Summarise(runs);
    if (!m.failures.empty()) {
      std::string list;
      for (const auto& [c, f] : m.failures) list += "\n  " + f.front();
      return Fail(Status::FailedPrecondition("baseline set: runs did not succeed; a baseline must come from good "
                                             "runs:" + list));
    }
    regress::Baseline wanted;
    wanted.name = name_;
    wanted.source = source;
    wanted.note = note_;
    wanted.cases = m.stats;
    auto rec = backend->SaveBaseline(wanted);
    if (!rec.ok()) return Fail(rec.status());
    const int v = rec->version;
    std::size_t values = 0;
    for (const auto& [c, metrics] : rec->cases) values += metrics.size();
    if (json) {
      std::cout << regress::BaselineToJson(*rec).dump(2) << "\n";
    } else {
      std::printf("baseline %s version %d stored in %s (%zu values from %s)%s\n", name_.c_str(), v,
                  backend->Where().c_str(), values, source.c_str(),
                  v > 1 ? ("; versions 1-" + std::to_string(v - 1) + " are kept (baseline show " + name_ +
                           " --version N)").c_str()
                        : "");
    }
    return kExitOk;
  }

  if (baseline_list_->parsed()) {
    auto backend = ChooseBackend(server, store_path, make_client);
    auto list = backend->ListBaselines();
    if (!list.ok()) return Fail(list.status());
    if (json) {
      Json a = Json::array();
      for (const auto& b : *list)
        a.push_back({{"name", b.name}, {"version", b.version}, {"created_unix_s", b.created_unix_s},
                     {"source", b.source}, {"note", b.note}});
      std::cout << a.dump(2) << "\n";
    } else {
      if (list->empty()) std::printf("no baselines in %s\n", backend->Where().c_str());
      for (const auto& b : *list)
        std::printf("%-20s v%-3d %s  %s%s%s\n", b.name.c_str(), b.version, Time(b.created_unix_s).c_str(),
                    b.source.c_str(), b.note.empty() ? "" : "  -- ", b.note.c_str());
    }
    return kExitOk;
  }

  if (baseline_show_->parsed()) {
    auto backend = ChooseBackend(server, store_path, make_client);
    auto rec = backend->GetBaseline(name_, version_);
    if (!rec.ok()) return Fail(rec.status());
    const regress::Baseline& b = *rec;
    if (json) {
      std::cout << regress::BaselineToJson(b).dump(2) << "\n";
      return kExitOk;
    }
    std::printf("baseline %s version %d, %s, from %s%s%s\n", b.name.c_str(), b.version, Time(b.created_unix_s).c_str(),
                b.source.c_str(), b.note.empty() ? "" : "; ", b.note.c_str());
    for (const auto& [c, metrics] : b.cases)
      for (const auto& [name, s] : metrics)
        std::printf("  %-40s %-18s %-12.6g +/- %-10.3g n=%d\n", c.c_str(), name.c_str(), s.mean, s.spread, s.n);
    return kExitOk;
  }

  if (regress_->parsed()) {
    if (version_ < 0) return Fail(Status::InvalidArgument("--baseline-version: must be >= 1"));
    auto suite = regress::LoadSuite(suite_path_);
    if (!suite.ok()) return Fail(suite.status());
    // One service for the whole command: it runs the suite, holds a named baseline and keeps the result.
    auto backend = ChooseBackend(server, store_path, make_client, {/*execute=*/true, /*keep_traces=*/false});
    auto baseline = LoadBaselineArg(baseline_arg_, version_, *backend);
    if (!baseline.ok()) return Fail(baseline.status());
    const std::uint64_t seed = seed_ != 0 ? seed_ : (suite->suite.seed() != 0 ? suite->suite.seed() : 1);
    if (!json)
      std::fprintf(stderr, "regress: suite %s (%d entries) on %s vs baseline %s v%d, seed %llu\n",
                   suite->suite.name().c_str(), suite->suite.experiments_size(), Where(server).c_str(),
                   baseline->name.c_str(), baseline->version, static_cast<unsigned long long>(seed));
    auto out = RunSuite(*suite, seed, *backend);
    if (!out.ok()) return Fail(out.status());
    regress::RegressResult r = regress::Compare(suite->suite, *baseline, regress::Summarise(out->runs));
    r.batch_id = out->batch_id;
    r.where = server.empty() ? "local" : server;
    r.seed = seed;
    if (backend->RecordsKept().ok()) {  // --no-store keeps nothing, the result included
      // Beside its batch, in the same store (the server's history with --server).
      auto id = backend->SaveRegression(r);
      if (id.ok()) r.id = *id;
      else std::fprintf(stderr, "benchctl: warning: the result was not stored: %s\n", id.status().message().c_str());
    }
    if (!junit_path_.empty()) {
      auto st = WriteFile(junit_path_, regress::JUnitXml(r));
      if (!st.ok()) return Fail(st);
    }
    if (json) {
      std::cout << regress::ResultToJson(r).dump(2) << "\n";
    } else {
      std::cout << regress::ResultTable(r);
      if (r.id != 0)
        std::printf("regression %lld stored in %s (benchctl report --regress %lld%s --html FILE)\n",
                    static_cast<long long>(r.id), backend->Where().c_str(), static_cast<long long>(r.id),
                    server.empty() ? "" : (" --server " + server).c_str());
    }
    return r.regressed() ? kExitRunFailed : kExitOk;
  }

  if (nights_->parsed()) {
    if (limit_ < 1 || limit_ > 1000) return Fail(Status::InvalidArgument("--limit: must be 1-1000"));
    if (server.empty())
      return Fail(Status::InvalidArgument("nights: the nights run on a server and are stored there; give it with "
                                          "--server ADDR or VALVEBENCH_SERVER (local regressions: benchctl report "
                                          "--regress ID)"));
    auto c = make_client();
    auto resp = c->ListNights(limit_);
    if (!resp.ok()) return Fail(resp.status());
    if (!junit_path_.empty()) {
      std::vector<regress::NightOutcome> outcomes;
      for (const auto& n : resp->nights()) {
        regress::NightOutcome o;
        o.date = n.date(), o.verdict = n.verdict(), o.suite = n.suite(), o.baseline = n.baseline();
        o.summary = n.summary(), o.cause = n.cause(), o.cause_reason = n.cause_reason(), o.batch_id = n.batch_id();
        o.regressed_cases.assign(n.regressed_cases().begin(), n.regressed_cases().end());
        o.valve_changes.assign(n.valve_changes().begin(), n.valve_changes().end());
        outcomes.push_back(std::move(o));
      }
      if (auto st = WriteFile(junit_path_, regress::NightsJUnitXml(outcomes)); !st.ok()) return Fail(st);
    }
    if (json) {
      Json a = Json::array();
      for (const auto& n : resp->nights())
        a.push_back({{"date", n.date()},
                     {"verdict", n.verdict()},
                     {"batch_id", n.batch_id()},
                     {"regression_id", n.regression_id()},
                     {"suite", n.suite()},
                     {"baseline", n.baseline()},
                     {"regressed", n.regressed_count()},
                     {"unchanged", n.unchanged()},
                     {"improved", n.improved()},
                     {"started_unix_s", n.started_unix_s()},
                     {"finished_unix_s", n.finished_unix_s()},
                     {"summary", n.summary()},
                     {"regressed_cases", n.regressed_cases()},
                     {"valve_changes", n.valve_changes()},
                     {"cause", n.cause()},
                     {"cause_reason", n.cause_reason()}});
      std::cout << a.dump(2) << "\n";
    } else {
      if (resp->nights_size() == 0) std::printf("no nights yet on %s\n", server.c_str());
      for (const auto& n : resp->nights()) {
        char head[256];
        std::snprintf(head, sizeof head, "%s  %-9s  batch %-5lld %s vs %s  ", n.date().c_str(), n.verdict().c_str(),
                      static_cast<long long>(n.batch_id()), n.suite().c_str(), n.baseline().c_str());
        std::cout << gap::Hanging(head, n.summary());
        // Under the night, within 120 columns: the bench twin's lines (docs/track.md "On the server").
        for (const auto& v : n.valve_changes()) std::cout << gap::Hanging("            valve changed: ", v);
        if (!n.cause().empty())
          std::cout << gap::Hanging("            cause: " + n.cause() + ": ", n.cause_reason());
      }
    }
    // The newest night decides: a script can gate on "did last night pass" (no nights yet is not a failure).
    if (resp->nights_size() > 0 && resp->nights(0).verdict() != "passed") return kExitRunFailed;
    return kExitOk;
  }

  return kExitBadInput;
}

}  // namespace vb::benchctl
