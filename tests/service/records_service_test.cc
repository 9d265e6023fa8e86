// Baselines, regression results and the store's description through the service (service/records_service.cc),
// called with client::Client on a hosted BenchService with three tokens, on both engines (SQLite, and a throwaway
// PostgreSQL server where one can start: tests/db/pg_server.h): versions, who may save, and bad input answered
// with the field or record it concerns.
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>

#include "client/client.h"
#include "tests/db/pg_server.h"
#include "service/hosting.h"
#include "service/service.h"

namespace vb::server {
namespace {

namespace v1 = valvebench::v1;

constexpr const char* kViewer = "viewer-secret";
constexpr const char* kOperator = "operator-secret";

Authenticator TwoRoles() {
  google::protobuf::RepeatedPtrField<v1::TokenConfig> tokens;
  for (const auto& [user, role, token] :
       {std::tuple{"vera", "viewer", kViewer}, std::tuple{"olga", "operator", kOperator}}) {
    auto* t = tokens.Add();
    t->set_user(user);
    t->set_role(role);
    t->set_token_sha256(Sha256Hex(token));
  }
  auto a = Authenticator::Create(tokens);
  EXPECT_TRUE(a.ok()) << a.status().message();
  return std::move(*a);
}

regress::Baseline Sample(const std::string& name, double rmse) {
  regress::Baseline b;
  b.name = name;
  b.source = "local batch 3";
  b.note = "from the test";
  b.cases["hold/pi"]["rmse"] = {rmse, 1e-5, 3};
  b.cases["hold/pi"]["energy_J"] = {0.25, 0.0, 3};
  b.cases["hold/pi"]["overshoot"] = {0.0, 0.0, 0};  // no finite value in any repeat: not kept
  return b;
}

class RecordsService : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "/vb-records-" + std::to_string(::getpid()) + "-" + GetParam();
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
    std::string location = dir_ + "/runs.db";
    if (GetParam() == "postgresql") {
      auto* pg = db::testing::PgServer::Get();
      if (pg == nullptr) GTEST_SKIP() << "PostgreSQL cannot start here: " << db::testing::PgServer::WhyUnavailable();
      auto db = pg->CreateDatabase();
      ASSERT_TRUE(db.ok()) << db.status().message();
      location = *db;
    }
    settings_.auth = TwoRoles();
    pool_ = std::make_unique<StorePool>(location);
    service_ = std::make_unique<BenchServiceImpl>(&settings_, pool_.get(), &registry_, &workers_);
    grpc::ServerBuilder builder;
    HostService(&builder, service_.get());
    server_ = builder.BuildAndStart();
    ASSERT_NE(server_, nullptr);
    client::ClientOptions o;
    o.address = "records test";
    o.token = kOperator;
    operator_ = std::make_unique<client::Client>(server_->InProcessChannel(InProcessChannelArguments()), o);
    o.token = kViewer;
    viewer_ = std::make_unique<client::Client>(server_->InProcessChannel(InProcessChannelArguments()), o);
  }
  void TearDown() override {
    if (server_) server_->Shutdown(std::chrono::system_clock::now());
    std::filesystem::remove_all(dir_);
  }

  std::string dir_;
  ServiceSettings settings_;
  std::unique_ptr<StorePool> pool_;
  runs::Registry registry_;
  std::vector<std::unique_ptr<runs::Worker>> workers_;
  std::unique_ptr<BenchServiceImpl> service_;
  std::unique_ptr<grpc::Server> server_;
  std::unique_ptr<client::Client> operator_, viewer_;
};

