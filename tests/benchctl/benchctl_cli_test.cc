// benchctl as a user runs it: exit codes, JSON, CSV, errors naming the field.
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <unistd.h>

#include "../common/run_command.h"

#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <regex>
#include <thread>
#include <vector>
#include <fstream>
#include <sstream>
#include <memory>
#include <string>

namespace {

using Result = vb::testing::CommandResult;

Result RunBenchctl(const std::string& args) {
  // Local runs are recorded in a store of the test's own.
  return vb::testing::RunCommand("VALVEBENCH_DB=" + ::testing::TempDir() + "/benchctl-cli-" +
                                 std::to_string(::getpid()) + ".db " + std::string(VB_BENCHCTL) + " " + args);
}

std::string Example(const std::string& rel) { return std::string(VB_SOURCE_DIR) + "/examples/" + rel; }

TEST(BenchctlCli, RunLocalWritesCsvAndJson) {
  const std::string csv = ::testing::TempDir() + "/e3.csv";
  Result r = RunBenchctl("run --local " + Example("standard/e3.json") + " --json --trace-csv " + csv);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("\"status\": \"done\""), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("\"samples\": 5001"), std::string::npos) << r.out;
  std::ifstream in(csv);
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header.rfind("t_s,gate,v_coil_V,i_A,x_m", 0), 0u) << header;
  size_t lines = 0;
  for (std::string line; std::getline(in, line);) ++lines;
  EXPECT_EQ(lines, 5001u);
}

TEST(BenchctlCli, BadSpecExitsTwoAndNamesTheField) {
  const std::string path = ::testing::TempDir() + "/bad.json";
  std::ofstream(path) << R"({"duration_s": 1, "conditions": {"supply_V": -1},
    "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 50, "duty": 0.4}]}}})";
  Result r = RunBenchctl("run --local " + path);
  EXPECT_EQ(r.exit_code, 2) << r.out;
  EXPECT_NE(r.out.find("conditions.supply_V"), std::string::npos) << r.out;
  Result missing = RunBenchctl("run --local /nonexistent/spec.json");
  EXPECT_EQ(missing.exit_code, 2) << missing.out;
  Result no_server = RunBenchctl("run " + Example("standard/e3.json"));
  EXPECT_EQ(no_server.exit_code, 2) << no_server.out;
  EXPECT_NE(no_server.out.find("--local"), std::string::npos);

  // A misspelt field: refused (never a silent default), with the field's path and the closest real name.
  const std::string typo = ::testing::TempDir() + "/typo.json";
  std::ofstream(typo) << R"({"duration_s": 0.01, "conditions": {"suply_V": 24},
    "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 50, "duty": 0.4}]}}})";
  Result misspelt = RunBenchctl("run --local " + typo);
  EXPECT_EQ(misspelt.exit_code, 2) << misspelt.out;
  EXPECT_NE(misspelt.out.find("conditions.suply_V: unknown field; did you mean 'supply_V'?"), std::string::npos)
      << misspelt.out;
  std::ofstream(typo) << R"({"duration_s": 0.01, "controller": {"open_loop_pwm": {"segments": [
    {"start_s": 0, "frequency_Hz": 50, "dutty": 0.4}]}}})";
  Result nested = RunBenchctl("run --local " + typo);
  EXPECT_EQ(nested.exit_code, 2) << nested.out;
  EXPECT_NE(nested.out.find("did you mean 'duty'?"), std::string::npos) << nested.out;
}

