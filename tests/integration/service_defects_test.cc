// Issue 14's smaller defects in the service (server/service.cc), on a real server: each test failed before
// its fix. WatchRun honours sample_rate_Hz (0 = none) and sends the reference; an unknown ListRuns status
// filter is refused instead of matching every run; CompareRuns caps the number of ids.
#include <gtest/gtest.h>

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <cmath>
#include <filesystem>
#include <thread>

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

#include "client/client.h"
#include "service/auth.h"
#include "server/config.h"
#include "experiment/spec.h"
#include "server_process.h"

namespace vb {
namespace {

namespace v1 = valvebench::v1;
using testing::ServerProcess;

std::string TempDir(const std::string& name) {
  const std::string d = ::testing::TempDir() + "/vb-defects-" + name + "-" + std::to_string(::getpid());
  std::filesystem::remove_all(d);
  return d;
}

client::Client MakeClient(const std::string& address) {
  client::ClientOptions o;
  o.address = address;
  o.token = testing::kOperatorToken;
  o.deadline_s = 20.0;
  return client::Client(o);
}

// A paced (wall-clock) PI current run on the seed-001 profile: 0.9 A for 6 ms, then 0.5 A.
v1::ExperimentSpec PacedCurrentRun(double duration_s) {
  auto s = experiment::ParseSpecJson(R"({"name": "live", "duration_s": )" + std::to_string(duration_s) + R"(,
      "realtime": true, "conditions": {"supply_V": 24, "supply_pressure_Pa": 400000},
      "reference": {"on_off_profile": {"switching_value": 0.9, "switching_time_s": 0.006, "holding_value": 0.5}},
      "controller": {"pi_current": {}}, "recording": {"rate_Hz": 10000}})");
  EXPECT_TRUE(s.ok()) << s.status().message();
  return *s;
}

TEST(ServiceDefects, WatchRunHonoursTheSampleRateAndSendsTheReference) {
  ServerProcess server(TempDir("watch"));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto c = MakeClient(addr);
  auto watch = [&](double rate_Hz, std::vector<v1::LiveSample>* samples) {
    auto sub = c.Submit(PacedCurrentRun(1.0));
    ASSERT_TRUE(sub.ok()) << sub.status().message();
    auto st = c.Watch(sub->run_ids(0), 30.0, rate_Hz, [&](const v1::RunEvent& ev) {
      for (const auto& s : ev.samples()) samples->push_back(s);
      return ev.status() != v1::DONE && ev.status() != v1::FAILED && ev.status() != v1::CANCELLED;
    });
    ASSERT_TRUE(st.ok()) << st.message();
  };
  std::vector<v1::LiveSample> none, slow;
  watch(0.0, &none);
  EXPECT_EQ(none.size(), 0u) << "sample_rate_Hz 0 means no live samples";
  watch(10.0, &slow);
  // 10 Hz over a 1 s run: about 10 (the stream starts when the watch does), never the tap's 1 kHz.
  EXPECT_GE(slow.size(), 3u);
  EXPECT_LE(slow.size(), 12u);
  for (std::size_t k = 1; k < slow.size(); ++k) EXPECT_GE(slow[k].t_s() - slow[k - 1].t_s(), 0.1 - 1e-9);
  for (const auto& s : slow) EXPECT_EQ(s.ref(), s.t_s() < 0.006 ? 0.9 : 0.5) << "t = " << s.t_s();

  auto bad = c.Watch(1, 5.0, std::nan(""), [](const v1::RunEvent&) { return false; });
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad.message().find("sample_rate_Hz"), std::string::npos) << bad.message();
}