TEST_P(RecordsService, BaselinesAreVersionedAndReadBackAsSaved) {
  auto v1 = operator_->SaveBaseline(Sample("main", 8.3e-4));
  ASSERT_TRUE(v1.ok()) << v1.status().message();
  EXPECT_EQ(v1->version, 1);
  EXPECT_GT(v1->created_unix_s, 1.7e9);
  EXPECT_EQ(v1->source, "local batch 3");
  EXPECT_EQ(v1->note, "from the test");
  ASSERT_EQ(v1->cases.count("hold/pi"), 1u);
  EXPECT_EQ(v1->cases.at("hold/pi").size(), 2u) << "a metric with n = 0 is not a baseline value";
  EXPECT_DOUBLE_EQ(v1->cases.at("hold/pi").at("rmse").mean, 8.3e-4);
  EXPECT_DOUBLE_EQ(v1->cases.at("hold/pi").at("rmse").spread, 1e-5);
  EXPECT_EQ(v1->cases.at("hold/pi").at("rmse").n, 3);

  auto v2 = operator_->SaveBaseline(Sample("main", 9.1e-4));
  ASSERT_TRUE(v2.ok()) << v2.status().message();
  EXPECT_EQ(v2->version, 2) << "a second save under a name is its next version, never an overwrite";

  // Read by the viewer: the newest by default, an older one by number.
  auto newest = viewer_->GetBaseline("main");
  ASSERT_TRUE(newest.ok()) << newest.status().message();
  EXPECT_EQ(newest->version, 2);
  EXPECT_DOUBLE_EQ(newest->cases.at("hold/pi").at("rmse").mean, 9.1e-4);
  auto first = viewer_->GetBaseline("main", 1);
  ASSERT_TRUE(first.ok()) << first.status().message();
  EXPECT_DOUBLE_EQ(first->cases.at("hold/pi").at("rmse").mean, 8.3e-4);

  ASSERT_TRUE(operator_->SaveBaseline(Sample("other", 1e-3)).ok());
  auto list = viewer_->ListBaselines();
  ASSERT_TRUE(list.ok()) << list.status().message();
  ASSERT_EQ(list->size(), 3u);
  EXPECT_EQ((*list)[0].name, "main");
  EXPECT_EQ((*list)[0].version, 1);
  EXPECT_EQ((*list)[1].version, 2);
  EXPECT_EQ((*list)[2].name, "other");
  EXPECT_TRUE((*list)[0].cases.empty()) << "listings carry no values";

  auto info = viewer_->DescribeStore();
  ASSERT_TRUE(info.ok()) << info.status().message();
  EXPECT_EQ(info->engine(), GetParam());
  EXPECT_GE(info->schema_version(), 5);
  bool counted = false;
  for (const auto& c : info->rows())
    if (c.name() == "baselines") {
      counted = true;
      EXPECT_EQ(c.count(), 3);
    }
  EXPECT_TRUE(counted) << info->DebugString();
  EXPECT_FALSE(info->runs_by_status().empty());
}

TEST_P(RecordsService, RegressionResultsAreKeptWholeAndReadBack) {
  regress::RegressResult r;
  r.suite = "ci";
  r.baseline_name = "main";
  r.baseline_version = 2;
  r.where = "local";
  r.seed = 7;
  regress::Finding f;
  f.case_name = "hold/pi";
  f.metric = "rmse";
  f.verdict = regress::Verdict::kRegressed;
  f.baseline = {8e-4, 1e-5, 3};
  f.now = {4e-3, 1e-5, 3};
  f.delta = 3.2e-3;
  f.message = "rmse regressed: baseline 0.0008 A, now 0.004 A";
  r.findings.push_back(f);
  auto id = operator_->SaveRegression(r);
  ASSERT_TRUE(id.ok()) << id.status().message();
  EXPECT_GE(*id, 1);

  auto back = viewer_->GetRegression(*id);
  ASSERT_TRUE(back.ok()) << back.status().message();
  EXPECT_EQ(back->id(), *id);
  EXPECT_EQ(back->suite(), "ci");
  EXPECT_EQ(back->baseline_name(), "main");
  EXPECT_EQ(back->baseline_version(), 2);
  EXPECT_EQ(back->verdict(), "regressed") << "the verdict is the service's reading of the findings";
  EXPECT_EQ(back->night(), "");
  auto j = regress::Json::parse(back->result_json(), nullptr, false);
  ASSERT_FALSE(j.is_discarded()) << back->result_json();
  auto parsed = regress::ResultFromJson(j);
  ASSERT_TRUE(parsed.ok()) << parsed.status().message();
  ASSERT_EQ(parsed->findings.size(), 1u);
  EXPECT_EQ(parsed->findings[0].message, f.message);
  EXPECT_EQ(parsed->seed, 7u);
}

// A viewer reads but cannot add to the store's history; nothing is written by the refused calls.
TEST_P(RecordsService, AReadOnlyTokenCannotSave) {
  auto refused = viewer_->SaveBaseline(Sample("main", 8e-4));
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("permission denied"), std::string::npos) << refused.status().message();
  EXPECT_NE(refused.status().message().find("needs the operator role"), std::string::npos)
      << refused.status().message();
  regress::RegressResult r;
  r.suite = "ci";
  auto refused_result = viewer_->SaveRegression(r);
  ASSERT_FALSE(refused_result.ok());
  EXPECT_NE(refused_result.status().message().find("needs the operator role"), std::string::npos)
      << refused_result.status().message();
  auto list = viewer_->ListBaselines();
  ASSERT_TRUE(list.ok()) << list.status().message();
  EXPECT_TRUE(list->empty());
  EXPECT_EQ(viewer_->GetRegression(1).status().code(), StatusCode::kNotFound);
}

