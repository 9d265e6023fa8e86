// benchctl as a user or a CI script drives a real server: exit codes, data on stdout, errors naming the field.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <filesystem>

#include <array>
#include <cstdio>
#include <fstream>
#include <memory>
#include <chrono>
#include <set>
#include <thread>
#include <vector>

#include "../common/run_command.h"
#include "client/client.h"
#include "server_process.h"

namespace vb {
namespace {

using Result = testing::CommandResult;

Result Benchctl(const std::string& args) { return testing::RunCommand(std::string(VB_BENCHCTL) + " " + args); }

std::string Example(const std::string& rel) { return std::string(VB_SOURCE_DIR) + "/examples/" + rel; }

TEST(BenchctlRemote, RunWaitQueueShowExportCompareBenches) {
  const std::string dir = ::testing::TempDir() + "/vb-cli-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  testing::ServerProcess server(dir);
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  const std::string op = "--server " + addr + " --token " + testing::kOperatorToken;

  Result run = Benchctl("run " + Example("compare-current-controllers.json") + " --wait --metrics rmse,driver_loss_W " + op);
  ASSERT_EQ(run.exit_code, 0) << run.out;
  EXPECT_NE(run.out.find("compare-current-controllers/pi: done\n"), std::string::npos) << "one line per run: " << run.out;
  EXPECT_NE(run.out.find("rank by RMSE"), std::string::npos) << "a batch ends with the comparison";
  EXPECT_NE(run.out.find("driver loss [mW]"), std::string::npos) << "--metrics reaches a server's comparison";
  EXPECT_EQ(run.out.find("sw rate"), std::string::npos) << run.out;
  Result wide = Benchctl("compare --batch 1 --wide " + op);
  ASSERT_EQ(wide.exit_code, 0) << wide.out;
  EXPECT_NE(wide.out.find("energy"), std::string::npos) << "--wide: every metric the server has: " << wide.out;

  Result submitted = Benchctl("run " + Example("standard/e3.json") + " --json " + op);
  ASSERT_EQ(submitted.exit_code, 0) << submitted.out;
  // {"batch_id": 2, "run_ids": [5]}: numbers, as benchctl import writes them (not protobuf JSON's strings).
  const auto sub = nlohmann::json::parse(submitted.out, nullptr, false);
  ASSERT_TRUE(sub.is_object() && sub["run_ids"].is_array() && sub["run_ids"][0].is_number_integer()) << submitted.out;
  const std::string id = std::to_string(sub["run_ids"][0].get<std::int64_t>());
  Result watch = Benchctl("watch " + id + " " + op);
  EXPECT_EQ(watch.exit_code, 0) << watch.out;

  Result show = Benchctl("show " + id + " --json " + op);
  ASSERT_EQ(show.exit_code, 0) << show.out;
  const auto shown = nlohmann::ordered_json::parse(show.out, nullptr, false);
  ASSERT_TRUE(shown.is_object()) << show.out;
  EXPECT_EQ(shown["status"], "done") << show.out;  // the one status vocabulary, as locally
  EXPECT_EQ(std::to_string(shown["id"].get<std::int64_t>()), id);
  // Metrics in one order on every call and in every output (a protobuf map has none).
  Result again = Benchctl("show " + id + " --json " + op);
  const auto shown_again = nlohmann::ordered_json::parse(again.out, nullptr, false);
  ASSERT_TRUE(shown_again.is_object()) << again.out;
  EXPECT_EQ(shown["metrics"].dump(), shown_again["metrics"].dump());
  std::vector<std::string> order;
  for (const auto& [k, v] : shown["metrics"].items()) order.push_back(k);
  ASSERT_GE(order.size(), 2u);
  EXPECT_EQ(order[0], "effort_l2") << show.out;  // experiment::MetricList's order, not alphabetical

  const std::string csv = dir + "/trace.csv";
  Result exp = Benchctl("export " + id + " --trace-csv " + csv + " " + op);
  ASSERT_EQ(exp.exit_code, 0) << exp.out;
  std::ifstream in(csv);
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header.rfind("t_s,gate,v_coil_V,i_A,x_m", 0), 0u) << header;
  size_t lines = 0;
  for (std::string line; std::getline(in, line);) ++lines;
  EXPECT_EQ(lines, 5001u);