// An unreachable server: one short line naming the address and how to point elsewhere, exit 3 (environment).
TEST(BenchctlCli, UnreachableServerSaysWhereItLookedInOneLine) {
  Result r = RunBenchctl("show 1 --server 127.0.0.1:1 --token t");
  EXPECT_EQ(r.exit_code, 3) << r.out;
  EXPECT_NE(r.out.find("127.0.0.1:1"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("VALVEBENCH_SERVER"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find('\n'), r.out.size() - 1) << "one line: " << r.out;
  EXPECT_LT(r.out.size(), 140u) << r.out;
}

TEST(BenchctlCli, CompareAndCsvOutputs) {
  Result run = RunBenchctl("run --local " + Example("dither.json") + " --csv");
  ASSERT_EQ(run.exit_code, 0) << run.out;
  EXPECT_EQ(run.out.rfind("id,batch_id,name,controller,\"controller.dither_pwm.average_current_A\",status", 0), 0u)
      << "the sweep value is a column: " << run.out;
  size_t rows = 0;
  for (size_t p = run.out.find('\n'); p != std::string::npos; p = run.out.find('\n', p + 1)) ++rows;
  EXPECT_EQ(rows, 5u) << "header + 4 sweep points";

  const std::string results = ::testing::TempDir() + "/runs.json";
  Result json = RunBenchctl("run --local " + Example("dither.json") + " --json > " + results);
  ASSERT_EQ(json.exit_code, 0) << json.out;
  {
    std::ifstream in(results);
    std::stringstream ss;
    ss << in.rdbuf();
    // Each run's identity travels as fields: the comparison groups on them, never on the name.
    EXPECT_NE(ss.str().find("\"key\": {"), std::string::npos) << ss.str().substr(0, 400);
    EXPECT_NE(ss.str().find("\"field\": \""), std::string::npos) << ss.str().substr(0, 400);
  }
  Result cmp = RunBenchctl("compare " + results + " --csv");
  ASSERT_EQ(cmp.exit_code, 0) << cmp.out;
  EXPECT_EQ(cmp.out.rfind("rank,name,controller", 0), 0u) << cmp.out;

  Result bad = RunBenchctl("compare " + Example("standard/e1.json"));
  EXPECT_EQ(bad.exit_code, 2) << bad.out;
  EXPECT_NE(bad.out.find("metrics"), std::string::npos) << bad.out;
}

TEST(BenchctlCli, LocalRunsAreRecordedAndComparableByBatch) {
  Result run = RunBenchctl("run --local " + Example("compare-current-controllers.json") + " --json");
  ASSERT_EQ(run.exit_code, 0) << run.out;
  const size_t at = run.out.find("\"batch_id\": ");
  ASSERT_NE(at, std::string::npos) << run.out;
  const std::string batch = run.out.substr(at + 12, run.out.find_first_of(",\n", at + 12) - at - 12);
  Result cmp = RunBenchctl("compare --local --batch " + batch + " --csv");
  ASSERT_EQ(cmp.exit_code, 0) << cmp.out;
  EXPECT_NE(cmp.out.find("fuzzy_current"), std::string::npos) << cmp.out;
  EXPECT_NE(cmp.out.find("hysteresis_current"), std::string::npos) << cmp.out;
  Result cmp_json = RunBenchctl("compare --local --batch " + batch + " --json");
  ASSERT_EQ(cmp_json.exit_code, 0) << cmp_json.out;
  EXPECT_NE(cmp_json.out.find("\"columns\": ["), std::string::npos) << cmp_json.out;
  EXPECT_NE(cmp_json.out.find("\"failed\": 0"), std::string::npos) << cmp_json.out;
  Result missing = RunBenchctl("compare --local --batch 999999");
  EXPECT_EQ(missing.exit_code, 2) << missing.out;
  Result unstored = RunBenchctl("run --local " + Example("standard/e3.json") + " --json --no-store");
  ASSERT_EQ(unstored.exit_code, 0) << unstored.out;
  EXPECT_EQ(unstored.out.find("\"id\": "), std::string::npos) << "--no-store records nothing";
}

// The tables' options reach the comparison on `run` and on `compare --batch/--runs` of the store; a batch
// prints one line per run (the metrics are in the table), a single run its metrics with units; a report of a
// stored run carries its spec and times (docs/comparison.md, docs/report.md).
TEST(BenchctlCli, TableOptionsPerRunLinesUnitsAndReportOnTheLocalStore) {
  Result run = RunBenchctl("run --local " + Example("compare-current-controllers.json") +
                           " --metrics rmse,driver_loss_W");
  ASSERT_EQ(run.exit_code, 0) << run.out;
  const std::regex line("(^|\n)run [0-9]+ compare-current-controllers/pi: done\n");
  EXPECT_TRUE(std::regex_search(run.out, line)) << "one line per run: " << run.out;
  EXPECT_EQ(run.out.find("  rmse "), std::string::npos) << "no per-run metric lines in a batch: " << run.out;
  EXPECT_NE(run.out.find("RMSE [mA]"), std::string::npos) << run.out;
  EXPECT_NE(run.out.find("driver loss [mW]"), std::string::npos) << run.out;
  EXPECT_EQ(run.out.find("sw rate"), std::string::npos) << "--metrics picks the columns: " << run.out;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(run.out, m, std::regex("run ([0-9]+) compare-current-controllers/hysteresis")));
  const std::int64_t first = std::stoll(m[1]);
  const std::string ids = std::to_string(first) + "," + std::to_string(first + 1);

  Result cmp = RunBenchctl("compare --local --runs " + ids + " --metrics max_abs_error");
  ASSERT_EQ(cmp.exit_code, 0) << cmp.out;
  EXPECT_NE(cmp.out.find("max|e| [mA]"), std::string::npos) << cmp.out;
  EXPECT_EQ(cmp.out.find("driver loss [mW]"), std::string::npos) << cmp.out;
  Result wide = RunBenchctl("compare --local --runs " + ids + " --wide");
  ASSERT_EQ(wide.exit_code, 0) << wide.out;
  EXPECT_NE(wide.out.find("energy"), std::string::npos) << "--wide: every metric: " << wide.out;
  Result bad = RunBenchctl("compare --local --runs " + ids + " --metrics no_such_metric");
  EXPECT_EQ(bad.exit_code, 2) << bad.out;
  EXPECT_NE(bad.out.find("no_such_metric"), std::string::npos) << bad.out;

  Result single = RunBenchctl("run --local " + Example("standard/e3.json"));
  ASSERT_EQ(single.exit_code, 0) << single.out;
  EXPECT_TRUE(std::regex_search(single.out, std::regex("\n  mean_current_A +[0-9.]+ [mµ]?A\n"))) << single.out;
  std::smatch sm;
  ASSERT_TRUE(std::regex_search(single.out, sm, std::regex("^run ([0-9]+) e3 ")));
  const std::string html = ::testing::TempDir() + "/benchctl-cli-run.html";
  Result rep = RunBenchctl("report --run " + sm[1].str() + " --html " + html);
  ASSERT_EQ(rep.exit_code, 0) << rep.out;
  std::ifstream in(html);
  std::stringstream page;
  page << in.rdbuf();
  EXPECT_NE(page.str().find("supply_V"), std::string::npos) << "the run's spec is on its page";
  EXPECT_NE(page.str().find("[\"ran\",\"2"), std::string::npos) << "the run's times are on its page";
}

std::int64_t FirstId(const std::string& run_json) {
  const auto j = nlohmann::json::parse(run_json, nullptr, false);
  if (!j.is_array() || j.empty() || !j[0].contains("id")) return 0;
  return j[0]["id"].get<std::int64_t>();
}

// show, queue, export, compare --runs and watch work on the local store as on a server: the same commands,
// the same run JSON (numeric ids, lower-case status), times in ISO 8601, metrics in one order.
TEST(BenchctlCli, StoredRunCommandsWorkOnTheLocalStore) {
  Result run = RunBenchctl("run --local " + Example("standard/e3.json") + " --json");
  ASSERT_EQ(run.exit_code, 0) << run.out;
  const std::int64_t id = FirstId(run.out);
  ASSERT_GT(id, 0) << run.out;
  const std::string ids = std::to_string(id);
  const auto ran = nlohmann::ordered_json::parse(run.out)[0];
  EXPECT_EQ(ran["status"], "done");
  EXPECT_EQ(ran["summary"]["samples"], 5001);

  Result show = RunBenchctl("show " + ids + " --json");
  ASSERT_EQ(show.exit_code, 0) << show.out;
  const auto shown = nlohmann::ordered_json::parse(show.out);
  EXPECT_EQ(shown["id"], id);
  EXPECT_EQ(shown["status"], "done");
  EXPECT_EQ(shown["spec"]["name"], "e3");
  EXPECT_EQ(shown["history"].back()["status"], "done");
  std::vector<std::string> run_order, show_order;
  for (const auto& [k, v] : ran["metrics"].items()) run_order.push_back(k);
  for (const auto& [k, v] : shown["metrics"].items()) show_order.push_back(k);
  EXPECT_EQ(run_order, show_order);
  EXPECT_GT(show_order.size(), 3u);

  Result text = RunBenchctl("show " + ids);
  ASSERT_EQ(text.exit_code, 0) << text.out;
  const std::regex iso(R"(\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d[+-]\d\d:\d\d)");
  EXPECT_TRUE(std::regex_search(text.out, iso)) << text.out;
  EXPECT_NE(text.out.find("history: done"), std::string::npos) << text.out;

  Result queue = RunBenchctl("queue");
  ASSERT_EQ(queue.exit_code, 0) << queue.out;
  EXPECT_NE(queue.out.find("no runs queued or running on local store"), std::string::npos) << queue.out;
  Result done = RunBenchctl("queue --status done --json");
  ASSERT_EQ(done.exit_code, 0) << done.out;
  EXPECT_NE(done.out.find("\"id\": " + ids), std::string::npos) << done.out;

  const std::string csv = ::testing::TempDir() + "/local-export.csv";
  Result exp = RunBenchctl("export " + ids + " --trace-csv " + csv);
  ASSERT_EQ(exp.exit_code, 0) << exp.out;
  std::ifstream in(csv);
  std::string header;
  std::getline(in, header);
  EXPECT_EQ(header.rfind("t_s,gate,v_coil_V,i_A,x_m", 0), 0u) << header;
  size_t lines = 0;
  for (std::string line; std::getline(in, line);) ++lines;
  EXPECT_EQ(lines, 5001u);
  Result to_stdout = RunBenchctl("export " + ids + " --csv");
  ASSERT_EQ(to_stdout.exit_code, 0) << to_stdout.out.substr(0, 300);
  EXPECT_EQ(to_stdout.out.rfind("t_s,gate,", 0), 0u) << to_stdout.out.substr(0, 300);
  const std::string old_csv = ::testing::TempDir() + "/local-export-old.csv";
  Result old = RunBenchctl("export " + ids + " --csv " + old_csv);  // the old spelling, with a note
  ASSERT_EQ(old.exit_code, 0) << old.out;
  EXPECT_NE(old.out.find("--trace-csv"), std::string::npos) << old.out;
  EXPECT_TRUE(std::ifstream(old_csv).good());

  Result watch = RunBenchctl("watch " + ids);
  EXPECT_EQ(watch.exit_code, 0) << watch.out;
  Result cmp = RunBenchctl("compare --runs " + ids + "," + ids + " --csv");
  ASSERT_EQ(cmp.exit_code, 0) << cmp.out;
  EXPECT_EQ(cmp.out.rfind("rank,name,controller", 0), 0u) << cmp.out;
  Result finished = RunBenchctl("cancel " + ids);
  EXPECT_EQ(finished.exit_code, 2) << finished.out;
  Result missing = RunBenchctl("show 99999999");
  EXPECT_EQ(missing.exit_code, 2) << missing.out;
  EXPECT_NE(missing.out.find("local store"), std::string::npos) << missing.out;
}

// A paced local run's loop statistics are stored with the run (issue 40): `run --local --realtime` prints them,
// and so does `show` from another process, text and JSON, with the build that executed it; a run not paced shows
// its execution without a loop.
TEST(BenchctlCli, LoopStatisticsOfAPacedRunAreShownFromTheStore) {
  const std::string dir = ::testing::TempDir() + "/benchctl-loop-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string env = "VALVEBENCH_DB=" + dir + "/local.db ";
  auto cli = [&](const std::string& args) { return vb::testing::RunCommand(env + VB_BENCHCTL + " " + args); };
  const std::string spec = dir + "/short.json";
  std::ofstream(spec) << R"({"name": "short", "duration_s": 0.1, "recording": {"rate_Hz": 10000},
      "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 100, "duty": 0.5}]}}})";
  Result paced = cli("run --local " + spec + " --realtime");
  ASSERT_EQ(paced.exit_code, 0) << paced.out;
  EXPECT_NE(paced.out.find("  loop: "), std::string::npos) << paced.out;
  EXPECT_NE(paced.out.find(" paced ticks, "), std::string::npos) << paced.out;
  const std::regex id_re("run ([0-9]+) ");
  std::smatch m;
  ASSERT_TRUE(std::regex_search(paced.out, m, id_re)) << paced.out;
  const std::string id = m[1].str();

  Result shown = cli("show " + id);
  ASSERT_EQ(shown.exit_code, 0) << shown.out;
  EXPECT_NE(shown.out.find(" paced ticks, "), std::string::npos) << "show reads them from the store\n" << shown.out;
  EXPECT_NE(shown.out.find(" s wall, "), std::string::npos) << shown.out;
  Result json = cli("show " + id + " --json");
  ASSERT_EQ(json.exit_code, 0) << json.out;
  const auto j = nlohmann::json::parse(json.out, nullptr, false);
  ASSERT_TRUE(j.is_object()) << json.out;
  ASSERT_TRUE(j["summary"].contains("loop")) << json.out;
  EXPECT_GT(j["summary"]["loop"]["paced_ticks"].get<std::int64_t>(), 0);
  EXPECT_GE(j["summary"]["loop"]["jitter_max_s"].get<double>(), j["summary"]["loop"]["jitter_p50_s"].get<double>());
  EXPECT_EQ(j["summary"]["samples"], 1001);
  // The build that executed it: this benchctl, named by its SHA-256 (docs/store.md, "Schema version 7").
  Result sum = vb::testing::RunCommand(std::string("sha256sum ") + VB_BENCHCTL);
  ASSERT_EQ(sum.exit_code, 0) << sum.out;
  const std::string digest = "sha256:" + sum.out.substr(0, 32);
  EXPECT_EQ(j["summary"].value("build", "").rfind("valvebench ", 0), 0u) << json.out;
  EXPECT_NE(j["summary"].value("build", "").find(digest), std::string::npos) << json.out << "\n" << sum.out;
  EXPECT_NE(shown.out.find("  build: valvebench "), std::string::npos) << shown.out;

  Result plain = cli("run --local " + spec + " --json");
  ASSERT_EQ(plain.exit_code, 0) << plain.out;
  const auto p = nlohmann::json::parse(plain.out, nullptr, false);
  ASSERT_TRUE(p.is_array() && p.size() == 1u) << plain.out;
  ASSERT_TRUE(p[0].contains("summary")) << plain.out;
  EXPECT_FALSE(p[0]["summary"].contains("loop")) << "not paced: no loop statistics\n" << plain.out;
  Result plain_shown = cli("show " + std::to_string(p[0]["id"].get<std::int64_t>()));
  EXPECT_EQ(plain_shown.out.find("paced ticks"), std::string::npos) << plain_shown.out;
}

// A local run executing in one benchctl is seen by another through the store: queue lists it running with
// its progress, cancel stops it and reports the state it reached; the running benchctl exits 1.
TEST(BenchctlCli, LocalRunIsFollowedAndCancelledFromAnotherProcess) {
  const std::string dir = ::testing::TempDir() + "/benchctl-cancel-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string env = "VALVEBENCH_DB=" + dir + "/local.db ";
  auto cli = [&](const std::string& args) { return vb::testing::RunCommand(env + VB_BENCHCTL + " " + args); };
  const std::string spec = dir + "/long.json";
  std::ofstream(spec) << R"({"name": "long", "duration_s": 30, "recording": {"rate_Hz": 1000},
      "reference": {"on_off_profile": {"switching_value": 0.9, "switching_time_s": 0.006, "holding_value": 0.5}},
      "controller": {"pi_current": {}}})";
  const std::string out = dir + "/run.out", rc = dir + "/run.rc";
  ASSERT_EQ(std::system(("(" + env + VB_BENCHCTL + " run --local " + spec + " --realtime --json > " + out +
                         " 2>&1; echo $? > " + rc + ".tmp; mv " + rc + ".tmp " + rc + ") &").c_str()), 0);
  std::int64_t id = 0;
  double progress = 0.0;
  for (int k = 0; k < 150 && progress <= 0.0; ++k) {  // up to 15 s for the run to start and report progress
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    Result q = cli("queue --json");
    const auto j = nlohmann::json::parse(q.out, nullptr, false);
    if (!j.is_object() || j["runs"].empty()) continue;
    id = j["runs"][0]["id"].get<std::int64_t>();
    if (j["runs"][0]["status"] == "running") progress = j["runs"][0]["progress"].get<double>();
  }
  ASSERT_GT(id, 0);
  EXPECT_GT(progress, 0.0) << "progress by simulated time, through the store";
  Result text = cli("queue");
  EXPECT_NE(text.out.find("1 running"), std::string::npos) << text.out;
  EXPECT_NE(text.out.find("ETA"), std::string::npos) << text.out;

  Result cancel = cli("cancel " + std::to_string(id) + " --json");
  ASSERT_EQ(cancel.exit_code, 0) << cancel.out;
  const auto c = nlohmann::json::parse(cancel.out, nullptr, false);
  ASSERT_TRUE(c.is_object()) << cancel.out;
  EXPECT_EQ(c["status"], "cancelled") << cancel.out;
  EXPECT_EQ(c["cancel"], "done") << cancel.out;
  for (int k = 0; k < 200 && !std::filesystem::exists(rc); ++k) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  std::ifstream rc_in(rc);
  int code = -1;
  rc_in >> code;
  EXPECT_EQ(code, 1) << "a cancelled run exits 1";
  std::ifstream out_in(out);
  std::stringstream ss;
  ss << out_in.rdbuf();
  EXPECT_NE(ss.str().find("\"status\": \"cancelled\""), std::string::npos) << ss.str();
}