TEST_P(RecordsService, BadInputNamesTheFieldOrTheRecord) {
  auto no_name = operator_->SaveBaseline(Sample("", 8e-4));
  EXPECT_EQ(no_name.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(no_name.status().message().find("baseline.name: must not be empty"), std::string::npos)
      << no_name.status().message();
  regress::Baseline bad = Sample("main", 8e-4);
  bad.cases["hold/pi"]["rmse"].spread = -1.0;
  auto bad_spread = operator_->SaveBaseline(bad);
  EXPECT_EQ(bad_spread.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad_spread.status().message().find("baseline.entries["), std::string::npos)
      << bad_spread.status().message();
  EXPECT_NE(bad_spread.status().message().find("].spread: must be finite and >= 0"), std::string::npos)
      << bad_spread.status().message();
  regress::Baseline empty = Sample("main", 8e-4);
  empty.cases.clear();
  EXPECT_EQ(operator_->SaveBaseline(empty).status().code(), StatusCode::kInvalidArgument);

  ASSERT_TRUE(operator_->SaveBaseline(Sample("main", 8e-4)).ok());
  auto get_no_name = viewer_->GetBaseline("");
  EXPECT_EQ(get_no_name.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(get_no_name.status().message().find("name: must not be empty"), std::string::npos)
      << get_no_name.status().message();
  auto v9 = viewer_->GetBaseline("main", 9);
  EXPECT_EQ(v9.status().code(), StatusCode::kNotFound);
  EXPECT_NE(v9.status().message().find("baseline 'main' has no version 9"), std::string::npos)
      << v9.status().message();
  auto negative = viewer_->GetBaseline("main", -1);
  EXPECT_EQ(negative.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(negative.status().message().find("version: must be >= 1"), std::string::npos)
      << negative.status().message();
  auto nope = viewer_->GetBaseline("nope");
  EXPECT_EQ(nope.status().code(), StatusCode::kNotFound);
  EXPECT_NE(nope.status().message().find("baseline 'nope' not found"), std::string::npos) << nope.status().message();

  auto id0 = viewer_->GetRegression(0);
  EXPECT_EQ(id0.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(id0.status().message().find("id: must be >= 1"), std::string::npos) << id0.status().message();
  auto unknown = viewer_->GetRegression(99);
  EXPECT_EQ(unknown.status().code(), StatusCode::kNotFound);
  EXPECT_NE(unknown.status().message().find("regression 99 not found"), std::string::npos)
      << unknown.status().message();

  // What a client sends as a result: no suite, a batch this store does not have, text that is not JSON (the
  // raw stub: client::Client always sends regress::ResultToJson's).
  regress::RegressResult no_suite;
  auto r1 = operator_->SaveRegression(no_suite);
  EXPECT_EQ(r1.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r1.status().message().find("result_json.suite: must not be empty"), std::string::npos)
      << r1.status().message();
  regress::RegressResult elsewhere;
  elsewhere.suite = "ci";
  elsewhere.batch_id = 42;
  auto r2 = operator_->SaveRegression(elsewhere);
  EXPECT_EQ(r2.status().code(), StatusCode::kNotFound);
  EXPECT_NE(r2.status().message().find("result_json.batch_id: batch 42 has no runs in this store"),
            std::string::npos)
      << r2.status().message();
  auto stub = v1::BenchService::NewStub(server_->InProcessChannel(InProcessChannelArguments()));
  for (const auto& [text, expected] : {std::pair{"{not json", "result_json: not JSON"},
                                       std::pair{R"({"suite": "ci"})", "result_json: regression result: expected"},
                                       std::pair{R"({"suite": 3, "findings": []})", "result_json: not a regression"},
                                       std::pair{"", "result_json: must not be empty"}}) {
    grpc::ClientContext ctx;
    ctx.AddMetadata("authorization", std::string("Bearer ") + kOperator);
    v1::SaveRegressionRequest req;
    req.set_result_json(text);
    v1::SaveRegressionResponse resp;
    auto st = stub->SaveRegression(&ctx, req, &resp);
    EXPECT_EQ(st.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << text << ": " << st.error_message();
    EXPECT_NE(st.error_message().find(expected), std::string::npos) << text << ": " << st.error_message();
  }
  EXPECT_EQ(viewer_->GetRegression(1).status().code(), StatusCode::kNotFound) << "nothing refused was kept";
}

INSTANTIATE_TEST_SUITE_P(Engines, RecordsService, ::testing::Values("sqlite", "postgresql"),
                         [](const ::testing::TestParamInfo<std::string>& info) { return info.param; });

}  // namespace
}  // namespace vb::server
