#include <gtest/gtest.h>

#include "experiment/compare.h"

namespace vb::experiment {
namespace {

RunRecord R(const std::string& name, double rmse, double effort, bool ok = true) {
  RunRecord r;
  r.name = name;
  r.controller = name;
  r.ok = ok;
  r.metrics["rmse"] = rmse;
  r.metrics["effort_l2"] = effort;
  return r;
}

const CompareRow& Row(const Comparison& c, const std::string& name) {
  for (const auto& r : c.rows)
    if (r.name == name) return r;
  ADD_FAILURE() << "no row " << name;
  return c.rows.front();
}

TEST(Compare, RanksByRmseAndMarksTheParetoFront) {
  const Comparison c = Compare({R("a", 3.0, 1.0), R("b", 1.0, 3.0), R("c", 2.0, 2.0), R("d", 2.5, 2.5)});
  ASSERT_EQ(c.rows.size(), 4u);
  EXPECT_EQ(c.rows[0].name, "b");
  EXPECT_EQ(Row(c, "b").rank, 1);
  EXPECT_EQ(Row(c, "c").rank, 2);
  EXPECT_EQ(Row(c, "d").rank, 3);
  EXPECT_EQ(Row(c, "a").rank, 4);
  EXPECT_TRUE(Row(c, "a").pareto);
  EXPECT_TRUE(Row(c, "b").pareto);
  EXPECT_TRUE(Row(c, "c").pareto);
  EXPECT_FALSE(Row(c, "d").pareto) << "d is dominated by c";
}

TEST(Compare, DifferencesInsideTheRepeatSpreadAreNotRanked) {
  // x: 1.0 +/- ~0.14, y: 1.1 +/- ~0.14 -> same rank; z: 2.0 -> next rank.
  const Comparison c = Compare({R("x", 0.9, 1), R("x", 1.1, 1), R("x", 1.0, 1), R("y", 1.0, 1), R("y", 1.2, 1),
                                R("y", 1.1, 1), R("z", 2.0, 1), R("z", 2.0, 1)});
  EXPECT_EQ(Row(c, "x").runs, 3);
  EXPECT_NEAR(Row(c, "x").metrics.at("rmse").mean, 1.0, 1e-12);
  EXPECT_NEAR(Row(c, "x").metrics.at("rmse").spread, 0.1, 1e-12);
  EXPECT_EQ(Row(c, "x").rank, 1);
  EXPECT_EQ(Row(c, "y").rank, 1);
  EXPECT_EQ(Row(c, "z").rank, 2);
}

TEST(Compare, FailedRunsAreCountedNotAveraged) {
  const Comparison c = Compare({R("a", 1.0, 1.0), R("a", 99.0, 99.0, false)});
  EXPECT_EQ(Row(c, "a").failed, 1);
  EXPECT_NEAR(Row(c, "a").metrics.at("rmse").mean, 1.0, 1e-12);
  EXPECT_NE(ComparisonCsv(c).find("rank,name,controller"), std::string::npos);
  EXPECT_NE(ComparisonTable(c).find("Pareto"), std::string::npos);
}

TEST(Compare, CsvQuotesNamesSoCommasAndQuotesStayInTheirColumn) {
  const Comparison c = Compare({R("say \"hi\", then go", 1.0, 1.0)});
  const std::string csv = ComparisonCsv(c);
  EXPECT_NE(csv.find(",\"say \"\"hi\"\", then go\","), std::string::npos) << csv;
}

}  // namespace
}  // namespace vb::experiment
