// The web gateway (web/gateway.h, docs/web.md) on the real valvebench-server over loopback, driven with
// cpp-httplib's client: the embedded page and dygraphs, the service's own auth, roles and field-named errors,
// traces (decimated, windowed, CSV), comparison units, SSE live samples, cancel and re-run, the cookie rule.
#include <gtest/gtest.h>

#include "experiment/compare.h"
#include <httplib.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "server/config.h"
#include "valvebench/v1/api.grpc.pb.h"
#include "tests/integration/server_process.h"
#include "web/gateway.h"

namespace {

// The door now answers some requests (a refused import, bad framing) before it has read their bodies and closes
// the connection; the test's HTTP client then writes into a closed socket. A real client gets EPIPE there, not a
// signal that ends the process: the test process ignores SIGPIPE as a browser does (it failed once with SIGPIPE
// in 4 runs under the full suite).
const bool kSigpipeIgnored = [] {
  std::signal(SIGPIPE, SIG_IGN);
  return true;
}();


using Json = nlohmann::json;
using vb::testing::kOperatorToken;
using vb::testing::kViewerToken;

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

httplib::Headers Bearer(const char* token) { return {{"Authorization", std::string("Bearer ") + token}}; }

class WebGatewayTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string dir = ::testing::TempDir() + "/web-gateway-" +
                            ::testing::UnitTest::GetInstance()->current_test_info()->name();
    std::filesystem::remove_all(dir);
    server_ = std::make_unique<vb::testing::ServerProcess>(dir, R"("web": {"listen_address": "127.0.0.1:0"})");
    grpc_address_ = server_->Start();
    ASSERT_FALSE(grpc_address_.empty()) << server_->Log();
    ConnectToDashboard();
  }

  // The dashboard's port from the server's log (port 0: a new one at every start).
  void ConnectToDashboard() {
    port_ = 0;
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (std::chrono::steady_clock::now() < until) {
      const std::string log = server_->Log();
      const auto at = log.find("web dashboard on http://127.0.0.1:");
      if (at != std::string::npos) {
        port_ = std::stoi(log.substr(at + std::string("web dashboard on http://127.0.0.1:").size()));
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    ASSERT_GT(port_, 0) << server_->Log();
    http_ = std::make_unique<httplib::Client>("127.0.0.1", port_);
    http_->set_read_timeout(30, 0);
  }

  // Logs in with the token; the session id from the cookie.
  std::string Login(const char* token) {
    auto login = http_->Post("/api/login", std::string(R"({"token": ")") + token + "\"}", "application/json");
    EXPECT_TRUE(login && login->status == 200);
    if (!login) return "";
    const std::string cookie = login->get_header_value("Set-Cookie");
    return cookie.substr(11, cookie.find(';') - 11);
  }

  Json Submit(const std::string& spec_json, const char* token = kOperatorToken) {
    auto res = http_->Post("/api/runs", Bearer(token), R"({"spec": )" + spec_json + "}", "application/json");
    EXPECT_TRUE(res);
    if (!res) return {};
    EXPECT_EQ(res->status, 201) << res->body;
    return Json::parse(res->body);
  }

  Json WaitEnded(const std::string& run_id) {
    const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    Json run;
    while (std::chrono::steady_clock::now() < until) {
      auto res = http_->Get("/api/runs/" + run_id, Bearer(kViewerToken));
      EXPECT_TRUE(res && res->status == 200);
      if (!res) return {};
      run = Json::parse(res->body);
      const std::string s = run["run"]["status"];
      if (s != "QUEUED" && s != "RUNNING") return run;
      std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ADD_FAILURE() << "run " << run_id << " did not end";
    return run;
  }

  std::unique_ptr<vb::testing::ServerProcess> server_;
  std::unique_ptr<httplib::Client> http_;
  std::string grpc_address_;
  int port_ = 0;
};

std::string SpecFile(const char* rel) { return ReadFile(std::string(VB_SOURCE_DIR) + "/examples/" + rel); }

TEST(WebHttpStatus, GrpcCodesMapToTheirHttpMeaning) {
  EXPECT_EQ(vb::web::HttpStatusFor(grpc::StatusCode::OK), 200);
  EXPECT_EQ(vb::web::HttpStatusFor(grpc::StatusCode::INVALID_ARGUMENT), 400);
  EXPECT_EQ(vb::web::HttpStatusFor(grpc::StatusCode::UNAUTHENTICATED), 401);
  EXPECT_EQ(vb::web::HttpStatusFor(grpc::StatusCode::PERMISSION_DENIED), 403);
  EXPECT_EQ(vb::web::HttpStatusFor(grpc::StatusCode::NOT_FOUND), 404);
  EXPECT_EQ(vb::web::HttpStatusFor(grpc::StatusCode::FAILED_PRECONDITION), 409);
  EXPECT_EQ(vb::web::HttpStatusFor(grpc::StatusCode::RESOURCE_EXHAUSTED), 429);
  EXPECT_EQ(vb::web::HttpStatusFor(grpc::StatusCode::UNAVAILABLE), 503);
  EXPECT_EQ(vb::web::HttpStatusFor(grpc::StatusCode::INTERNAL), 500);
}

TEST(WebConfig, ListenAddressIsCheckedAtStart) {
  auto c = vb::testing::MinimalConfig();
  c.mutable_web()->set_listen_address("8080");
  auto s = vb::server::SettingsFromConfig(c, "");
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().message().rfind("web.listen_address: must be host:port", 0), 0u) << s.status().message();
  c.mutable_web()->set_listen_address("127.0.0.1:99999");
  EXPECT_FALSE(vb::server::SettingsFromConfig(c, "").ok());
  c.mutable_web()->set_listen_address("127.0.0.1:8080");
  auto ok = vb::server::SettingsFromConfig(c, "");
  ASSERT_TRUE(ok.ok()) << ok.status().message();
  EXPECT_EQ(ok->web_listen_address, "127.0.0.1:8080");
  EXPECT_TRUE(vb::server::SettingsFromConfig(vb::testing::MinimalConfig(), "")->web_listen_address.empty());
  // The door's limits: named in the error, live views below the workers.
  auto refused = [&](auto&& set, const std::string& field) {
    auto bad = c;
    set(*bad.mutable_web());
    auto s = vb::server::SettingsFromConfig(bad, "");
    ASSERT_FALSE(s.ok()) << field;
    EXPECT_EQ(s.status().message().rfind(field, 0), 0u) << s.status().message();
  };
  refused([](auto& w) { w.set_head_timeout_s(-1); }, "web.head_timeout_s");
  refused([](auto& w) { w.set_max_streams(64); }, "web.max_streams");  // = the default 64 workers
  refused([](auto& w) { w.set_workers(8); }, "web.max_streams");       // below the default 48 streams
  refused([](auto& w) { w.add_allowed_origins("https://proxy.lab/"); }, "web.allowed_origins");
  c.mutable_web()->set_workers(16);
  c.mutable_web()->set_max_streams(12);
  c.mutable_web()->add_allowed_origins("https://proxy.lab:8443");
  auto limits = vb::server::SettingsFromConfig(c, "");
  ASSERT_TRUE(limits.ok()) << limits.status().message();
  EXPECT_EQ(limits->web.workers(), 16);
}

TEST_F(WebGatewayTest, ServesThePageAndDebiansDygraphsFromTheBinary) {
  auto page = http_->Get("/");
  ASSERT_TRUE(page);
  EXPECT_EQ(page->status, 200);
  EXPECT_NE(page->body.find(R"(<script src="/dygraph.min.js">)"), std::string::npos);
  EXPECT_EQ(page->get_header_value("Content-Type"), "text/html; charset=utf-8");
  EXPECT_NE(page->get_header_value("Content-Security-Policy").find("default-src 'self'"), std::string::npos);
  auto dy = http_->Get("/dygraph.min.js");
  ASSERT_TRUE(dy);
  EXPECT_EQ(dy->status, 200);
  EXPECT_EQ(dy->body, ReadFile("/usr/share/javascript/dygraphs/dygraph.min.js"));
  auto js = http_->Get("/app.js");
  ASSERT_TRUE(js);
  EXPECT_EQ(js->body, ReadFile(std::string(VB_SOURCE_DIR) + "/web/static/app.js"));
  auto missing = http_->Get("/api/nothing");
  ASSERT_TRUE(missing);
  EXPECT_EQ(missing->status, 404);
}

TEST_F(WebGatewayTest, TokensAndRolesAreTheServices) {
  auto none = http_->Get("/api/benches");
  ASSERT_TRUE(none);
  EXPECT_EQ(none->status, 401);
  EXPECT_EQ(Json::parse(none->body)["code"], "UNAUTHENTICATED");
  auto wrong = http_->Get("/api/benches", Bearer("not-a-token"));
  ASSERT_TRUE(wrong);
  EXPECT_EQ(wrong->status, 401);
  auto viewer = http_->Get("/api/benches", Bearer(kViewerToken));
  ASSERT_TRUE(viewer);
  ASSERT_EQ(viewer->status, 200);
  const Json b = Json::parse(viewer->body);
  ASSERT_EQ(b["benches"].size(), 2u);
  EXPECT_EQ(b["benches"][0]["name"], "emu-a");
  EXPECT_EQ(b["benches"][0]["max_supply_V"], 1000);  // proto field names, not lowerCamelCase
  EXPECT_GT(b["benches"][0]["max_current_A"].get<double>(), 0.0);  // the interlock's current limit
  EXPECT_EQ(b["benches"][0]["max_duty"], 1);
  auto refused = http_->Post("/api/runs", Bearer(kViewerToken), R"({"spec": )" + SpecFile("standard/e3.json") + "}",
                             "application/json");
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->status, 403);
  const Json e = Json::parse(refused->body);
  EXPECT_EQ(e["code"], "PERMISSION_DENIED");
  EXPECT_NE(e["message"].get<std::string>().find("needs the operator role"), std::string::npos);
  // Nothing was queued by the refused submission.
  auto runs = http_->Get("/api/runs", Bearer(kViewerToken));
  ASSERT_TRUE(runs);
  EXPECT_FALSE(Json::parse(runs->body).contains("runs"));
}