  Result queue = Benchctl("queue --status done --csv " + op);
  ASSERT_EQ(queue.exit_code, 0) << queue.out;
  EXPECT_NE(queue.out.find("id,batch_id,name,controller,status"), std::string::npos) << queue.out;
  Result idle = Benchctl("queue " + op);
  ASSERT_EQ(idle.exit_code, 0) << idle.out;
  EXPECT_NE(idle.out.find("no runs queued or running on server " + addr), std::string::npos) << idle.out;

  // cancel reports the state the run reached, not "running 0 %".
  const std::string long_spec = dir + "/long.json";
  std::ofstream(long_spec) << R"({"name": "long", "duration_s": 20, "realtime": true, "recording": {"rate_Hz": 1000},
      "reference": {"on_off_profile": {"switching_value": 0.9, "switching_time_s": 0.006, "holding_value": 0.5}},
      "controller": {"pi_current": {}}})";
  Result long_run = Benchctl("run " + long_spec + " --json " + op);
  ASSERT_EQ(long_run.exit_code, 0) << long_run.out;
  const std::string long_id =
      std::to_string(nlohmann::json::parse(long_run.out)["run_ids"][0].get<std::int64_t>());
  for (int k = 0; k < 50; ++k) {  // until it runs
    Result s = Benchctl("show " + long_id + " --json " + op);
    if (s.out.find("\"status\": \"running\"") != std::string::npos) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  }
  Result cancelled = Benchctl("cancel " + long_id + " " + op);
  ASSERT_EQ(cancelled.exit_code, 0) << cancelled.out;
  EXPECT_NE(cancelled.out.find("): cancelled"), std::string::npos) << cancelled.out;

  Result cmp = Benchctl("compare --batch 1 --csv " + op);
  ASSERT_EQ(cmp.exit_code, 0) << cmp.out;
  EXPECT_NE(cmp.out.find("fuzzy_current"), std::string::npos) << cmp.out;
  // The one comparison renderer, whichever backend: the same JSON shape as `compare --local --batch --json`.
  Result cmp_json = Benchctl("compare --batch 1 --json " + op);
  ASSERT_EQ(cmp_json.exit_code, 0) << cmp_json.out;
  const auto j = nlohmann::json::parse(cmp_json.out, nullptr, false);
  ASSERT_TRUE(j.is_object()) << cmp_json.out;
  EXPECT_EQ(j["columns"][0], "rmse");
  ASSERT_EQ(j["rows"].size(), 4u);
  EXPECT_EQ(j["rows"][0]["failed"], 0);  // written out, not left to proto3's "default means absent"
  EXPECT_TRUE(j["rows"][0]["metrics"]["rmse"].contains("spread")) << cmp_json.out;

  Result benches = Benchctl("benches " + op);
  ASSERT_EQ(benches.exit_code, 0) << benches.out;
  EXPECT_NE(benches.out.find("emu-a"), std::string::npos);

  // Refusals exit 2 and say why; an unreachable server exits 3.
  Result bad_token = Benchctl("benches --server " + addr + " --token nope");
  EXPECT_EQ(bad_token.exit_code, 2) << bad_token.out;
  EXPECT_NE(bad_token.out.find("VALVEBENCH_TOKEN"), std::string::npos) << bad_token.out;
  Result no_token = testing::RunCommand("env -u VALVEBENCH_TOKEN " + std::string(VB_BENCHCTL) + " benches --server " + addr);
  EXPECT_EQ(no_token.exit_code, 2) << no_token.out;
  EXPECT_NE(no_token.out.find("no token given"), std::string::npos) << no_token.out;
  EXPECT_NE(no_token.out.find("VALVEBENCH_TOKEN"), std::string::npos) << no_token.out;
  EXPECT_NE(no_token.out.find("--token"), std::string::npos) << no_token.out;
  const std::string bad_spec = dir + "/bad.json";
  std::ofstream(bad_spec) << R"({"duration_s": 0.1, "recording": {"rate_Hz": -1},
      "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 50, "duty": 0.5}]}}})";
  Result bad = Benchctl("run " + bad_spec + " " + op);
  EXPECT_EQ(bad.exit_code, 2) << bad.out;
  EXPECT_NE(bad.out.find("recording.rate_Hz"), std::string::npos) << bad.out;
  Result missing = Benchctl("show 99999 " + op);
  EXPECT_EQ(missing.exit_code, 2) << missing.out;
  server.Kill(SIGTERM);
  Result gone = Benchctl("benches " + op);
  EXPECT_EQ(gone.exit_code, 3) << gone.out;
  EXPECT_NE(gone.out.find("cannot reach valvebench-server at " + addr), std::string::npos) << gone.out;
  EXPECT_NE(gone.out.find("VALVEBENCH_SERVER"), std::string::npos) << gone.out;
  EXPECT_EQ(gone.out.find('\n'), gone.out.size() - 1) << "one line: " << gone.out;
}