TEST(BenchctlCli, DiagnoseReportsJsonAndRefusesBadData) {
  const std::string practice = std::string(VB_SHARED_DIR) + "/gapbench/practice/";
  Result none = RunBenchctl("diagnose " + practice + "p12 --json");
  if (none.out.find("does not exist") != std::string::npos) GTEST_SKIP() << "no practice data";
  ASSERT_EQ(none.exit_code, 0) << none.out;
  EXPECT_NE(none.out.find("\"verdict\": \"none\""), std::string::npos) << none.out;
  // A gap, its cause, and the improved model: with it, the same data shows no gap any more.
  const std::string file = ::testing::TempDir() + "/p07.json", improved = ::testing::TempDir() + "/p07-model.json";
  Result gap = RunBenchctl("diagnose " + practice + "p07 --json-out " + file + " --model-out " + improved);
  ASSERT_EQ(gap.exit_code, 0) << gap.out;
  EXPECT_NE(gap.out.find("SIGNIFICANT"), std::string::npos) << gap.out;
  EXPECT_NE(gap.out.find("verdict: supply_resistance"), std::string::npos) << gap.out;
  std::ifstream in(file);
  std::stringstream ss;
  ss << in.rdbuf();
  EXPECT_NE(ss.str().find("\"significant\": true"), std::string::npos);
  EXPECT_NE(ss.str().find("\"verdict\": \"supply_resistance\""), std::string::npos);
  Result after = RunBenchctl("diagnose " + practice + "p07 --model " + improved + " --json");
  ASSERT_EQ(after.exit_code, 0) << after.out;
  EXPECT_NE(after.out.find("\"verdict\": \"none\""), std::string::npos) << after.out;
  // The old spellings still work, each with a note naming the new one.
  const std::string old_file = ::testing::TempDir() + "/p12-old.json";
  Result old = RunBenchctl("diagnose " + practice + "p12 --json " + old_file + " --emit-model " + improved + "-old");
  ASSERT_EQ(old.exit_code, 0) << old.out;
  EXPECT_NE(old.out.find("--json-out FILE"), std::string::npos) << old.out;
  EXPECT_NE(old.out.find("--model-out FILE"), std::string::npos) << old.out;
  EXPECT_TRUE(std::ifstream(old_file).good());
  EXPECT_TRUE(std::ifstream(improved + "-old").good());
  Result flag_first = RunBenchctl("diagnose --json " + practice + "p12");  // --json before the dataset
  ASSERT_EQ(flag_first.exit_code, 0) << flag_first.out;
  EXPECT_NE(flag_first.out.find("\"verdict\": \"none\""), std::string::npos) << flag_first.out;
  Result bad = RunBenchctl("diagnose /nonexistent/dataset");
  EXPECT_EQ(bad.exit_code, 2) << bad.out;
  Result bad_model = RunBenchctl("diagnose " + practice + "p12 --model nosuchmodel");
  EXPECT_EQ(bad_model.exit_code, 2) << bad_model.out;
  EXPECT_NE(bad_model.out.find("--model"), std::string::npos) << bad_model.out;
}

