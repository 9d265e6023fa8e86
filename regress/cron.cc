#include "regress/cron.h"

#include <fmt/format.h>
#include <cstdio>
#include <ctime>
#include <sstream>
#include <vector>

namespace vb::regress {
namespace {

struct FieldSpec {
  const char* name;
  int lo, hi;
  const char* const* names;  // optional symbolic names, names[0] is value lo (or 0 for weekdays)
  int names_count;
};

const char* const kMonths[] = {"JAN", "FEB", "MAR", "APR", "MAY", "JUN", "JUL", "AUG", "SEP", "OCT", "NOV", "DEC"};
const char* const kDays[] = {"SUN", "MON", "TUE", "WED", "THU", "FRI", "SAT"};

std::vector<std::string> Split(const std::string& s, char sep) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : s) {
    if (c == sep) {
      out.push_back(cur);
      cur.clear();
    } else {
      cur += c;
    }
  }
  out.push_back(cur);
  return out;
}

StatusOr<int> Value(const std::string& tok, const FieldSpec& f, int hi_allowed, const std::string& where) {
  if (tok.empty()) return Status::InvalidArgument(where + ": empty value");
  std::string up;
  for (char c : tok) up += static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  for (int k = 0; k < f.names_count; ++k)
    if (up == f.names[k]) return f.names == kMonths ? k + 1 : k;
  for (char c : tok)
    if (c < '0' || c > '9') return Status::InvalidArgument(where + ": '" + tok + "' is not a number");
  if (tok.size() > 4) return Status::InvalidArgument(where + ": '" + tok + "' is out of range");
  const int v = std::stoi(tok);
  if (v < f.lo || v > hi_allowed)
    return Status::InvalidArgument(where + ": " + tok + " is outside " + std::to_string(f.lo) + "-" +
                                   std::to_string(f.hi));
  return v;
}

// Sets bits [lo..hi] of the field from a comma list. Returns whether the field was '*' (unrestricted).
template <size_t N>
StatusOr<bool> ParseField(const std::string& text, const FieldSpec& f, std::bitset<N>* bits, const std::string& expr) {
  const std::string where = "cron '" + expr + "': " + f.name;
  const bool weekday = f.names == kDays;
  const int hi_allowed = weekday ? 7 : f.hi;  // 7 = Sunday too
  bool star = false;
  for (const std::string& item : Split(text, ',')) {
    if (item.empty()) return Status::InvalidArgument(where + ": empty list item in '" + text + "'");
    std::string range = item;
    int step = 1;
    if (const size_t slash = item.find('/'); slash != std::string::npos) {
      range = item.substr(0, slash);
      const std::string s = item.substr(slash + 1);
      if (s.empty() || s.find_first_not_of("0123456789") != std::string::npos || s.size() > 4 || std::stoi(s) < 1)
        return Status::InvalidArgument(where + ": step '" + s + "' must be a positive number");
      step = std::stoi(s);
    }
    int lo = f.lo, hi = f.hi;
    if (range == "*") {
      if (step == 1 && Split(text, ',').size() == 1) star = true;
    } else if (const size_t dash = range.find('-'); dash != std::string::npos) {
      auto a = Value(range.substr(0, dash), f, hi_allowed, where);
      if (!a.ok()) return a.status();
      auto b = Value(range.substr(dash + 1), f, hi_allowed, where);
      if (!b.ok()) return b.status();
      if (*a > *b) return Status::InvalidArgument(where + ": range '" + range + "' runs backwards");
      lo = *a;
      hi = *b;
    } else {
      auto a = Value(range, f, hi_allowed, where);
      if (!a.ok()) return a.status();
      lo = *a;
      hi = item.find('/') != std::string::npos ? f.hi : *a;  // "5/15" = from 5 every 15
    }
    for (int v = lo; v <= hi; v += step) bits->set(static_cast<size_t>(weekday && v == 7 ? 0 : v));
  }
  return star;
}

bool IsLeap(int y) { return (y % 4 == 0 && y % 100 != 0) || y % 400 == 0; }
int DaysIn(int y, int m) {
  static const int d[] = {31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31};
  return m == 2 && IsLeap(y) ? 29 : d[m - 1];
}

}  // namespace

int DayOfWeek(int y, int m, int d) {
  // Sakamoto's method.
  static const int t[] = {0, 3, 2, 5, 0, 3, 5, 1, 4, 6, 2, 4};
  if (m < 3) y -= 1;
  return (y + y / 4 - y / 100 + y / 400 + t[m - 1] + d) % 7;
}

