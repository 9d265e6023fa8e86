// client/'s per-call credentials and the views more than one door builds (docs/client.md): the trace read chunk
// by chunk and as CSV, a run as an export file, a report's runs, waiting for a batch, a run key as JSON. Against
// the local service on its in-process channel (the BenchService itself, a store and the emulator).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "client/batch_wait.h"
#include "client/client.h"
#include "client/report_runs.h"
#include "client/run_file.h"
#include "client/run_key_json.h"
#include "client/trace_csv.h"
#include "client/trace_stream.h"
#include "experiment/spec.h"
#include "service/local_service.h"

namespace vb {
namespace {

namespace v1 = valvebench::v1;

// Two runs of 0.05 s (a sweep of the duty), one batch.
const char* kSweepSpec = R"({"name": "views/sweep", "duration_s": 0.05,
  "controller": {"open_loop_pwm": {"segments": [{"start_s": 0, "frequency_Hz": 100, "duty": 0.5}]}},
  "sweep": [{"field": "controller.open_loop_pwm.segments[0].duty", "values": [0.3, 0.6]}]})";

class ClientViews : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "/vb-client-views-" + std::to_string(::getpid());
    std::filesystem::remove_all(dir_);
    server::LocalServiceOptions o;
    o.store = dir_ + "/runs.db";
    auto s = server::LocalService::Start(o);
    ASSERT_TRUE(s.ok()) << s.status().message();
    service_ = std::move(*s);
    client::ClientOptions co;
    co.address = service_->Where();
    co.token = service_->token();
    client_ = std::make_unique<client::Client>(service_->InProcessChannel(), co);
    auto spec = experiment::ParseSpecJson(kSweepSpec);
    ASSERT_TRUE(spec.ok()) << spec.status().message();
    auto sub = client_->Submit(*spec, "views");
    ASSERT_TRUE(sub.ok()) << sub.status().message();
    batch_ = sub->batch_id();
    ids_.assign(sub->run_ids().begin(), sub->run_ids().end());
    ASSERT_EQ(ids_.size(), 2u);
    std::vector<std::int64_t> ended;
    auto st = client::WaitForRuns(*client_, ids_, 120.0, [&](std::int64_t id) { ended.push_back(id); });
    ASSERT_TRUE(st.ok()) << st.message();
    ASSERT_EQ(ended, ids_);
    for (auto id : ids_) {  // WaitForRuns returned: each has ended
      auto r = client_->GetRun(id);
      ASSERT_TRUE(r.ok());
      ASSERT_EQ(r->status(), v1::DONE) << r->reason();
    }
  }
  void TearDown() override {
    client_.reset();
    service_.reset();
    std::filesystem::remove_all(dir_);
  }

  std::string dir_;
  std::unique_ptr<server::LocalService> service_;
  std::unique_ptr<client::Client> client_;
  std::int64_t batch_ = 0;
  std::vector<std::int64_t> ids_;
};