// identify: a bounded fit of named parameters; p05's coil resistance is 12 % high (14.56 ohm).
TEST(BenchctlCli, IdentifyFitsNamedParametersAndWritesAModel) {
  const std::string practice = std::string(VB_SHARED_DIR) + "/gapbench/practice/";
  const std::string out = ::testing::TempDir() + "/p05-identified.json";
  Result r = RunBenchctl("identify " + practice + "p05 --params R --model-out " + out + " --json");
  if (r.out.find("does not exist") != std::string::npos) GTEST_SKIP() << "no practice data";
  ASSERT_EQ(r.exit_code, 0) << r.out;
  auto j = nlohmann::json::parse(r.out.substr(r.out.find('{')));
  EXPECT_NEAR(j["params"]["R"]["value"].get<double>(), 14.56, 0.05);
  EXPECT_GT(j["params"]["R"]["sigma"].get<double>(), 0.0);
  EXPECT_LT(j["holdout_rmse_after_A"].get<double>(), 3e-3);
  Result check = RunBenchctl("diagnose " + practice + "p05 --model " + out + " --json");
  EXPECT_NE(check.out.find("\"verdict\": \"none\""), std::string::npos) << check.out;
  Result bad = RunBenchctl("identify " + practice + "p05 --params R,flux_capacitor");
  EXPECT_EQ(bad.exit_code, 2) << bad.out;
  EXPECT_NE(bad.out.find("flux_capacitor"), std::string::npos) << bad.out;
}

