// Listing runs (db/run_query.h, docs/store.md "Listing runs") on both engines: every order of order_by pages
// through 250 runs with ties in every key, each run exactly once and in order; the count of all matches; the name
// filter; page tokens refused with other filters or another order; a bad order_by names the field and lists the
// fields.
#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <set>
#include <string>
#include <vector>

#include "db/run_query.h"
#include "db/store.h"
#include "db/text.h"
#include "tests/db/store_engines.h"

namespace vb::db {
namespace {

constexpr int kRuns = 250;

class ListRunsTest : public testing::StoreEngineTest {
 protected:
  void SetUp() override {
    StoreEngineTest::SetUp();
    if (IsSkipped() || HasFatalFailure()) return;
    // Five batches of 50 (submitters and controllers differ by batch), names with repeats and mixed case.
    const char* submitters[] = {"alice", "bob", "Carol", "alice", "dave"};
    const char* controllers[] = {"pi_current", "bang_bang", "pi_current", "mpc", "Pi_current"};
    for (int b = 0; b < 5; ++b) {
      std::vector<RunRecord> runs;
      for (int k = 0; k < 50; ++k) {
        RunRecord r;
        const int n = b * 50 + k;
        r.key = NamedRun(Cat(n % 3 == 0 ? "Hold-" : "map-", n % 17, n % 2 == 0 ? "-Step" : "-ramp"));
        r.controller = controllers[b];
        r.bench_kind = "emulated";
        r.spec_json = "{}";
        if (n % 4 == 0) r.tags = {"nightly"};
        runs.push_back(r);
      }
      auto batch = store().SubmitBatch(submitters[b], "b", "{}", runs, nullptr);
      ASSERT_TRUE(batch.ok()) << batch.status().ToString();
    }
    // Times, statuses and benches with many ties, so that the id tie-break matters in every order.
    RawExec("UPDATE runs SET submitted = 1000 + (id % 37), "
            "started = CASE WHEN id % 5 = 0 THEN 0 ELSE 2000 + (id % 41) * 0.5 END, "
            "finished = CASE WHEN id % 5 = 0 OR id % 7 = 0 THEN 0 ELSE 2000 + (id % 41) * 0.5 + (id % 13) * 0.1 END, "
            "status = CASE id % 6 WHEN 0 THEN 'queued' WHEN 1 THEN 'running' WHEN 2 THEN 'done' WHEN 3 THEN 'failed' "
            "WHEN 4 THEN 'cancelled' ELSE 'interrupted' END, "
            "bench_name = CASE id % 3 WHEN 0 THEN 'bench-B' WHEN 1 THEN 'bench-a' ELSE '' END");
    RunFilter all;
    all.limit = 1000;
    auto runs = store().ListRuns(all);
    ASSERT_TRUE(runs.ok()) << runs.status().ToString();
    ASSERT_EQ(runs->size(), static_cast<std::size_t>(kRuns));
    all_ = *runs;
  }

  // Every run matching `f` through pages of `page` runs, continuing with page tokens as the API does.
  std::vector<RunRecord> PageThrough(RunFilter f, int page) {
    f.limit = page;
    std::vector<RunRecord> out;
    std::string token;
    for (int guard = 0; guard < 1000; ++guard) {
      RunFilter g = f;
      Status st = ApplyPageToken(token, &g);
      EXPECT_TRUE(st.ok()) << st.ToString();
      auto got = store().ListRuns(g);
      EXPECT_TRUE(got.ok()) << got.status().ToString();
      if (!got.ok()) break;
      out.insert(out.end(), got->begin(), got->end());
      if (static_cast<int>(got->size()) < page) break;
      token = EncodePageToken(f, got->back());
    }
    return out;
  }

  // The expected order, computed here from the runs' fields (byte order for text).
  std::vector<std::int64_t> Expected(const RunOrder& order, bool (*keep)(const RunRecord&) = nullptr) {
    std::vector<RunRecord> runs;
    for (const RunRecord& r : all_)
      if (keep == nullptr || keep(r)) runs.push_back(r);
    std::stable_sort(runs.begin(), runs.end(), [&](const RunRecord& a, const RunRecord& b) {
      const RunCursor ca = CursorAfter(a, order), cb = CursorAfter(b, order);
      const int key = ca.text != cb.text ? (ca.text < cb.text ? -1 : 1)
                      : ca.number != cb.number ? (ca.number < cb.number ? -1 : 1)
                                               : 0;
      const int c = key != 0 ? key : (a.id < b.id ? -1 : a.id > b.id ? 1 : 0);
      return order.desc ? c > 0 : c < 0;
    });
    std::vector<std::int64_t> ids;
    for (const RunRecord& r : runs) ids.push_back(r.id);
    return ids;
  }

  static std::vector<std::int64_t> Ids(const std::vector<RunRecord>& runs) {
    std::vector<std::int64_t> ids;
    for (const RunRecord& r : runs) ids.push_back(r.id);
    return ids;
  }