// A view carries its own credentials over the shared channel, and keeps the service's status as it answered.
TEST_F(ClientViews, AViewCallsWithItsOwnCredentialsAndKeepsTheServiceStatus) {
  grpc::Status rpc;
  auto none = client_->With({std::string(), 10.0, &rpc}).GetRun(ids_[0]);
  ASSERT_FALSE(none.ok());
  EXPECT_EQ(rpc.error_code(), grpc::StatusCode::UNAUTHENTICATED) << rpc.error_message();
  EXPECT_NE(none.status().message().find("no token given"), std::string::npos) << none.status().message();
  auto wrong = client_->With({std::string("Bearer not-the-token"), 10.0, &rpc}).Benches();
  ASSERT_FALSE(wrong.ok());
  EXPECT_EQ(rpc.error_code(), grpc::StatusCode::UNAUTHENTICATED);
  auto right = client_->With({"Bearer " + service_->token(), 10.0, &rpc}).GetRun(ids_[0]);
  ASSERT_TRUE(right.ok()) << right.status().message();
  EXPECT_TRUE(rpc.ok());  // each call starts afresh
  auto missing = client_->With({"Bearer " + service_->token(), 10.0, &rpc}).GetRun(999999);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(rpc.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
}

// Read chunk by chunk, the trace is the one GetTrace gives whole; the CSV of both is the same text.
TEST_F(ClientViews, TheTraceStreamedAsCsvIsTheWholeTracesCsv) {
  auto whole = client_->GetTrace(ids_[0]);
  ASSERT_TRUE(whole.ok()) << whole.status().message();
  ASSERT_GT(whole->samples(), 10u);
  const std::string csv = client::TraceCsv(*whole);
  EXPECT_EQ(csv.rfind("t_s,gate,", 0), 0u) << csv.substr(0, 80);
  EXPECT_EQ(static_cast<std::size_t>(std::count(csv.begin(), csv.end(), '\n')), whole->samples() + 1);

  v1::GetTraceRequest r;
  r.set_run_id(ids_[0]);
  auto stream = client_->OpenTrace(r);
  ASSERT_TRUE(stream.ok()) << stream.status().message();
  const std::string path = dir_ + "/streamed.csv";
  std::FILE* f = std::fopen(path.c_str(), "w");
  ASSERT_NE(f, nullptr);
  const Status st = client::WriteTraceCsv(**stream, f, path);
  std::fclose(f);
  ASSERT_TRUE(st.ok()) << st.message();
  EXPECT_EQ((*stream)->rows().samples(), 0u);  // dropped as written
  std::ifstream in(path);
  const std::string streamed((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(streamed, csv);
  // The whole trace written in blocks: the same text again.
  const std::string whole_path = dir_ + "/whole.csv";
  std::FILE* w = std::fopen(whole_path.c_str(), "w");
  ASSERT_NE(w, nullptr);
  const Status wst = client::WriteTraceCsv(*whole, w, whole_path);
  std::fclose(w);
  ASSERT_TRUE(wst.ok()) << wst.message();
  std::ifstream win(whole_path);
  EXPECT_EQ(std::string((std::istreambuf_iterator<char>(win)), std::istreambuf_iterator<char>()), csv);

  v1::GetTraceRequest none;
  none.set_run_id(999999);
  auto refused = client_->OpenTrace(none);
  ASSERT_FALSE(refused.ok());  // the first chunk is read on opening: the refusal is the open's
  EXPECT_EQ(refused.status().code(), StatusCode::kNotFound);
}

// The export file: the run's identity in benchctl's words, t_s first with its unit, every channel's samples.
TEST_F(ClientViews, ARunsExportFileHasItsIdentityAndEveryChannel) {
  auto run = client_->GetRun(ids_[1]);
  ASSERT_TRUE(run.ok());
  auto f = client::FetchRunFile(*client_, *run);
  ASSERT_TRUE(f.ok()) << f.status().message();
  EXPECT_EQ(f->run_id, ids_[1]);
  EXPECT_EQ(f->name, run->name());
  EXPECT_EQ(f->status, "done");
  EXPECT_NE(f->spec_json.find("\"duration_s\""), std::string::npos);
  ASSERT_GE(f->channels.size(), 3u);
  EXPECT_EQ(f->channels[0].name, "t_s");
  EXPECT_EQ(f->channels[0].unit, "s");
  for (const auto& ch : f->channels) EXPECT_EQ(ch.values.size(), f->channels[0].values.size()) << ch.name;
  EXPECT_FALSE(f->metrics.empty());
  // A limit below the trace's size: refused, naming the run.
  auto small = client::FetchRunFile(*client_, *run, 16);
  ASSERT_FALSE(small.ok());
  EXPECT_EQ(small.status().code(), StatusCode::kResourceExhausted);
  EXPECT_NE(small.status().message().find("run " + std::to_string(ids_[1])), std::string::npos);
}

// The report's runs: every run of the batch in order with its spec; traces within the count and the size.
TEST_F(ClientViews, AReportsRunsComeWithTheirTracesWithinTheLimits) {
  auto all = client::FetchReportRuns(*client_, batch_, {}, {100, 0});
  ASSERT_TRUE(all.ok()) << all.status().message();
  ASSERT_EQ(all->runs.size(), 2u);
  EXPECT_EQ(all->runs[0].id, ids_[0]);
  EXPECT_EQ(all->runs[1].id, ids_[1]);
  EXPECT_EQ(all->traces_left_out, 0);
  for (const auto& r : all->runs) {
    EXPECT_FALSE(r.spec_json.empty());
    EXPECT_FALSE(r.trace.channels.empty());
    EXPECT_EQ(r.trace.label, "run " + std::to_string(r.id) + ": " + r.key.DisplayName());
  }
  EXPECT_EQ(client::BatchReportTitle(batch_, all->runs), "Batch " + std::to_string(batch_) + ": views");

  auto one = client::FetchReportRuns(*client_, batch_, {}, {1, 0});
  ASSERT_TRUE(one.ok());
  EXPECT_FALSE(one->runs[0].trace.channels.empty());
  EXPECT_TRUE(one->runs[1].trace.channels.empty());
  EXPECT_EQ(one->traces_left_out, 1);
  auto tiny = client::FetchReportRuns(*client_, batch_, {}, {100, 16});
  ASSERT_TRUE(tiny.ok());
  EXPECT_EQ(tiny->traces_left_out, 2);

  auto listed = client::FetchReportRuns(*client_, 0, {ids_[1]}, {});
  ASSERT_TRUE(listed.ok());
  ASSERT_EQ(listed->runs.size(), 1u);
  EXPECT_EQ(listed->runs[0].id, ids_[1]);
  auto missing = client::FetchReportRuns(*client_, 999999, {}, {});
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().message(), "batch 999999: no runs");
}

TEST(RunKeyJson, OneShapeWithSweepAndRepeat) {
  const RunKey key{"compare/pi", {{"conditions.supply_V", 12.5}}, 2};
  EXPECT_EQ(client::RunKeyJson(key).dump(),
            R"({"name":"compare/pi","sweep":[{"field":"conditions.supply_V","value":12.5}],"repeat":2})");
  EXPECT_EQ(client::RunKeyJson(NamedRun("e1")).dump(), R"({"name":"e1","sweep":[],"repeat":-1})");
}

// Read back (benchctl compare RESULTS.json): what RunKeyJson wrote is the same key; a member left out keeps its
// default; a malformed one is refused with its path.
TEST(RunKeyJson, ReadBackAndMalformedMembersNamed) {
  const RunKey key{"compare/pi", {{"conditions.supply_V", 12.5}, {"controller.pi.kp", 3.0}}, 2};
  auto back = client::RunKeyFromJson(nlohmann::json::parse(client::RunKeyJson(key).dump()), "r.json: [0].key", "x");
  ASSERT_TRUE(back.ok()) << back.status().message();
  EXPECT_EQ(*back, key);
  auto named = client::RunKeyFromJson(nlohmann::json::object(), "r.json: [0].key", "e1");
  ASSERT_TRUE(named.ok());
  EXPECT_EQ(*named, NamedRun("e1"));
  const std::pair<const char*, const char*> bad[] = {
      {R"([1])", "r.json: [0].key: not an object"},
      {R"({"name": 3})", "r.json: [0].key.name: not a string"},
      {R"({"repeat": 1.5})", "r.json: [0].key.repeat: not a repeat index"},
      {R"({"sweep": {"field": "a"}})", "r.json: [0].key.sweep: not an array"},
      {R"({"sweep": [{"field": "a", "value": 1}, {"field": "b"}]})", "r.json: [0].key.sweep[1].value: missing"},
      {R"({"sweep": [{"value": 1}]})", "r.json: [0].key.sweep[0].field: missing"},
  };
  for (const auto& [text, message] : bad) {
    auto k = client::RunKeyFromJson(nlohmann::json::parse(text), "r.json: [0].key", "e1");
    ASSERT_FALSE(k.ok()) << text;
    EXPECT_EQ(k.status().message().rfind(message, 0), 0u) << text << ": " << k.status().message();
  }
}

}  // namespace
}  // namespace vb