// identify without --params on a moving valve's switch-on runs: from scratch, progress on stderr, the holdout
// runs predicted (practice3 m01: 6 bar, and 0.75x supply that does not pull in), a model written.
TEST(BenchctlCli, IdentifyFromScratchOnSwitchOnRuns) {
  const std::string m01 = std::string(VB_SHARED_DIR) + "/gapbench/practice3/m01";
  const std::string out = ::testing::TempDir() + "/m01-identified.json";
  Result r = RunBenchctl("identify " + m01 + " --json --model-out " + out);
  if (r.out.find("does not exist") != std::string::npos) GTEST_SKIP() << "no practice3 data";
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("benchctl: identify: stage 1 electrical"), std::string::npos) << r.out;
  auto j = nlohmann::json::parse(r.out.substr(r.out.find("\n{") + 1));
  EXPECT_LT(j["holdout_rmse_after_A"].get<double>(), 5e-3);
  bool low_supply_seen = false;
  for (const auto& lm : j["landmarks"]) {
    if (lm["split"] != "holdout") continue;
    EXPECT_LT(lm["rmse_A"].get<double>(), 5e-3) << lm.dump();
    if (lm["supply_V"].get<double>() < 10.0) {
      low_supply_seen = true;
      EXPECT_FALSE(lm["measured"]["pulls_in"].get<bool>());
      EXPECT_FALSE(lm["predicted"]["pulls_in"].get<bool>());
      EXPECT_TRUE(lm["predicted"]["pull_in_s"].is_null());
    }
  }
  EXPECT_TRUE(low_supply_seen);
  EXPECT_FALSE(j["held"].empty());
  // The model written predicts the runs as identify said.
  Result check = RunBenchctl("diagnose " + m01 + " --model " + out + " --json");
  ASSERT_EQ(check.exit_code, 0) << check.out;
  auto d = nlohmann::json::parse(check.out.substr(check.out.find('{')));
  EXPECT_LT(d["gap"]["holdout_rmse_A"].get<double>(), 5e-3) << check.out.substr(0, 2000);
  EXPECT_EQ(d["verdict"], "none");
}