  std::vector<RunRecord> all_;
};
INSTANTIATE_TEST_SUITE_P(Engines, ListRunsTest, ::testing::ValuesIn(testing::StoreEngines()), testing::EngineName);

TEST_P(ListRunsTest, EveryOrderPagesThroughEachRunExactlyOnceInOrder) {
  for (std::string_view field : RunSortFields()) {
    for (const char* dir : {"", " desc"}) {
      const std::string text = Cat(field, dir);
      auto order = ParseRunOrder(text);
      ASSERT_TRUE(order.ok()) << order.status().ToString();
      EXPECT_EQ(RunOrderText(*order), text);
      RunFilter f;
      f.order = *order;
      const std::vector<RunRecord> got = PageThrough(f, 7);
      const std::vector<std::int64_t> ids = Ids(got);
      EXPECT_EQ(std::set<std::int64_t>(ids.begin(), ids.end()).size(), static_cast<std::size_t>(kRuns))
          << text << ": every run exactly once";
      EXPECT_EQ(ids, Expected(*order)) << text;
    }
  }
}

TEST_P(ListRunsTest, DefaultOrderIsNewestFirstAndPagesWithFiltersToo) {
  auto order = ParseRunOrder("");
  ASSERT_TRUE(order.ok());
  EXPECT_EQ(RunOrderText(*order), "submitted desc");
  RunFilter f;
  f.order = *order;
  f.name = "hold";  // contains, ASCII case-insensitive: matches "Hold-..."
  f.status = RunStatus::kCancelled;
  const auto keep = [](const RunRecord& r) {
    return r.key.DisplayName().rfind("Hold-", 0) == 0 && r.status == RunStatus::kCancelled;
  };
  const std::vector<std::int64_t> expected = Expected(*order, keep);
  ASSERT_GT(expected.size(), 5u);
  EXPECT_EQ(Ids(PageThrough(f, 4)), expected);
  auto total = store().CountRuns(f);
  ASSERT_TRUE(total.ok()) << total.status().ToString();
  EXPECT_EQ(*total, static_cast<std::int64_t>(expected.size()));
  // The newest first: the first run has the largest submission time.
  f.limit = 1;
  auto first = store().ListRuns(f);
  ASSERT_TRUE(first.ok());
  for (const RunRecord& r : all_)
    if (keep(r)) {
      EXPECT_LE(r.submitted_unix_s, first->front().submitted_unix_s);
    }
}

TEST_P(ListRunsTest, TotalCountsEveryMatchOnEveryPage) {
  RunFilter f;
  f.limit = 10;
  auto total = store().CountRuns(f);
  ASSERT_TRUE(total.ok()) << total.status().ToString();
  EXPECT_EQ(*total, kRuns);
  f.after = CursorAfter(all_[100], f.order);  // the cursor does not change the count
  total = store().CountRuns(f);
  ASSERT_TRUE(total.ok());
  EXPECT_EQ(*total, kRuns);
  f.name = "STEP";
  f.submitter = "alice";
  f.tag = "nightly";
  std::int64_t expected = 0;
  for (const RunRecord& r : all_)
    expected += r.key.DisplayName().find("-Step") != std::string::npos && r.submitter == "alice" &&
                std::find(r.tags.begin(), r.tags.end(), "nightly") != r.tags.end();
  ASSERT_GT(expected, 0);
  total = store().CountRuns(f);
  ASSERT_TRUE(total.ok());
  EXPECT_EQ(*total, expected);
  f.name = "no run has this name";
  total = store().CountRuns(f);
  ASSERT_TRUE(total.ok());
  EXPECT_EQ(*total, 0);
}

TEST_P(ListRunsTest, ATokenIsRefusedWithOtherFiltersOrAnotherOrder) {
  RunFilter f;
  f.order = RunOrder{RunSortKey::kName, false};
  f.limit = 10;
  auto page = store().ListRuns(f);
  ASSERT_TRUE(page.ok());
  const std::string token = EncodePageToken(f, page->back());
  RunFilter same = f;
  same.limit = 50;  // the page size may change
  EXPECT_TRUE(ApplyPageToken(token, &same).ok());
  ASSERT_TRUE(same.after.has_value());
  auto next = store().ListRuns(same);
  ASSERT_TRUE(next.ok());
  EXPECT_EQ(next->front().id, Expected(f.order)[10]);

  for (const auto& change : std::vector<std::function<void(RunFilter*)>>{
           [](RunFilter* g) { g->name = "hold"; }, [](RunFilter* g) { g->order.desc = true; },
           [](RunFilter* g) { g->order.key = RunSortKey::kSubmitted; }, [](RunFilter* g) { g->controller = "mpc"; },
           [](RunFilter* g) { g->status = RunStatus::kDone; }, [](RunFilter* g) { g->submitted_after_unix_s = 1; }}) {
    RunFilter other = f;
    change(&other);
    const Status st = ApplyPageToken(token, &other);
    ASSERT_FALSE(st.ok());
    EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(st.message().rfind("page_token: ", 0), 0u) << st.message();
    EXPECT_FALSE(other.after.has_value());
  }
  for (const char* junk : {"12", "not a token!", "cjE"}) {
    RunFilter g = f;
    const Status st = ApplyPageToken(junk, &g);
    EXPECT_EQ(st.code(), StatusCode::kInvalidArgument) << junk;
    EXPECT_EQ(st.message().rfind("page_token: ", 0), 0u) << st.message();
  }
}

TEST(RunOrderTest, ABadOrderByNamesTheFieldAndListsTheFields) {
  for (const char* bad : {"newest", "submitted descending", "name, id", "name asc desc", "Submitted"}) {
    auto order = ParseRunOrder(bad);
    ASSERT_FALSE(order.ok()) << bad;
    EXPECT_EQ(order.status().code(), StatusCode::kInvalidArgument);
    const std::string& m = order.status().message();
    EXPECT_EQ(m.rfind("order_by: ", 0), 0u) << m;
    EXPECT_NE(m.find("id, submitted, started, finished, duration, name, status, bench, controller, submitter"),
              std::string::npos)
        << m;
  }
  auto asc = ParseRunOrder("  finished asc ");
  ASSERT_TRUE(asc.ok());
  EXPECT_EQ(RunOrderText(*asc), "finished");
}

}  // namespace
}  // namespace vb::db