TEST_F(WebGatewayTest, BadSpecsGetTheFieldNamedErrorsOfTheCliAndTheService) {
  Json spec = Json::parse(SpecFile("standard/e3.json"));
  spec["conditions"]["suply_V"] = spec["conditions"]["supply_V"];
  spec["conditions"].erase("supply_V");
  auto typo = http_->Post("/api/runs", Bearer(kOperatorToken), Json{{"spec", spec}}.dump(), "application/json");
  ASSERT_TRUE(typo);
  EXPECT_EQ(typo->status, 400);
  EXPECT_EQ(Json::parse(typo->body)["message"], "conditions.suply_V: unknown field; did you mean 'supply_V'?");
  spec = Json::parse(SpecFile("standard/e3.json"));
  spec["conditions"]["supply_V"] = -1;
  auto negative = http_->Post("/api/runs", Bearer(kOperatorToken), Json{{"spec", spec}}.dump(), "application/json");
  ASSERT_TRUE(negative);
  EXPECT_EQ(negative->status, 400);
  const Json e = Json::parse(negative->body);
  EXPECT_EQ(e["code"], "INVALID_ARGUMENT");
  EXPECT_EQ(e["message"].get<std::string>().rfind("conditions.supply_V:", 0), 0u) << e["message"];
  auto not_json = http_->Post("/api/runs", Bearer(kOperatorToken), "{", "application/json");
  ASSERT_TRUE(not_json);
  EXPECT_EQ(not_json->status, 400);
  EXPECT_EQ(Json::parse(not_json->body)["message"].get<std::string>().rfind("body: not JSON", 0), 0u);
  auto extra = http_->Post("/api/runs", Bearer(kOperatorToken), R"({"spec": {}, "priority": 3})", "application/json");
  ASSERT_TRUE(extra);
  EXPECT_EQ(extra->status, 400);
  EXPECT_EQ(Json::parse(extra->body)["message"].get<std::string>().rfind("priority: unknown field", 0), 0u);
  auto bad_param = http_->Get("/api/runs/1/trace?max_points=lots", Bearer(kViewerToken));
  ASSERT_TRUE(bad_param);
  EXPECT_EQ(bad_param->status, 400);
  EXPECT_EQ(Json::parse(bad_param->body)["message"], "max_points: not a number, got 'lots'");
  auto unknown_run = http_->Get("/api/runs/999", Bearer(kViewerToken));
  ASSERT_TRUE(unknown_run);
  EXPECT_EQ(unknown_run->status, 404);
}