// One spec, run locally and on the server, goes through the same admission: the same runs, with the same
// identities (typed sweep point and repeat) and the same controller.
TEST(BenchctlRemote, LocalAndServerRunsOfASpecHaveTheSameIdentities) {
  const std::string dir = ::testing::TempDir() + "/vb-cli-same-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  testing::ServerProcess server(dir + "/server");
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  const std::string op = "--server " + addr + " --token " + testing::kOperatorToken;
  const std::string spec = dir + "/swept.json";
  std::ofstream(spec) << R"({"name": "swept", "duration_s": 0.02, "repeats": 2,
      "sweep": [{"field": "conditions.supply_V", "values": [12, 15]}],
      "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 500, "duty": 0.5}]}}})";
  Result local = testing::RunCommand("VALVEBENCH_DB=" + dir + "/local.db " + std::string(VB_BENCHCTL) + " run --local " +
                                     spec + " --json");
  ASSERT_EQ(local.exit_code, 0) << local.out;
  Result remote = Benchctl("run " + spec + " --wait --json " + op);
  ASSERT_EQ(remote.exit_code, 0) << remote.out;
  const auto l = nlohmann::json::parse(local.out, nullptr, false);
  const auto r = nlohmann::json::parse(remote.out, nullptr, false);
  ASSERT_TRUE(l.is_array() && r.is_array()) << local.out << remote.out;
  ASSERT_EQ(l.size(), 4u);
  ASSERT_EQ(r.size(), 4u);
  std::multiset<std::string> local_runs, remote_runs;
  for (const auto& x : l) local_runs.insert(x["name"].get<std::string>() + " | " + x["controller"].get<std::string>());
  for (const auto& x : r) remote_runs.insert(x["name"].get<std::string>() + " | " + x["controller"].get<std::string>());
  EXPECT_EQ(local_runs, remote_runs);
  EXPECT_EQ(local_runs.count("swept sweep:conditions.supply_V=15 repeat:1 | open_loop_pwm"), 1u);
  for (const auto& x : r) {
    ASSERT_TRUE(x.contains("key")) << x.dump();
    EXPECT_EQ(x["key"]["sweep"][0]["field"], "conditions.supply_V");
  }
  // One JSON shape for a run from either side: the same fields, the executed run's "summary" included (it is
  // stored with the run, issue 40, not kept in the process that ran it), numeric ids, the same status words.
  std::set<std::string> local_fields, remote_fields;
  for (const auto& [k, v] : l[0].items()) local_fields.insert(k);
  for (const auto& [k, v] : r[0].items()) remote_fields.insert(k);
  EXPECT_EQ(local_fields, remote_fields);
  EXPECT_TRUE(r[0].contains("summary")) << r[0].dump();
  EXPECT_EQ(l[0]["summary"]["samples"], r[0]["summary"]["samples"]);
  EXPECT_TRUE(l[0]["id"].is_number_integer() && r[0]["id"].is_number_integer());
  EXPECT_EQ(l[0]["status"], r[0]["status"]);
}