// convert --channel: a scope capture becomes a run; a bad cell is named by line and column.
TEST(BenchctlCli, ConvertScopeCapture) {
  const std::string dir = ::testing::TempDir() + "/scope-cli-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  {
    std::ofstream f(dir + "/cap.csv");
    f << "X,CH1,CH2\nSecond,Volt,Volt\n";
    for (int k = 0; k < 100; ++k) f << (k - 10) * 1e-5 << "," << (k >= 10 ? 5 : 0) << "," << (k >= 10 ? 0.01 * (k - 10) : 0.0) << "\n";
    std::ofstream b(dir + "/bad.csv");
    b << "X,CH1,CH2\n0,0,0\n1e-5,0,zz\n";
  }
  Result r = RunBenchctl("convert " + dir + "/cap.csv " + dir + "/ds --channel CH2 --shunt-ohm 0.5 --gate-channel CH1 "
                         "--supply-V 12 --pressure-Pa 1e5 --json");
  ASSERT_EQ(r.exit_code, 0) << r.out;
  auto j = nlohmann::json::parse(r.out.substr(r.out.find('{')));
  EXPECT_EQ(j["samples"].get<int>(), 100);
  EXPECT_NEAR(j["gate_on_s"].get<double>(), 1e-4, 1e-9);
  Result bad = RunBenchctl("convert " + dir + "/bad.csv " + dir + "/ds2 --channel CH2 --shunt-ohm 1 --trigger-s 0 --supply-V 12");
  EXPECT_EQ(bad.exit_code, 2) << bad.out;
  EXPECT_NE(bad.out.find("bad.csv:3: column CH2: 'zz' is not a number"), std::string::npos) << bad.out;
  std::filesystem::remove_all(dir);
}