TEST_F(WebGatewayTest, TracesDecimatedWindowedAndExportedWhole) {
  const Json sub = Submit(SpecFile("standard/e1.json"));  // 1 s at 50 kHz: 50001 samples
  const std::string id = sub["run_ids"][0];
  const Json run = WaitEnded(id);
  ASSERT_EQ(run["run"]["status"], "DONE");
  EXPECT_EQ(run["metric_units"]["effort_l2"], "V s^0.5");
  EXPECT_EQ(run["channel_units"]["i_A"], "A");
  auto whole = http_->Get("/api/runs/" + id + "/trace?max_points=1000", Bearer(kViewerToken));
  ASSERT_TRUE(whole);
  ASSERT_EQ(whole->status, 200) << whole->body;
  const Json t = Json::parse(whole->body);
  EXPECT_EQ(t["total_samples"], 50001);
  EXPECT_TRUE(t["decimated"]);
  EXPECT_LE(t["rows"].size(), 1000u);
  EXPECT_GE(t["rows"].size(), 990u);
  const auto& ch = t["channels"];
  ASSERT_EQ(ch[0], "gate");  // t_s is the rows' first column, not a channel
  const size_t i_col = std::find(ch.begin(), ch.end(), "i_A") - ch.begin() + 1;
  // The envelope keeps the PWM's extremes: the decimated maximum of i_A is the trace's maximum.
  auto csv = http_->Get("/api/runs/" + id + "/trace.csv", Bearer(kViewerToken));
  ASSERT_TRUE(csv);
  ASSERT_EQ(csv->status, 200);
  std::istringstream lines(csv->body);
  std::string line, header;
  std::getline(lines, header);
  EXPECT_EQ(header.rfind("t_s,gate,", 0), 0u) << header;
  size_t rows = 0, i_index = 0;
  {
    std::istringstream h(header);
    std::string name;
    for (size_t k = 0; std::getline(h, name, ','); ++k)
      if (name == "i_A") i_index = k;
  }
  double csv_max = -1e300, rows_max = -1e300;
  while (std::getline(lines, line)) {
    std::istringstream f(line);
    std::string cell;
    for (size_t k = 0; std::getline(f, cell, ','); ++k)
      if (k == i_index) csv_max = std::max(csv_max, std::stod(cell));
    ++rows;
  }
  EXPECT_EQ(rows, 50001u);
  for (const auto& r : t["rows"]) rows_max = std::max(rows_max, r[i_col].get<double>());
  EXPECT_NEAR(rows_max, csv_max, 1e-8 * std::abs(csv_max));
  auto window = http_->Get("/api/runs/" + id + "/trace?t_from_s=0.1&t_to_s=0.1002", Bearer(kViewerToken));
  ASSERT_TRUE(window);
  const Json w = Json::parse(window->body);
  EXPECT_FALSE(w["decimated"]);
  ASSERT_GE(w["rows"].size(), 10u);
  EXPECT_LE(w["rows"].size(), 13u);
  EXPECT_NEAR(w["rows"][1][0].get<double>() - w["rows"][0][0].get<double>(), 2e-5, 1e-12);
  auto cmp = http_->Get("/api/compare?runs=" + id, Bearer(kViewerToken));
  ASSERT_TRUE(cmp);
  ASSERT_EQ(cmp->status, 200) << cmp->body;
  const Json c = Json::parse(cmp->body);
  EXPECT_EQ(c["comparison"]["rows"].size(), 1u);
  EXPECT_EQ(c["units"]["effort_l2"], "V s^0.5");
  EXPECT_EQ(c["units"]["driver_loss_W"], "W");
  EXPECT_FALSE(c["units"][c["comparison"]["effort_metric"].get<std::string>()].get<std::string>().empty());
  // How the CLI shows each column, for the page (experiment::MetricColumnDisplay), and every row's key.
  const Json& d = c["display"];
  EXPECT_EQ(d["columns"]["effort_l2"]["header"], "||v||2 [V s^0.5]") << d.dump();
  EXPECT_FALSE(d["columns"]["rmse"]["header"].get<std::string>().empty()) << d.dump();
  EXPECT_GT(d["columns"]["rmse"]["scale"].get<double>(), 0.0);
  EXPECT_FALSE(d["default_columns"].empty());
  ASSERT_EQ(d["keys"].size(), 1u);
  EXPECT_EQ(d["keys"][0]["name"], c["comparison"]["rows"][0]["name"]);
  // Zeros are written: e1 is a single run, so every spread is 0 and still there.
  const Json& stat = c["comparison"]["rows"][0]["metrics"]["effort_l2"];
  ASSERT_TRUE(stat.contains("spread")) << stat.dump();
  EXPECT_EQ(stat["spread"], 0.0);
  auto units = http_->Get("/api/units", Bearer(kViewerToken));
  ASSERT_TRUE(units);
  ASSERT_EQ(units->status, 200);
  const Json u = Json::parse(units->body);
  ASSERT_GE(u["prefixes"].size(), 5u);
  EXPECT_EQ(u["prefixes"][0]["symbol"], "G");
  auto bad = http_->Get("/api/compare?runs=1,x", Bearer(kViewerToken));
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->status, 400);
}