TEST(ServiceDefects, UnknownStatusFilterAndTooManyCompareIdsAreRefusedNamingTheField) {
  ServerProcess server(TempDir("filters"));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto c = MakeClient(addr);
  v1::ListRunsRequest req;
  req.set_status(static_cast<v1::RunStatus>(42));
  auto listed = c.ListRuns(req);
  ASSERT_FALSE(listed.ok()) << "an unknown status filter returned " << listed->runs_size() << " runs";
  EXPECT_EQ(listed.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(listed.status().message().find("status: unknown run status 42"), std::string::npos)
      << listed.status().message();
  req.set_status(v1::RUN_STATUS_UNSPECIFIED);  // "any" stays allowed
  EXPECT_TRUE(c.ListRuns(req).ok());

  std::vector<std::int64_t> ids(1001);
  for (std::size_t k = 0; k < ids.size(); ++k) ids[k] = static_cast<std::int64_t>(k + 1);
  auto compared = c.Compare(0, ids);
  ASSERT_FALSE(compared.ok());
  EXPECT_EQ(compared.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(compared.status().message().find("run_ids: at most 1000"), std::string::npos)
      << compared.status().message();
}

// grpc.health.v1.Health/Check by hand (no generated health stubs here): HealthCheckRequest{service = name} is
// field 1 as a length-delimited string; the response's status SERVING is field 1 = 1, bytes 08 01.
StatusOr<std::string> HealthCheck(const std::string& address, const std::string& service) {
  auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  grpc::GenericStub stub(channel);
  std::string request;
  if (!service.empty()) {
    request.push_back('\x0a');
    request.push_back(static_cast<char>(service.size()));
    request += service;
  }
  grpc::Slice slice(request);
  grpc::ByteBuffer in(&slice, 1), out;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(5));
  std::mutex mu;
  std::condition_variable cv;
  bool done = false;
  grpc::Status status;
  stub.UnaryCall(&ctx, "/grpc.health.v1.Health/Check", grpc::StubOptions(), &in, &out, [&](grpc::Status s) {
    std::lock_guard<std::mutex> lock(mu);
    status = s;
    done = true;
    cv.notify_one();
  });
  std::unique_lock<std::mutex> lock(mu);
  cv.wait(lock, [&] { return done; });
  if (!status.ok()) return Status::NotFound(std::to_string(status.error_code()) + " " + status.error_message());
  std::vector<grpc::Slice> slices;
  (void)out.Dump(&slices);
  std::string bytes;
  for (const auto& s : slices) bytes.append(reinterpret_cast<const char*>(s.begin()), s.size());
  return bytes;
}

TEST(ServiceDefects, HealthAnswersServingForTheServiceByName) {
  ServerProcess server(TempDir("health"));
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  auto overall = HealthCheck(addr, "");
  ASSERT_TRUE(overall.ok()) << overall.status().message();
  EXPECT_EQ(*overall, std::string("\x08\x01"));
  auto by_name = HealthCheck(addr, "valvebench.v1.BenchService");
  ASSERT_TRUE(by_name.ok()) << "health by service name: " << by_name.status().message();
  EXPECT_EQ(*by_name, std::string("\x08\x01"));
  EXPECT_FALSE(HealthCheck(addr, "no.such.Service").ok());
}

TEST(ServerConfig, PerUserDiskBudgetIsMappedAndValidated) {
  valvebench::v1::ServerConfig c = testing::MinimalConfig();
  auto none = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(none.ok()) << none.status().message();
  EXPECT_TRUE(std::isinf(none->AdmitPolicy().limits.max_disk_bytes_per_user));  // 0 / absent: no limit
  c.mutable_limits()->set_max_disk_mb_per_user(250);
  auto set = server::SettingsFromConfig(c, "");
  ASSERT_TRUE(set.ok()) << set.status().message();
  EXPECT_EQ(set->AdmitPolicy().limits.max_disk_bytes_per_user, 250e6);
  c.mutable_limits()->set_max_disk_mb_per_user(-1);
  auto bad = server::SettingsFromConfig(c, "");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("limits.max_disk_MB_per_user"), std::string::npos) << bad.status().message();
}

}  // namespace
}  // namespace vb
