// The one edit distance behind "did you mean" (common/edit_distance.h).
#include <gtest/gtest.h>

#include "common/edit_distance.h"

namespace vb {
namespace {

TEST(EditDistance, CountsInsertionsDeletionsAndSubstitutions) {
  EXPECT_EQ(EditDistance("", ""), 0u);
  EXPECT_EQ(EditDistance("abc", ""), 3u);
  EXPECT_EQ(EditDistance("", "abc"), 3u);
  EXPECT_EQ(EditDistance("suply_V", "supply_V"), 1u);     // an insertion
  EXPECT_EQ(EditDistance("metrcis", "metrics"), 2u);      // a swap is two substitutions
  EXPECT_EQ(EditDistance("kitten", "sitting"), 3u);
  EXPECT_EQ(EditDistance("sitting", "kitten"), 3u);       // symmetric
}

TEST(EditDistance, IgnoresCaseOnlyWhenAsked) {
  EXPECT_EQ(EditDistance("Supply_V", "supply_v"), 2u);
  EXPECT_EQ(EditDistance("Supply_V", "supply_v", /*ignore_case=*/true), 0u);
}

}  // namespace
}  // namespace vb