TEST_F(WebGatewayTest, LiveSamplesArriveAsServerSentEventsUntilTheEnd) {
  Json spec = Json::parse(SpecFile("standard/e3.json"));
  spec["realtime"] = true;
  spec["duration_s"] = 0.6;
  const std::string id = Submit(spec.dump())["run_ids"][0];
  std::string stream;
  auto res = http_->Get("/api/runs/" + id + "/events?rate_Hz=200", Bearer(kViewerToken),
                        [&](const char* data, size_t n) {
                          stream.append(data, n);
                          return true;
                        });
  ASSERT_TRUE(res);
  EXPECT_EQ(res->status, 200);
  EXPECT_EQ(res->get_header_value("Content-Type"), "text/event-stream");
  size_t samples = 0, events = 0;
  std::istringstream lines(stream);
  std::string line, event;
  double last_t = -1.0;
  bool increasing = true;
  while (std::getline(lines, line)) {
    if (line.rfind("event: ", 0) == 0) event = line.substr(7);
    if (line.rfind("data: ", 0) != 0 || event != "run") continue;
    const Json ev = Json::parse(line.substr(6));
    ++events;
    if (!ev.contains("samples")) continue;
    for (const auto& s : ev["samples"]) {
      increasing = increasing && s["t_s"].get<double>() > last_t;
      last_t = s["t_s"].get<double>();
      ++samples;
    }
  }
  EXPECT_GE(events, 3u) << stream.substr(0, 2000);
  // 0.6 s of run at 200 Hz: about 120 samples live (the first ones may come before the watch starts).
  EXPECT_GE(samples, 40u) << stream.substr(0, 2000);
  EXPECT_TRUE(increasing);
  EXPECT_NE(stream.find("event: end\ndata: {\"status\":\"DONE\"}"), std::string::npos) << stream.substr(stream.size() - 400);
  // The stream needs a token like any other call.
  auto anonymous = http_->Get("/api/runs/" + id + "/events");
  ASSERT_TRUE(anonymous);
  EXPECT_NE(anonymous->body.find("event: error"), std::string::npos);
  EXPECT_NE(anonymous->body.find("UNAUTHENTICATED"), std::string::npos);
}

// A run watched from before its start (issue 24, M3): proto3 JSON leaves out fields at zero (a sample at t_s = 0,
// a plunger at x_m = 0 before it moves, the gate off), and a chart fed such a sample stays blank: every live
// sample carries every field.
TEST_F(WebGatewayTest, LiveSamplesCarryEveryFieldFromTheStart) {
  Json spec = Json::parse(SpecFile("standard/e3.json"));
  spec["realtime"] = true;
  spec["bench"]["name"] = "emu-a";
  spec["duration_s"] = 30;
  const std::string blocker = Submit(spec.dump())["run_ids"][0];
  spec["duration_s"] = 0.3;
  const std::string id = Submit(spec.dump())["run_ids"][0];
  std::string stream;
  std::thread watch([&] {
    httplib::Client c("127.0.0.1", port_);
    c.set_read_timeout(30, 0);
    c.Get("/api/runs/" + id + "/events?rate_Hz=200", Bearer(kViewerToken), [&](const char* data, size_t n) {
      stream.append(data, n);
      return true;
    });
  });
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  auto cancel = http_->Post("/api/runs/" + blocker + "/cancel", Bearer(kOperatorToken), "{}", "application/json");
  ASSERT_TRUE(cancel && cancel->status == 200);
  watch.join();
  size_t samples = 0, missing = 0;
  std::string example;
  std::istringstream lines(stream);
  for (std::string line; std::getline(lines, line);) {
    if (line.rfind("data: {\"run_id\"", 0) != 0) continue;
    const Json ev = Json::parse(line.substr(6));
    for (const auto& sample : ev["samples"]) {
      ++samples;
      for (const char* field : {"t_s", "gate", "duty", "i_A", "x_m", "ref"}) {
        if (!sample.contains(field)) {
          ++missing;
          example = sample.dump();
        }
      }
    }
  }
  EXPECT_GE(samples, 20u) << stream.substr(0, 1500);
  EXPECT_EQ(missing, 0u) << example;
  EXPECT_NE(stream.find("\"dropped_samples\""), std::string::npos) << "the server's loss count on every event";
}

// An interactive run is cancelled when its submitter's watch goes away: the page's streams come and go, so the
// gateway does not watch those runs, and the run is not cancelled by a page that looked at it.
TEST_F(WebGatewayTest, InteractiveRunsAreNotWatchedFromThePage) {
  Json spec = Json::parse(SpecFile("standard/e3.json"));
  spec["realtime"] = true;
  spec["interactive"] = true;
  spec["duration_s"] = 2;
  const std::string id = Submit(spec.dump())["run_ids"][0];
  httplib::Client c("127.0.0.1", port_);
  c.set_read_timeout(2, 0);
  auto res = c.Get("/api/runs/" + id + "/events", Bearer(kOperatorToken));
  ASSERT_TRUE(res);
  EXPECT_EQ(res->get_header_value("Content-Type"), "text/event-stream");
  EXPECT_NE(res->body.find("event: error"), std::string::npos) << res->body;
  EXPECT_NE(res->body.find("is interactive: follow it with benchctl watch"), std::string::npos) << res->body;
  EXPECT_EQ(WaitEnded(id)["run"]["status"], "DONE");
}

// An imported run is a measurement: "Re-run" is refused as a precondition, saying so (not an internal error).
TEST_F(WebGatewayTest, AnImportedRunIsNotReRun) {
  auto stub = valvebench::v1::BenchService::NewStub(grpc::CreateChannel(grpc_address_, grpc::InsecureChannelCredentials()));
  valvebench::v1::ImportRunsRequest req;
  req.set_dataset("web-lab");
  auto* r = req.add_runs();
  r->set_id("step");
  r->set_supply_v(24.0);
  r->set_sample_period_s(2e-5);
  for (int k = 0; k < 3; ++k) {
    r->add_gate(k > 0 ? 1 : 0);
    r->add_i_a(0.01 * k);
  }
  grpc::ClientContext ctx;
  ctx.AddMetadata("authorization", std::string("Bearer ") + kOperatorToken);
  valvebench::v1::SubmitRunResponse out;
  const grpc::Status st = stub->ImportRuns(&ctx, req, &out);
  ASSERT_TRUE(st.ok()) << st.error_message();
  ASSERT_EQ(out.run_ids_size(), 1);
  const std::string id = std::to_string(out.run_ids(0));
  auto rerun = http_->Post("/api/runs/" + id + "/rerun", Bearer(kOperatorToken), "{}", "application/json");
  ASSERT_TRUE(rerun);
  EXPECT_EQ(rerun->status, 409) << rerun->body;
  const Json e = Json::parse(rerun->body);
  EXPECT_EQ(e["code"], "FAILED_PRECONDITION");
  EXPECT_NE(e["message"].get<std::string>().find("imported measurement"), std::string::npos) << rerun->body;
}

