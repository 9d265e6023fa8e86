// The one way CSV writers say "no value" (common/csv.h; docs/cli.md "Missing values").
#include "common/csv.h"

#include <gtest/gtest.h>

#include <limits>

namespace vb {
namespace {

TEST(CsvNumber, NaNIsAnEmptyFieldInfinitiesAreSpelledNumbersKeepTenDigits) {
  EXPECT_EQ(CsvNumber(std::numeric_limits<double>::quiet_NaN()), "");
  EXPECT_EQ(CsvNumber(std::numeric_limits<double>::infinity()), "inf");
  EXPECT_EQ(CsvNumber(-std::numeric_limits<double>::infinity()), "-inf");
  EXPECT_EQ(CsvNumber(0.0), "0");
  EXPECT_EQ(CsvNumber(0.00053751234567), "0.0005375123457");
  EXPECT_EQ(CsvNumber(1.0 / 3.0, 4), "0.3333");
  std::string row = "t";
  row += ',';
  AppendCsvNumber(&row, std::numeric_limits<double>::quiet_NaN());
  row += ',';
  AppendCsvNumber(&row, 2.5);
  EXPECT_EQ(row, "t,,2.5");
}

}  // namespace
}  // namespace vb