// diagnose on one switch-on curve: says nothing can be held out, ranks nothing (never "0.00 -> 0.00").
TEST(BenchctlCli, DiagnoseOneRunSaysNothingCanBeHeldOut) {
  const std::string m01 = std::string(VB_SHARED_DIR) + "/gapbench/practice3/m01";
  if (!std::filesystem::is_directory(m01)) GTEST_SKIP() << "no practice3 data";
  const std::string dir = ::testing::TempDir() + "/one-run-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  std::filesystem::copy_file(m01 + "/on1_1bar_12V.csv", dir + "/on1_1bar_12V.csv");
  std::ifstream in(m01 + "/manifest.json");
  auto m = nlohmann::json::parse(in);
  m["runs"] = nlohmann::json::array({m["runs"][0]});
  std::ofstream(dir + "/manifest.json") << m.dump(1);
  Result r = RunBenchctl("diagnose " + dir);
  ASSERT_EQ(r.exit_code, 0) << r.out;
  EXPECT_NE(r.out.find("nothing can be held out"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("no holdout run"), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find("0.00 ->"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("benchctl identify"), std::string::npos) << r.out;
  std::filesystem::remove_all(dir);
}

}  // namespace

namespace {

// benchctl --local is a client of a local service (service/local_service.h): import goes through the
// service's ImportRuns into the local store (it was refused before), and the imported runs are then what show,
// queue --status and diagnose --runs of later invocations read from that store.
TEST(BenchctlCli, ImportWorksLocallyThroughTheService) {
  const std::string p07 = std::string(VB_SHARED_DIR) + "/gapbench/practice/p07";
  if (!std::filesystem::exists(p07)) GTEST_SKIP() << "no practice data";
  const std::string dir = ::testing::TempDir() + "/benchctl-import-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string env = "VALVEBENCH_DB=" + dir + "/local.db ";
  auto cli = [&](const std::string& args) { return vb::testing::RunCommand(env + VB_BENCHCTL + " " + args); };
  Result imported = cli("import " + p07 + " --local --json");
  ASSERT_EQ(imported.exit_code, 0) << imported.out;
  const auto j = nlohmann::json::parse(imported.out);
  ASSERT_EQ(j["run_ids"].size(), 12u) << imported.out;  // p07 has 12 runs
  const std::string first = std::to_string(j["run_ids"][0].get<std::int64_t>());
  Result shown = cli("show " + first + " --local --json");
  ASSERT_EQ(shown.exit_code, 0) << shown.out;
  EXPECT_EQ(nlohmann::json::parse(shown.out)["status"], "done") << shown.out;
  // Listed newest first, cut by --limit, saying so.
  Result listed = cli("queue --local --status done --limit 5");
  ASSERT_EQ(listed.exit_code, 0) << listed.out;
  EXPECT_NE(listed.out.find("5 of 12 runs on local store " + dir + "/local.db"), std::string::npos) << listed.out;
  EXPECT_NE(listed.out.find("--limit"), std::string::npos) << listed.out;
}

// queue and benches --local ask the local service (GetQueue, ListBenches) as they ask a server: the queue
// says which store it looked at, and the bench is the service's local emulator (positions and ETAs of queued
// runs: tests/service/local_service_test.cc).
TEST(BenchctlCli, LocalQueueIsTheServicesGetQueue) {
  const std::string dir = ::testing::TempDir() + "/benchctl-queue-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string env = "VALVEBENCH_DB=" + dir + "/local.db ";
  auto cli = [&](const std::string& args) { return vb::testing::RunCommand(env + VB_BENCHCTL + " " + args); };
  Result empty = cli("queue --local --json");
  ASSERT_EQ(empty.exit_code, 0) << empty.out;
  const auto e = nlohmann::json::parse(empty.out);
  EXPECT_EQ(e["runs"].size(), 0u) << empty.out;
  EXPECT_NE(e["where"].get<std::string>().find("local store " + dir + "/local.db"), std::string::npos) << empty.out;
  Result benches = cli("benches --local");
  ASSERT_EQ(benches.exit_code, 0) << benches.out;
  EXPECT_NE(benches.out.find("local-emulator"), std::string::npos) << benches.out;
  EXPECT_NE(benches.out.find("idle"), std::string::npos) << benches.out;
}

}  // namespace