TEST_F(WebGatewayTest, CancelAndRerunGoThroughTheService) {
  Json spec = Json::parse(SpecFile("standard/e3.json"));
  spec["realtime"] = true;
  spec["duration_s"] = 20;
  const std::string id = Submit(spec.dump())["run_ids"][0];
  auto viewer_cancel = http_->Post("/api/runs/" + id + "/cancel", Bearer(kViewerToken), "{}", "application/json");
  ASSERT_TRUE(viewer_cancel);
  EXPECT_EQ(viewer_cancel->status, 403);
  auto cancel = http_->Post("/api/runs/" + id + "/cancel", Bearer(kOperatorToken), R"({"reason": "from the test"})",
                            "application/json");
  ASSERT_TRUE(cancel);
  ASSERT_EQ(cancel->status, 200) << cancel->body;
  const Json ended = WaitEnded(id);
  EXPECT_EQ(ended["run"]["status"], "CANCELLED");
  // Who cancelled is recorded ahead of the caller's words, which cannot replace it.
  EXPECT_EQ(ended["run"]["reason"].get<std::string>().rfind("cancelled by olga: from the test", 0), 0u) << ended.dump();
  auto again = http_->Post("/api/runs/" + id + "/cancel", Bearer(kOperatorToken), "{}", "application/json");
  ASSERT_TRUE(again);
  EXPECT_EQ(again->status, 409) << again->body;  // FAILED_PRECONDITION: already finished
  auto rerun = http_->Post("/api/runs/" + id + "/rerun", Bearer(kOperatorToken), "", "application/json");
  ASSERT_TRUE(rerun);
  ASSERT_EQ(rerun->status, 201) << rerun->body;
  const std::string new_id = Json::parse(rerun->body)["run_ids"][0];
  EXPECT_NE(new_id, id);
  auto fresh = http_->Get("/api/runs/" + new_id, Bearer(kViewerToken));
  ASSERT_TRUE(fresh);
  EXPECT_EQ(Json::parse(fresh->body)["run"]["spec"], ended["run"]["spec"]);
  http_->Post("/api/runs/" + new_id + "/cancel", Bearer(kOperatorToken), "{}", "application/json");
  auto viewer_rerun = http_->Post("/api/runs/" + id + "/rerun", Bearer(kViewerToken), "", "application/json");
  ASSERT_TRUE(viewer_rerun);
  EXPECT_EQ(viewer_rerun->status, 403);
}

// The cookie holds a server-side session id (never the token), authorises only what the page cannot send a
// header with (the live view, the CSV download), never from another origin, and logout revokes it.
TEST_F(WebGatewayTest, TheSessionCookieAuthorisesTheStreamAndTheDownloadOnlyAndLogoutRevokesIt) {
  auto bad = http_->Post("/api/login", R"({"token": "nope"})", "application/json");
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->status, 401);
  EXPECT_FALSE(bad->has_header("Set-Cookie"));
  auto login = http_->Post("/api/login", std::string(R"({"token": ")") + kOperatorToken + "\"}", "application/json");
  ASSERT_TRUE(login);
  ASSERT_EQ(login->status, 200);
  const std::string cookie = login->get_header_value("Set-Cookie");
  EXPECT_NE(cookie.find("HttpOnly"), std::string::npos);
  EXPECT_NE(cookie.find("SameSite=Strict"), std::string::npos);
  EXPECT_EQ(cookie.find(kOperatorToken), std::string::npos) << cookie;  // not the token
  ASSERT_EQ(cookie.rfind("vb_session=", 0), 0u) << cookie;
  const std::string session = cookie.substr(11, cookie.find(';') - 11);
  EXPECT_EQ(session.size(), 64u);
  const httplib::Headers with_cookie = {{"Cookie", "vb_session=" + session}};

  Json spec = Json::parse(SpecFile("standard/e3.json"));
  spec["duration_s"] = 0.05;
  const std::string id = Submit(spec.dump())["run_ids"][0];
  WaitEnded(id);
  auto csv = http_->Get("/api/runs/" + id + "/trace.csv", with_cookie);
  ASSERT_TRUE(csv);
  EXPECT_EQ(csv->status, 200) << csv->body.substr(0, 300);
  // Other reads and every change need the header.
  auto read = http_->Get("/api/benches", with_cookie);
  ASSERT_TRUE(read);
  EXPECT_EQ(read->status, 401);
  auto write = http_->Post("/api/runs", with_cookie, R"({"spec": )" + SpecFile("standard/e3.json") + "}",
                           "application/json");
  ASSERT_TRUE(write);
  EXPECT_EQ(write->status, 401);
  // A page of another origin (another port of this host is same-site, not same-origin) gets nothing with it.
  httplib::Headers cross = with_cookie;
  cross.emplace("Origin", "http://127.0.0.1:1");
  auto from_elsewhere = http_->Get("/api/runs/" + id + "/trace.csv", cross);
  ASSERT_TRUE(from_elsewhere);
  EXPECT_EQ(from_elsewhere->status, 403);
  httplib::Headers same = with_cookie;
  same.emplace("Origin", "http://127.0.0.1:" + std::to_string(port_));
  auto from_here = http_->Get("/api/runs/" + id + "/trace.csv", same);
  ASSERT_TRUE(from_here);
  EXPECT_EQ(from_here->status, 200);
  // Logout revokes the session: the same cookie no longer authorises anything.
  auto logout = http_->Post("/api/logout", with_cookie, "", "application/json");
  ASSERT_TRUE(logout);
  EXPECT_EQ(logout->status, 200);
  auto after = http_->Get("/api/runs/" + id + "/trace.csv", with_cookie);
  ASSERT_TRUE(after);
  EXPECT_EQ(after->status, 401) << after->body;
  // The old raw-token cookie is nothing.
  auto raw = http_->Get("/api/runs/" + id + "/trace.csv", {{"Cookie", std::string("vb_token=") + kOperatorToken}});
  ASSERT_TRUE(raw);
  EXPECT_EQ(raw->status, 401);
}

