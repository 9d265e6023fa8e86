// Standard 5-field cron expressions ("minute hour day-of-month month day-of-week"), for the server's nightly
// suite. No Debian package ships a maintained C++ cron parser (croncpp and libcron are not packaged), so this is
// ours: numbers, '*', ranges a-b, steps */n and a-b/n, lists, month and weekday names (JAN, MON), 7 = Sunday,
// and Vixie cron's rule that when both day fields are restricted a day matching either fires.
#pragma once

#include <bitset>
#include <string>

#include "common/status.h"

namespace vb::regress {

// A civil time, minute resolution (no time zone: the caller picks local time or UTC).
struct CivilMinute {
  int year = 1970, month = 1, day = 1, hour = 0, minute = 0;  // month 1-12, day 1-31
  bool operator==(const CivilMinute&) const = default;
};
int DayOfWeek(int year, int month, int day);  // 0 = Sunday

class Cron {
 public:
  // Errors name the field: "cron 'x': hour: 25 is outside 0-23".
  static StatusOr<Cron> Parse(const std::string& expr);
  // The first minute strictly after `after` that matches. Searches up to ~5 years (an expression like
  // "0 0 31 2 *" never fires: NotFound).
  StatusOr<CivilMinute> Next(const CivilMinute& after) const;
  bool Matches(const CivilMinute& t) const;
  const std::string& expression() const { return expr_; }

  // Unix-time wrappers in local time (TZ) or UTC: the next firing strictly after unix_s, in unix seconds.
  StatusOr<double> NextUnix(double unix_s, bool utc) const;

 private:
  std::string expr_;
  std::bitset<60> minute_;
  std::bitset<24> hour_;
  std::bitset<32> dom_;   // 1-31
  std::bitset<13> month_; // 1-12
  std::bitset<7> dow_;    // 0-6
  bool dom_star_ = true, dow_star_ = true;
};

// "YYYY-MM-DD" of unix_s in local time or UTC: the tag of a night.
std::string DateOf(double unix_s, bool utc);

}  // namespace vb::regress