// A measured dataset stored on the server and diagnosed from there: the same verdict as from the directory,
// the holdout split kept, the stored current equal to the CSV's.
TEST(BenchctlRemote, ImportThenDiagnoseStoredRuns) {
  const std::string p07 = std::string(VB_SHARED_DIR) + "/gapbench/practice/p07";
  if (!std::filesystem::exists(p07)) GTEST_SKIP() << "no practice data";
  const std::string dir = ::testing::TempDir() + "/vb-import-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  testing::ServerProcess server(dir);
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  const std::string op = "--server " + addr + " --token " + testing::kOperatorToken;

  Result imported = Benchctl("import " + p07 + " --json " + op);
  ASSERT_EQ(imported.exit_code, 0) << imported.out;
  const auto j = nlohmann::json::parse(imported.out);
  std::string ids;
  for (const auto& id : j["run_ids"]) {
    if (!ids.empty()) ids += ',';
    ids += std::to_string(id.get<std::int64_t>());
  }
  ASSERT_EQ(j["run_ids"].size(), 12u);  // p07 has 12 runs

  // The stored trace is the CSV's current.
  const std::string first = std::to_string(j["run_ids"][0].get<std::int64_t>());
  Result exp = Benchctl("export " + first + " --csv " + dir + "/first.csv " + op);
  ASSERT_EQ(exp.exit_code, 0) << exp.out;
  std::ifstream manifest_in(p07 + "/manifest.json");
  const auto manifest = nlohmann::json::parse(manifest_in);
  std::ifstream stored(dir + "/first.csv"), original(p07 + "/" + manifest["runs"][0]["file"].get<std::string>());
  std::string a, b;
  std::getline(stored, a);
  std::getline(original, b);
  EXPECT_EQ(a.rfind("t_s,gate,i_A", 0), 0u) << a;
  std::size_t rows = 0, mismatches = 0;
  while (std::getline(stored, a) && std::getline(original, b)) {
    ++rows;
    double ts, gs, is, to, go, io;
    if (std::sscanf(a.c_str(), "%lf,%lf,%lf", &ts, &gs, &is) != 3 || std::sscanf(b.c_str(), "%lf,%lf,%lf", &to, &go, &io) != 3 ||
        std::abs(is - io) > 1e-12 || gs != go || std::abs(ts - to) > 1e-9)
      ++mismatches;
  }
  EXPECT_GT(rows, 1000u);
  EXPECT_EQ(mismatches, 0u);
  Result show = Benchctl("show " + first + " --json " + op);
  EXPECT_NE(show.out.find("split:" + manifest["runs"][0]["split"].get<std::string>()), std::string::npos) << show.out;

  Result d = Benchctl("diagnose --runs " + ids + " --json --model-out " + dir + "/improved.json " + op);
  ASSERT_EQ(d.exit_code, 0) << d.out;
  const auto diag = nlohmann::json::parse(d.out);
  EXPECT_EQ(diag["verdict"], "supply_resistance");
  EXPECT_FALSE(diag.contains("split_note")) << "the manifest's split travels with the runs";

  // The same diagnosis computed by the server (DiagnoseRuns, what the web page's "diagnose" calls): the same
  // dataset and the same numbers as benchctl's.
  client::ClientOptions viewer;
  viewer.address = addr;
  viewer.token = testing::kViewerToken;
  client::Client c(viewer);
  std::vector<std::int64_t> id_list;
  for (const auto& id : j["run_ids"]) id_list.push_back(id.get<std::int64_t>());
  auto on_server = c.DiagnoseRuns(id_list);
  ASSERT_TRUE(on_server.ok()) << on_server.status().message();
  const auto sj = nlohmann::json::parse(on_server->report_json());
  EXPECT_EQ(sj["verdict"], diag["verdict"]);
  ASSERT_TRUE(sj.contains("gap") && sj.contains("how_far")) << on_server->report_json().substr(0, 400);
  for (const char* key : {"gap", "how_far", "verdict_reason"}) EXPECT_EQ(sj[key].dump(), diag[key].dump()) << key;
  EXPECT_NE(on_server->report().find("supply_resistance"), std::string::npos) << on_server->report();
  // The improved model: the server's is the one `diagnose --model-out` wrote (one builder,
  // gap/improved_model.h); only the description says who fitted it.
  ASSERT_FALSE(on_server->improved_model_json().empty());
  auto from_server = nlohmann::json::parse(on_server->improved_model_json());
  std::ifstream improved_in(dir + "/improved.json");
  auto from_cli = nlohmann::json::parse(improved_in);
  EXPECT_NE(from_server.dump().find("supply_resistance"), std::string::npos) << from_server.dump();
  EXPECT_NE(from_server["description"].get<std::string>().find("DiagnoseRuns"), std::string::npos);
  from_server.erase("description");
  from_cli.erase("description");
  EXPECT_EQ(from_server, from_cli);
  // A model file as the nominal model (DiagnoseRunsRequest.model_spec): the improved model already holds the
  // supply resistance, so the diagnosis against it is named after the file and no longer finds that effect
  // first; and --suggest's plan comes from the service too (the spec file written only when a run would tell).
  Result against = Benchctl("diagnose --runs " + ids + " --json --model " + dir + "/improved.json --suggest " + dir +
                            "/next.json " + op);
  ASSERT_EQ(against.exit_code, 0) << against.out;
  const auto aj = nlohmann::json::parse(against.out, nullptr, false);
  ASSERT_TRUE(aj.is_object()) << against.out;
  EXPECT_EQ(aj["model"], "taghizadeh2009 (model file)") << aj["model"];
  EXPECT_NE(aj["verdict"], "supply_resistance") << aj["verdict_reason"];
  EXPECT_LT(aj["gap"]["holdout_rmse_A"].get<double>(), diag["gap"]["holdout_rmse_A"].get<double>()) << aj["gap"].dump();
  EXPECT_TRUE(aj.contains("suggestion")) << against.out.substr(0, 300);
  Result bad_model = Benchctl("diagnose --runs " + ids + " --model " + dir + "/nonexistent.json " + op);
  EXPECT_EQ(bad_model.exit_code, 2) << bad_model.out;
  EXPECT_NE(bad_model.out.find("neither a preset nor a readable file"), std::string::npos) << bad_model.out;
  valvebench::v1::DiagnoseRunsRequest both;
  both.add_run_ids(id_list[0]);
  both.set_model("taghizadeh2009");
  both.mutable_model_spec()->set_preset("taghizadeh2009");
  auto both_refused = c.DiagnoseRuns(both);
  ASSERT_FALSE(both_refused.ok());
  EXPECT_NE(both_refused.status().message().find("not both"), std::string::npos) << both_refused.status().message();
  auto twice = c.DiagnoseRuns({id_list[0], id_list[0]});
  ASSERT_FALSE(twice.ok());
  EXPECT_NE(twice.status().message().find("run_ids[1]"), std::string::npos) << twice.status().message();
  auto none = c.DiagnoseRuns(std::vector<std::int64_t>{});
  EXPECT_EQ(none.status().code(), StatusCode::kInvalidArgument);

  // A bad dataset is refused before anything is sent, naming the file and line.
  const std::string bad = dir + "/bad";
  std::filesystem::create_directories(bad);
  std::ofstream(bad + "/manifest.json") << R"({"format": "valve-runs/1", "model": "taghizadeh2009", "runs": [)"
                                        << R"({"id": "r", "file": "r.csv", "supply_V": 24, "supply_pressure_Pa": 0,)"
                                        << R"( "t_start_s": 0}]})";
  std::ofstream(bad + "/r.csv") << "t_s,gate,i_A\n0,0,0\n2e-05,2,0.1\n4e-05,1,0.2\n";
  Result refused = Benchctl("import " + bad + " " + op);
  EXPECT_EQ(refused.exit_code, 2) << refused.out;
  EXPECT_NE(refused.out.find("r.csv:3"), std::string::npos) << refused.out;
}

// A config copied without its files: the server names the field, the path it tried, and that a relative path
// is relative to the config file's directory (which one).
TEST(BenchctlRemote, ConfigSaysRelativePathsAreRelativeToTheConfigFile) {
  const std::string dir = ::testing::TempDir() + "/vb-relative-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  testing::ServerProcess server(dir, R"("nights": {"cron": "0 2 * * *", "suite_file": "suites/ci.json",
      "baseline_file": "suites/ci-baseline.json", "timezone": "UTC"})");
  EXPECT_EQ(server.Start(), "");
  const std::string log = server.Log();
  EXPECT_NE(log.find("nights.suite_file"), std::string::npos) << log;
  EXPECT_NE(log.find("'suites/ci.json' is relative to the config file's directory, " + dir), std::string::npos)
      << log;

  // nights are the server's: no --db to offer and then refuse.
  Result nights_db = Benchctl("nights --db " + dir + "/x.db");
  EXPECT_EQ(nights_db.exit_code, 2) << nights_db.out;
  EXPECT_NE(nights_db.out.find("--db"), std::string::npos) << nights_db.out;  // CLI11: not an option of nights
}

}  // namespace
}  // namespace vb