// Issue 39, point 4: the dashboard's sessions survive a restart of the server (kept in <database>.web-sessions,
// the token sealed under the session id, so the file alone opens nothing); logout ends one, "everywhere" all of a
// token's, and that too survives the restart.
TEST_F(WebGatewayTest, SessionsSurviveARestartAndLogoutEverywhereEndsAllOfAToken) {
  Json spec = Json::parse(SpecFile("standard/e3.json"));
  spec["duration_s"] = 0.05;
  const std::string id = Submit(spec.dump())["run_ids"][0];
  WaitEnded(id);
  const std::string first = Login(kOperatorToken), second = Login(kOperatorToken), viewer = Login(kViewerToken);
  ASSERT_EQ(first.size(), 64u);
  auto cookie = [](const std::string& session) { return httplib::Headers{{"Cookie", "vb_session=" + session}}; };
  const std::string file = server_->dir() + "/runs.db.web-sessions";
  const std::string stored = ReadFile(file);
  ASSERT_FALSE(stored.empty()) << "no " << file << "\n" << server_->Log();
  EXPECT_EQ(stored.find(kOperatorToken), std::string::npos) << "the token is in the file";
  EXPECT_EQ(stored.find(first), std::string::npos) << "the session id is in the file";
  EXPECT_EQ(std::filesystem::status(file).permissions() & std::filesystem::perms::group_read,
            std::filesystem::perms::none);

  ASSERT_EQ(server_->Kill(SIGTERM), 0) << server_->Log();
  ASSERT_FALSE(server_->Start().empty()) << server_->Log();
  ConnectToDashboard();
  EXPECT_NE(server_->Log().find("web sessions: 3 kept from"), std::string::npos) << server_->Log();
  auto csv = http_->Get("/api/runs/" + id + "/trace.csv", cookie(first));
  ASSERT_TRUE(csv);
  EXPECT_EQ(csv->status, 200) << csv->body.substr(0, 300);
  auto state = http_->Get("/api/login", cookie(second));
  ASSERT_TRUE(state);
  EXPECT_EQ(Json::parse(state->body), (Json{{"session", true}, {"user", "olga"}, {"role", "operator"}})) << state->body;
  auto unknown = http_->Get("/api/login", cookie(std::string(64, 'a')));
  ASSERT_TRUE(unknown);
  EXPECT_EQ(Json::parse(unknown->body), (Json{{"session", false}}));

  // Logout everywhere from the first: the second goes too, the viewer's stays.
  auto out = http_->Post("/api/logout", cookie(first), R"({"everywhere": true})", "application/json");
  ASSERT_TRUE(out);
  EXPECT_EQ(out->status, 200);
  EXPECT_EQ(Json::parse(out->body)["sessions_ended"], 2) << out->body;
  auto bad = http_->Post("/api/logout", cookie(viewer), R"({"everywhere": "yes"})", "application/json");
  ASSERT_TRUE(bad);
  EXPECT_EQ(bad->status, 400);
  EXPECT_NE(bad->body.find("everywhere: must be true or false"), std::string::npos) << bad->body;
  ASSERT_EQ(server_->Kill(SIGTERM), 0);
  ASSERT_FALSE(server_->Start().empty()) << server_->Log();
  ConnectToDashboard();
  for (const std::string& gone : {first, second}) {
    auto after = http_->Get("/api/runs/" + id + "/trace.csv", cookie(gone));
    ASSERT_TRUE(after);
    EXPECT_EQ(after->status, 401);
  }
  auto kept = http_->Get("/api/runs/" + id + "/trace.csv", cookie(viewer));
  ASSERT_TRUE(kept);
  EXPECT_EQ(kept->status, 200);
}

// Login CSRF: a cross-site form can post text/plain, and a page of another origin sends its Origin; both are
// refused. Failed logins are limited per address and logged.
TEST_F(WebGatewayTest, LoginWantsJsonFromThisOriginAndFailuresAreLimited) {
  const std::string body = std::string(R"({"token": ")") + kViewerToken + "\"}";
  auto form = http_->Post("/api/login", body, "text/plain");
  ASSERT_TRUE(form);
  EXPECT_EQ(form->status, 415);
  EXPECT_FALSE(form->has_header("Set-Cookie"));
  auto cross = http_->Post("/api/login", {{"Origin", "http://evil.example"}}, body, "application/json");
  ASSERT_TRUE(cross);
  EXPECT_EQ(cross->status, 403);
  EXPECT_FALSE(cross->has_header("Set-Cookie"));
  for (int k = 0; k < 10; ++k) {
    auto bad = http_->Post("/api/login", R"({"token": "guess)" + std::to_string(k) + "\"}", "application/json");
    ASSERT_TRUE(bad);
    EXPECT_EQ(bad->status, 401);
  }
  auto blocked = http_->Post("/api/login", body, "application/json");  // even the right token, for a while
  ASSERT_TRUE(blocked);
  EXPECT_EQ(blocked->status, 429) << blocked->body;
  EXPECT_TRUE(blocked->has_header("Retry-After"));
  EXPECT_NE(server_->Log().find("web: failed login from 127.0.0.1"), std::string::npos);
  // API JSON is not cached.
  auto api = http_->Get("/api/benches", Bearer(kViewerToken));
  ASSERT_TRUE(api);
  EXPECT_EQ(api->get_header_value("Cache-Control"), "no-store");
}