StatusOr<Cron> Cron::Parse(const std::string& expr) {
  std::istringstream is(expr);
  std::vector<std::string> fields;
  for (std::string f; is >> f;) fields.push_back(f);
  if (fields.size() != 5)
    return Status::InvalidArgument("cron '" + expr + "': expected 5 fields (minute hour day-of-month month "
                                   "day-of-week), got " + std::to_string(fields.size()));
  Cron c;
  c.expr_ = expr;
  static const FieldSpec kMinute{"minute", 0, 59, nullptr, 0}, kHour{"hour", 0, 23, nullptr, 0},
      kDom{"day-of-month", 1, 31, nullptr, 0}, kMonth{"month", 1, 12, kMonths, 12},
      kDow{"day-of-week", 0, 6, kDays, 7};
  auto m = ParseField(fields[0], kMinute, &c.minute_, expr);
  if (!m.ok()) return m.status();
  auto h = ParseField(fields[1], kHour, &c.hour_, expr);
  if (!h.ok()) return h.status();
  auto dom = ParseField(fields[2], kDom, &c.dom_, expr);
  if (!dom.ok()) return dom.status();
  auto mon = ParseField(fields[3], kMonth, &c.month_, expr);
  if (!mon.ok()) return mon.status();
  auto dow = ParseField(fields[4], kDow, &c.dow_, expr);
  if (!dow.ok()) return dow.status();
  c.dom_star_ = *dom;
  c.dow_star_ = *dow;
  return c;
}

bool Cron::Matches(const CivilMinute& t) const {
  if (!minute_[t.minute] || !hour_[t.hour] || !month_[t.month]) return false;
  const bool dom_ok = dom_[t.day], dow_ok = dow_[DayOfWeek(t.year, t.month, t.day)];
  if (dom_star_ || dow_star_) return dom_ok && dow_ok;
  return dom_ok || dow_ok;
}

StatusOr<CivilMinute> Cron::Next(const CivilMinute& after) const {
  CivilMinute t = after;
  auto next_day = [&t] {
    t.hour = 0;
    t.minute = 0;
    if (++t.day > DaysIn(t.year, t.month)) {
      t.day = 1;
      if (++t.month > 12) {
        t.month = 1;
        ++t.year;
      }
    }
  };
  // One minute on.
  if (++t.minute == 60) {
    t.minute = 0;
    if (++t.hour == 24) {
      t.hour = 23;
      t.minute = 59;
      next_day();
    }
  }
  const int last_year = after.year + 5;
  while (t.year <= last_year) {
    if (!month_[t.month]) {
      t.day = DaysIn(t.year, t.month);
      next_day();
      continue;
    }
    const bool dom_ok = dom_[t.day], dow_ok = dow_[DayOfWeek(t.year, t.month, t.day)];
    const bool day_ok = (dom_star_ || dow_star_) ? dom_ok && dow_ok : dom_ok || dow_ok;
    if (!day_ok) {
      next_day();
      continue;
    }
    if (!hour_[t.hour]) {
      t.minute = 0;
      if (++t.hour == 24) next_day();
      continue;
    }
    if (!minute_[t.minute]) {
      if (++t.minute == 60) {
        t.minute = 0;
        if (++t.hour == 24) next_day();
      }
      continue;
    }
    return t;
  }
  return Status::NotFound("cron '" + expr_ + "': never fires within 5 years");
}

StatusOr<double> Cron::NextUnix(double unix_s, bool utc) const {
  const std::time_t now = static_cast<std::time_t>(unix_s);
  std::tm tm{};
  if (utc) {
    gmtime_r(&now, &tm);
  } else {
    localtime_r(&now, &tm);
  }
  CivilMinute c{tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday, tm.tm_hour, tm.tm_min};
  auto n = Next(c);
  if (!n.ok()) return n.status();
  std::tm out{};
  out.tm_year = n->year - 1900;
  out.tm_mon = n->month - 1;
  out.tm_mday = n->day;
  out.tm_hour = n->hour;
  out.tm_min = n->minute;
  out.tm_isdst = -1;
  return static_cast<double>(utc ? timegm(&out) : mktime(&out));
}

std::string DateOf(double unix_s, bool utc) {
  const std::time_t t = static_cast<std::time_t>(unix_s);
  std::tm tm{};
  if (utc) {
    gmtime_r(&t, &tm);
  } else {
    localtime_r(&t, &tm);
  }
  return fmt::format("{:04}-{:02}-{:02}", tm.tm_year + 1900, tm.tm_mon + 1, tm.tm_mday);
}

}  // namespace vb::regress