TEST_F(WebGatewayTest, ListsCheckTheirParametersAndPassTheRestToTheService) {
  auto nights = http_->Get("/api/nights?limit=5", Bearer(kViewerToken));
  ASSERT_TRUE(nights);
  EXPECT_EQ(nights->status, 200);
  EXPECT_EQ(nights->body, "{}");  // no night has run: protobuf JSON leaves the empty list out
  auto bad_limit = http_->Get("/api/nights?limit=-1", Bearer(kViewerToken));
  ASSERT_TRUE(bad_limit);
  EXPECT_EQ(bad_limit->status, 400);
  auto bad_status = http_->Get("/api/runs?status=DONEISH", Bearer(kViewerToken));
  ASSERT_TRUE(bad_status);
  EXPECT_EQ(bad_status->status, 400);
  EXPECT_EQ(Json::parse(bad_status->body)["message"].get<std::string>().rfind("status: unknown run status 'DONEISH'", 0),
            0u);
  const std::string id = Submit(SpecFile("standard/e3.json"))["run_ids"][0];
  WaitEnded(id);
  auto done = http_->Get("/api/runs?status=DONE&batch_id=1", Bearer(kViewerToken));
  ASSERT_TRUE(done);
  const Json runs = Json::parse(done->body)["runs"];
  ASSERT_EQ(runs.size(), 1u);
  EXPECT_EQ(runs[0]["id"], id);
  // Issue 28: the list's headline metrics are the ones the law's comparison ranks by, with the CLI's units.
  const Json headline = Json::parse(done->body)["headline"][runs[0]["controller"].get<std::string>()];
  EXPECT_EQ(headline["rank"]["metric"], "rmse");
  EXPECT_EQ(headline["effort"]["metric"],
            vb::experiment::EffortMetricOf(runs[0]["controller"].get<std::string>()).metric);
  EXPECT_FALSE(headline["effort"]["unit"].get<std::string>().empty());
  auto other_batch = http_->Get("/api/runs?batch_id=2", Bearer(kViewerToken));
  ASSERT_TRUE(other_batch);
  const Json none = Json::parse(other_batch->body);
  EXPECT_FALSE(none.contains("runs"));
  EXPECT_TRUE(none["headline"].empty());
}

// Issue 28: who is signed in, the downloads of every format the CLI writes (a missing value an empty CSV field,
// never "nan" or "null"), the import from the page with the dataset reader's field-named errors.
TEST_F(WebGatewayTest, SessionDownloadsAndImport) {
  auto who = http_->Get("/api/session", Bearer(kViewerToken));
  ASSERT_TRUE(who);
  ASSERT_EQ(who->status, 200) << who->body;
  EXPECT_EQ(Json::parse(who->body), (Json{{"user", "viewer"}, {"role", "viewer"}}));
  who = http_->Get("/api/session", Bearer(kOperatorToken));
  ASSERT_TRUE(who);
  EXPECT_EQ(Json::parse(who->body)["role"], "operator");
  auto stranger = http_->Get("/api/session", Bearer("not-a-token"));
  ASSERT_TRUE(stranger);
  EXPECT_EQ(stranger->status, 401) << stranger->body;

  // An open-loop run has no reference: its ref column is NaN in the store.
  Json spec = Json::parse(SpecFile("static-map.json"));
  spec.erase("sweep");
  spec.erase("variants");
  spec["duration_s"] = 0.05;
  spec["metric_window"] = {{"start_s", 0.0}, {"end_s", 0.05}};
  const Json sub = Submit(spec.dump());
  const std::string id = sub["run_ids"][0];
  ASSERT_EQ(WaitEnded(id)["run"]["status"], "DONE");
  auto csv = http_->Get("/api/runs/" + id + "/trace.csv", Bearer(kViewerToken));
  ASSERT_TRUE(csv);
  ASSERT_EQ(csv->status, 200);
  EXPECT_EQ(csv->body.find("nan"), std::string::npos);
  EXPECT_EQ(csv->body.find("null"), std::string::npos);
  std::istringstream lines(csv->body);
  std::string header, row;
  std::getline(lines, header);
  std::getline(lines, row);
  std::vector<std::string> names, cells;
  for (std::istringstream h(header); std::getline(h, names.emplace_back(), ',');) {
  }
  for (std::istringstream r(row); std::getline(r, cells.emplace_back(), ',');) {
  }
  const size_t ref = std::find(names.begin(), names.end(), "ref") - names.begin();
  ASSERT_LT(ref, names.size()) << header;
  EXPECT_EQ(cells.at(ref), "") << "no reference: an empty field\n" << header << "\n" << row;

  auto h5 = http_->Get("/api/runs/" + id + "/trace.h5", Bearer(kViewerToken));
  ASSERT_TRUE(h5);
  ASSERT_EQ(h5->status, 200) << h5->body;
  EXPECT_EQ(h5->get_header_value("Content-Type"), "application/x-hdf5");
  EXPECT_EQ(h5->body.substr(0, 8), std::string("\x89HDF\r\n\x1a\n", 8));
  auto mat = http_->Get("/api/runs/" + id + "/trace.mat", Bearer(kViewerToken));
  ASSERT_TRUE(mat);
  ASSERT_EQ(mat->status, 200) << mat->body;
  EXPECT_EQ(mat->body.rfind("MATLAB 5.0 MAT-file", 0), 0u);
  auto missing = http_->Get("/api/runs/999999/trace.h5", Bearer(kViewerToken));
  ASSERT_TRUE(missing);
  EXPECT_EQ(missing->status, 404) << missing->body;
  auto cmp = http_->Get("/api/compare.csv?runs=" + id, Bearer(kViewerToken));
  ASSERT_TRUE(cmp);
  ASSERT_EQ(cmp->status, 200) << cmp->body;
  EXPECT_EQ(cmp->body.rfind("rank,name,controller,runs,failed,pareto", 0), 0u) << cmp->body;
  EXPECT_EQ(cmp->body.find("nan"), std::string::npos) << cmp->body;
  auto report = http_->Get("/api/batches/" + std::string(sub["batch_id"]) + "/report.html", Bearer(kViewerToken));
  ASSERT_TRUE(report);
  ASSERT_EQ(report->status, 200) << report->body;
  EXPECT_NE(report->body.find("run " + id + ":"), std::string::npos);
  // Its charts are inline scripts: its CSP allows exactly those (issue 34: the dashboard's CSP blocked them).
  EXPECT_EQ(report->get_header_value_count("Content-Security-Policy"), 1u);
  EXPECT_EQ(report->get_header_value("Content-Security-Policy"), vb::web::ReportCsp(report->body));
  EXPECT_NE(report->get_header_value("Content-Security-Policy").find("'sha256-"), std::string::npos);

  // Import: field-named errors of the gateway and of the dataset reader, then the service's role check.
  auto post = [&](const Json& body, const char* token) {
    return http_->Post("/api/import", Bearer(token), body.dump(), "application/json");
  };
  auto no_manifest = post({{"dataset", "d1"}, {"files", {{"a.csv", "t_s,gate,i_A\n"}}}}, kOperatorToken);
  ASSERT_TRUE(no_manifest);
  EXPECT_EQ(no_manifest->status, 400);
  EXPECT_NE(no_manifest->body.find("files: no manifest.json"), std::string::npos) << no_manifest->body;
  auto escape = post({{"dataset", "d1"}, {"files", {{"../x.csv", ""}}}}, kOperatorToken);
  ASSERT_TRUE(escape);
  EXPECT_EQ(escape->status, 400);
  EXPECT_NE(escape->body.find("files['../x.csv']"), std::string::npos) << escape->body;
  auto bad_manifest = post({{"dataset", "d1"}, {"files", {{"manifest.json", R"({"format": "valve-runs/1"})"}}}}, kOperatorToken);
  ASSERT_TRUE(bad_manifest);
  EXPECT_EQ(bad_manifest->status, 400);
  EXPECT_NE(bad_manifest->body.find("d1/manifest.json"), std::string::npos) << bad_manifest->body;
  const std::string p07 = std::string(VB_SHARED_DIR) + "/gapbench/practice/p07";
  if (!std::filesystem::exists(p07 + "/manifest.json")) GTEST_SKIP() << "no " << p07;
  Json files = Json::object();
  for (const auto& e : std::filesystem::directory_iterator(p07)) files[e.path().filename().string()] = ReadFile(e.path());
  auto viewer = post({{"dataset", "p07"}, {"files", files}}, kViewerToken);
  ASSERT_TRUE(viewer);
  EXPECT_EQ(viewer->status, 403) << viewer->body;
  auto imported = post({{"dataset", "p07"}, {"files", files}}, kOperatorToken);
  ASSERT_TRUE(imported);
  ASSERT_EQ(imported->status, 201) << imported->body;
  EXPECT_EQ(Json::parse(imported->body)["run_ids"].size(), 12u);
}

TEST_F(WebGatewayTest, QueueListsRunningAndQueuedRunsInClaimOrder) {
  Json spec = Json::parse(SpecFile("standard/e3.json"));
  spec["realtime"] = true;
  spec["duration_s"] = 20;
  spec["bench"]["name"] = "emu-a";
  std::vector<std::string> ids;
  for (int k = 0; k < 3; ++k) ids.push_back(Submit(spec.dump())["run_ids"][0]);
  Json q;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (std::chrono::steady_clock::now() < until) {
    auto res = http_->Get("/api/queue", Bearer(kViewerToken));
    ASSERT_TRUE(res);
    ASSERT_EQ(res->status, 200) << res->body;
    q = Json::parse(res->body);
    if (q["running"].size() == 1 && q["running"][0]["eta_s"].is_number()) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  ASSERT_EQ(q["running"].size(), 1u) << q.dump();
  EXPECT_EQ(q["running"][0]["run"]["id"], ids[0]);
  EXPECT_GT(q["running"][0]["eta_s"].get<double>(), 5.0);
  ASSERT_EQ(q["queued"].size(), 2u);
  EXPECT_EQ(q["queued"][0]["position"], 1);
  EXPECT_EQ(q["queued"][0]["run"]["id"], ids[1]);
  EXPECT_EQ(q["queued"][1]["run"]["id"], ids[2]);
  for (const auto& id : ids) http_->Post("/api/runs/" + id + "/cancel", Bearer(kOperatorToken), "{}", "application/json");
}

}  // namespace

namespace {

// With the server's tls block, the dashboard is HTTPS with the same certificate (a client that trusts it gets
// in, a plaintext one does not) and its cookie is Secure.
TEST(WebTls, TheDashboardUsesTheServersCertificate) {
  const std::string dir = ::testing::TempDir() + "/web-tls";
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string gen = "openssl req -x509 -newkey rsa:2048 -nodes -days 2 -subj /CN=localhost "
                          "-addext subjectAltName=DNS:localhost,IP:127.0.0.1 -keyout " + dir + "/key.pem -out " +
                          dir + "/cert.pem > /dev/null 2>&1";
  ASSERT_EQ(std::system(gen.c_str()), 0) << "openssl is installed by scripts/setup.sh";
  vb::testing::ServerProcess server(
      dir, R"("tls": {"cert_file": "cert.pem", "key_file": "key.pem"}, "web": {"listen_address": "127.0.0.1:0"})");
  ASSERT_FALSE(server.Start().empty()) << server.Log();
  int port = 0;
  const auto until = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (port == 0 && std::chrono::steady_clock::now() < until) {
    const std::string log = server.Log();
    const std::string key = "web dashboard on https://127.0.0.1:";
    if (const auto at = log.find(key); at != std::string::npos) port = std::stoi(log.substr(at + key.size()));
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_GT(port, 0) << server.Log();
  httplib::SSLClient tls("127.0.0.1", port);
  tls.set_ca_cert_path(dir + "/cert.pem");
  tls.enable_server_certificate_verification(true);
  auto benches = tls.Get("/api/benches", Bearer(kViewerToken));
  ASSERT_TRUE(benches) << httplib::to_string(benches.error());
  EXPECT_EQ(benches->status, 200);
  EXPECT_EQ(benches->get_header_value("Strict-Transport-Security"), "max-age=31536000");
  // The door's checks hold under TLS too (the head is read by the door, the handshake as well).
  auto tab = tls.Get("/api/benches", {{"Authorization", "Bearer a\tb"}});
  ASSERT_TRUE(tab);
  EXPECT_EQ(tab->status, 401);
  auto kept = tls.Get("/api/benches", Bearer(kViewerToken));  // the same kept-alive connection
  ASSERT_TRUE(kept);
  EXPECT_EQ(kept->status, 200);
  auto login = tls.Post("/api/login", std::string(R"({"token": ")") + kViewerToken + "\"}", "application/json");
  ASSERT_TRUE(login);
  EXPECT_NE(login->get_header_value("Set-Cookie").find("; Secure"), std::string::npos);
  httplib::Client plain("127.0.0.1", port);
  plain.set_read_timeout(2, 0);
  auto refused = plain.Get("/api/benches", Bearer(kViewerToken));
  EXPECT_TRUE(!refused || refused->status != 200);
}

}  // namespace
