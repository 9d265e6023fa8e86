#include "regress/compare.h"

#include <fmt/format.h>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <sstream>

namespace vb::regress {
namespace {

namespace v1 = valvebench::v1;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string Num(double v) {
  if (!std::isfinite(v)) return std::isnan(v) ? "n/a" : (v > 0 ? "inf" : "-inf");
  return fmt::format("{:.6g}", v);
}

std::string Pct(double delta, double base) {
  if (!std::isfinite(delta) || base == 0.0) return "";
  return fmt::format(" ({:+.1f} %)", 100.0 * delta / std::fabs(base));
}

Json NumJson(double v) { return std::isfinite(v) ? Json(v) : Json(nullptr); }
double NumFrom(const Json& j) { return j.is_number() ? j.get<double>() : kNaN; }

Json StatJson(const Stat& s) { return {{"mean", NumJson(s.n > 0 ? s.mean : kNaN)}, {"spread", s.spread}, {"n", s.n}}; }

// The suite entry a case belongs to: the longest entry name the case is, or starts with followed by '/' (a
// variant) or ' ' (sweep tags).
int EntryOfCase(const Suite& suite, const std::string& c) {
  int best = -1;
  size_t best_len = 0;
  for (int e = 0; e < suite.experiments_size(); ++e) {
    const std::string& n = suite.experiments(e).name();
    const bool match = c == n || (c.size() > n.size() && c.compare(0, n.size(), n) == 0 &&
                                  (c[n.size()] == '/' || c[n.size()] == ' '));
    if (match && n.size() >= best_len) {
      best = e;
      best_len = n.size();
    }
  }
  return best;
}


StatusOr<Stat> StatFrom(const Json& j, const std::string& where) {
  if (!j.is_object()) return Status::InvalidArgument(where + ": expected {mean, spread, n}");
  Stat s;
  if (!j.contains("n") || !j["n"].is_number_integer() || j["n"].get<int>() < 0)
    return Status::InvalidArgument(where + ".n: must be an integer >= 0");
  s.n = j["n"].get<int>();
  s.mean = j.contains("mean") ? NumFrom(j["mean"]) : kNaN;
  if (s.n > 0 && !std::isfinite(s.mean)) return Status::InvalidArgument(where + ".mean: must be a finite number");
  s.spread = j.contains("spread") ? NumFrom(j["spread"]) : 0.0;
  if (!std::isfinite(s.spread) || s.spread < 0)
    return Status::InvalidArgument(where + ".spread: must be finite and >= 0");
  return s;
}

}  // namespace

std::string XmlEscape(const std::string& s) {
  std::string out;
  for (char ch : s) {
    switch (ch) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      case '\'': out += "&apos;"; break;
      default:
        // XML 1.0 forbids most control characters.
        if (static_cast<unsigned char>(ch) < 0x20 && ch != '\n' && ch != '\t' && ch != '\r') {
          out += '?';
        } else {
          out += ch;
        }
    }
  }
  return out;
}

const char* VerdictName(Verdict v) {
  switch (v) {
    case Verdict::kImproved: return "improved";
    case Verdict::kUnchanged: return "unchanged";
    case Verdict::kRegressed: return "regressed";
    case Verdict::kNew: return "new";
  }
  return "?";
}

Measured Summarise(const std::vector<RunMetrics>& runs) {
  Measured m;
  std::map<std::string, std::map<std::string, std::vector<double>>> values;
  for (const auto& r : runs) {
    const std::string& c = r.case_name;
    auto& per = values[c];
    if (!r.ok) {
      m.failures[c].push_back("run " + std::to_string(r.run_id) + " (" + r.name + "): " +
                              (r.reason.empty() ? "did not succeed" : r.reason));
      continue;
    }
    for (const auto& [name, v] : r.metrics)
      if (std::isfinite(v)) per[name].push_back(v);
  }
  for (const auto& [c, per] : values) {
    auto& out = m.stats[c];
    for (const auto& [name, vs] : per) {
      Stat s;
      s.n = static_cast<int>(vs.size());
      double sum = 0;
      for (double v : vs) sum += v;
      s.mean = sum / s.n;
      double ss = 0;
      for (double v : vs) ss += (v - s.mean) * (v - s.mean);
      s.spread = s.n > 1 ? std::sqrt(ss / (s.n - 1)) : 0.0;
      out[name] = s;
    }
  }
  return m;
}

std::string BaselineNotOfRuns(const Baseline& baseline, const std::vector<RunMetrics>& runs) {
  const Measured m = Summarise(runs);
  if (baseline.cases.empty()) return "the baseline holds no case";
  auto same = [](double a, double b) { return std::abs(a - b) <= 1e-9 * std::max({std::abs(a), std::abs(b), 1e-300}); };
  for (const auto& [c, metrics] : baseline.cases) {
    const auto got = m.stats.find(c);
    if (got == m.stats.end()) return "case " + c + ": not among the runs";
    for (const auto& [name, s] : metrics) {
      const auto v = got->second.find(name);
      if (v == got->second.end()) return "case " + c + ", metric " + name + ": not measured by the runs";
      if (v->second.n != s.n || !same(v->second.mean, s.mean) || !same(v->second.spread, s.spread))
        return fmt::format("case {}, metric {}: the baseline holds {:.6g} over {} runs, the runs give {:.6g} over {}",
                           c, name, s.mean, s.n, v->second.mean, v->second.n);
    }
  }
  return "";
}

Json BaselineToJson(const Baseline& b) {
  Json cases = Json::object();
  for (const auto& [c, metrics] : b.cases) {
    Json m = Json::object();
    for (const auto& [name, s] : metrics) m[name] = StatJson(s);
    cases[c] = m;
  }
  return {{"name", b.name},       {"version", b.version}, {"created_unix_s", b.created_unix_s},
          {"source", b.source},   {"note", b.note},       {"cases", cases}};
}

StatusOr<Baseline> BaselineFromJson(const Json& j) {
  if (!j.is_object()) return Status::InvalidArgument("baseline: expected a JSON object");
  Baseline b;
  if (!j.contains("name") || !j["name"].is_string() || j["name"].get<std::string>().empty())
    return Status::InvalidArgument("name: must be a non-empty string");
  b.name = j["name"].get<std::string>();
  if (j.contains("version")) {
    if (!j["version"].is_number_integer() || j["version"].get<int>() < 0)
      return Status::InvalidArgument("version: must be an integer >= 0");
    b.version = j["version"].get<int>();
  }
  b.created_unix_s = j.contains("created_unix_s") ? NumFrom(j["created_unix_s"]) : 0.0;
  if (!std::isfinite(b.created_unix_s)) b.created_unix_s = 0.0;
  if (j.contains("source") && j["source"].is_string()) b.source = j["source"].get<std::string>();
  if (j.contains("note") && j["note"].is_string()) b.note = j["note"].get<std::string>();
  if (!j.contains("cases") || !j["cases"].is_object() || j["cases"].empty())
    return Status::InvalidArgument("cases: must be a non-empty object {case: {metric: {mean, spread, n}}}");
  for (const auto& [c, metrics] : j["cases"].items()) {
    if (!metrics.is_object()) return Status::InvalidArgument("cases." + c + ": expected {metric: {mean, spread, n}}");
    for (const auto& [name, s] : metrics.items()) {
      auto st = StatFrom(s, "cases." + c + "." + name);
      if (!st.ok()) return st.status();
      b.cases[c][name] = *st;
    }
  }
  return b;
}

Finding Judge(const std::string& case_name, const ResolvedTolerance& tol, double noise_sigmas, const Stat* baseline,
              const Stat* now) {
  Finding f;
  f.case_name = case_name;
  f.metric = tol.metric;
  f.direction = tol.direction;
  if (baseline != nullptr) f.baseline = *baseline;
  if (now != nullptr) f.now = *now;
  const bool has_b = baseline != nullptr && baseline->n > 0, has_n = now != nullptr && now->n > 0;
  if (!has_b) {
    f.verdict = Verdict::kNew;
    f.delta = kNaN;
    f.message = tol.metric + ": not in the baseline; now " + (has_n ? Num(now->mean) : "n/a");
    return f;
  }
  if (!has_n) {
    f.verdict = Verdict::kRegressed;
    f.delta = kNaN;
    f.message = tol.metric + ": baseline " + Num(baseline->mean) + ", now no value (the runs no longer produce it)";
    return f;
  }
  f.delta = now->mean - baseline->mean;
  f.tolerance = std::max(tol.absolute, tol.relative * std::fabs(baseline->mean));
  f.noise = noise_sigmas * std::sqrt(baseline->spread * baseline->spread + now->spread * now->spread);
  f.allowed = f.tolerance + f.noise;
  const double worse = tol.direction == v1::HIGHER_IS_BETTER ? -f.delta : f.delta;
  if (tol.direction == v1::BOTH) {
    f.verdict = std::fabs(f.delta) > f.allowed ? Verdict::kRegressed : Verdict::kUnchanged;
  } else if (worse > f.allowed) {
    f.verdict = Verdict::kRegressed;
  } else if (-worse > f.allowed) {
    f.verdict = Verdict::kImproved;
  } else {
    f.verdict = Verdict::kUnchanged;
  }
  const std::string buf = fmt::format("; allowed {}{} (tolerance {} + noise {})",
                                      tol.direction == v1::BOTH ? "+/-" : "", Num(f.allowed), Num(f.tolerance),
                                      Num(f.noise));
  f.message = tol.metric + " " + VerdictName(f.verdict) + ": baseline " + Num(baseline->mean) + " -> now " +
              Num(now->mean) + Pct(f.delta, baseline->mean) + " [" + DirectionName(tol.direction) +
              " is better]" + buf;
  return f;
}

int RegressResult::Count(Verdict v) const {
  return static_cast<int>(std::count_if(findings.begin(), findings.end(), [v](const Finding& f) { return f.verdict == v; }));
}

RegressResult Compare(const Suite& suite, const Baseline& baseline, const Measured& measured) {
  RegressResult r;
  r.suite = suite.name();
  r.baseline_name = baseline.name;
  r.baseline_version = baseline.version;
  r.noise_sigmas = NoiseSigmas(suite);
  r.failures = measured.failures;
  r.created_unix_s =
      std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
  // Cases: everything measured (or failed) plus every baseline case that belongs to one of the suite's entries.
  std::set<std::string> cases;
  for (const auto& [c, m] : measured.stats) cases.insert(c);
  for (const auto& [c, f] : measured.failures) cases.insert(c);
  for (const auto& [c, m] : baseline.cases)
    if (EntryOfCase(suite, c) >= 0) cases.insert(c);
  for (const auto& c : cases) {
    const int entry = EntryOfCase(suite, c);
    if (entry < 0) continue;  // not the suite's
    const auto mb = baseline.cases.find(c);
    const auto mn = measured.stats.find(c);
    for (const auto& tol : TolerancesFor(suite, entry)) {
      const Stat* b = nullptr;
      const Stat* n = nullptr;
      if (mb != baseline.cases.end()) {
        auto it = mb->second.find(tol.metric);
        if (it != mb->second.end()) b = &it->second;
      }
      if (mn != measured.stats.end()) {
        auto it = mn->second.find(tol.metric);
        if (it != mn->second.end()) n = &it->second;
      }
      if ((b == nullptr || b->n == 0) && (n == nullptr || n->n == 0)) continue;  // not applicable on either side
      // A case whose runs all failed is reported once, as its "run" failure, not once per metric.
      if ((n == nullptr || n->n == 0) && measured.failures.count(c)) continue;
      r.findings.push_back(Judge(c, tol, r.noise_sigmas, b, n));
    }
  }
  return r;
}

Json ResultToJson(const RegressResult& r) {
  Json findings = Json::array();
  for (const auto& f : r.findings) {
    findings.push_back({{"case", f.case_name},
                        {"metric", f.metric},
                        {"verdict", VerdictName(f.verdict)},
                        {"direction", DirectionName(f.direction)},
                        {"baseline", StatJson(f.baseline)},
                        {"now", StatJson(f.now)},
                        {"delta", NumJson(f.delta)},
                        {"tolerance", f.tolerance},
                        {"noise", f.noise},
                        {"allowed", f.allowed},
                        {"message", f.message}});
  }
  Json failures = Json::object();
  for (const auto& [c, list] : r.failures) failures[c] = list;
  return {{"id", r.id},
          {"suite", r.suite},
          {"baseline", {{"name", r.baseline_name}, {"version", r.baseline_version}}},
          {"batch_id", r.batch_id},
          {"where", r.where},
          {"night", r.night},
          {"seed", r.seed},
          {"created_unix_s", r.created_unix_s},
          {"noise_sigmas", r.noise_sigmas},
          {"verdict", r.verdict()},
          {"counts",
           {{"improved", r.Count(Verdict::kImproved)},
            {"unchanged", r.Count(Verdict::kUnchanged)},
            {"regressed", r.Count(Verdict::kRegressed)},
            {"new", r.Count(Verdict::kNew)},
            {"failed_cases", r.failures.size()}}},
          {"findings", findings},
          {"failures", failures}};
}

StatusOr<RegressResult> ResultFromJson(const Json& j) {
  if (!j.is_object() || !j.contains("findings") || !j["findings"].is_array())
    return Status::InvalidArgument("regression result: expected an object with 'findings'");
  RegressResult r;
  r.id = j.value("id", std::int64_t{0});
  r.suite = j.value("suite", "");
  if (j.contains("baseline") && j["baseline"].is_object()) {
    r.baseline_name = j["baseline"].value("name", "");
    r.baseline_version = j["baseline"].value("version", 0);
  }
  r.batch_id = j.value("batch_id", std::int64_t{0});
  r.where = j.value("where", "");
  r.night = j.value("night", "");
  r.seed = j.value("seed", std::uint64_t{0});
  r.created_unix_s = j.contains("created_unix_s") ? NumFrom(j["created_unix_s"]) : 0.0;
  r.noise_sigmas = j.contains("noise_sigmas") ? NumFrom(j["noise_sigmas"]) : 0.0;
  for (size_t k = 0; k < j["findings"].size(); ++k) {
    const Json& x = j["findings"][k];
    const std::string where = "findings[" + std::to_string(k) + "]";
    if (!x.is_object()) return Status::InvalidArgument(where + ": expected an object");
    Finding f;
    f.case_name = x.value("case", "");
    f.metric = x.value("metric", "");
    const std::string v = x.value("verdict", "");
    if (v == "improved") {
      f.verdict = Verdict::kImproved;
    } else if (v == "unchanged") {
      f.verdict = Verdict::kUnchanged;
    } else if (v == "regressed") {
      f.verdict = Verdict::kRegressed;
    } else if (v == "new") {
      f.verdict = Verdict::kNew;
    } else {
      return Status::InvalidArgument(where + ".verdict: '" + v + "' is not improved, unchanged, regressed or new");
    }
    const std::string d = x.value("direction", "both");
    f.direction = d == "lower" ? v1::LOWER_IS_BETTER : d == "higher" ? v1::HIGHER_IS_BETTER : v1::BOTH;
    if (x.contains("baseline")) {
      auto s = StatFrom(x["baseline"], where + ".baseline");
      if (!s.ok()) return s.status();
      f.baseline = *s;
    }
    if (x.contains("now")) {
      auto s = StatFrom(x["now"], where + ".now");
      if (!s.ok()) return s.status();
      f.now = *s;
    }
    f.delta = x.contains("delta") ? NumFrom(x["delta"]) : kNaN;
    f.tolerance = x.contains("tolerance") ? NumFrom(x["tolerance"]) : 0.0;
    f.noise = x.contains("noise") ? NumFrom(x["noise"]) : 0.0;
    f.allowed = x.contains("allowed") ? NumFrom(x["allowed"]) : 0.0;
    f.message = x.value("message", "");
    r.findings.push_back(std::move(f));
  }
  if (j.contains("failures") && j["failures"].is_object())
    for (const auto& [c, list] : j["failures"].items())
      if (list.is_array())
        for (const auto& s : list)
          if (s.is_string()) r.failures[c].push_back(s.get<std::string>());
  return r;
}

std::string ResultTable(const RegressResult& r) {
  std::ostringstream os;
  os << "suite " << r.suite << " vs baseline " << r.baseline_name << " v" << r.baseline_version;
  if (r.batch_id != 0) os << " (batch " << r.batch_id << (r.where.empty() ? "" : " on " + r.where) << ")";
  if (!r.night.empty()) os << ", night " << r.night;
  os << ": " << (r.regressed() ? "REGRESSED" : "PASSED") << " -- " << r.Count(Verdict::kRegressed) << " regressed, "
     << r.Count(Verdict::kImproved) << " improved, " << r.Count(Verdict::kUnchanged) << " unchanged";
  if (r.Count(Verdict::kNew) > 0) os << ", " << r.Count(Verdict::kNew) << " new";
  if (!r.failures.empty()) os << ", " << r.failures.size() << " case(s) with failed runs";
  os << "\n";
  for (const auto& [c, list] : r.failures)
    for (const auto& s : list) os << "  FAILED     " << c << ": " << s << "\n";
  for (Verdict v : {Verdict::kRegressed, Verdict::kImproved, Verdict::kNew, Verdict::kUnchanged}) {
    for (const auto& f : r.findings) {
      if (f.verdict != v) continue;
      std::string word = VerdictName(v);
      for (char& ch : word) ch = static_cast<char>(std::toupper(static_cast<unsigned char>(ch)));
      const std::string head = fmt::format("{:<10}", word);
      os << "  " << head << " " << f.case_name << "  " << f.message << "\n";
    }
  }
  return os.str();
}

std::string JUnitXml(const RegressResult& r) {
  const int tests = static_cast<int>(r.findings.size() + r.failures.size());
  const int failures = r.Count(Verdict::kRegressed) + static_cast<int>(r.failures.size());
  std::ostringstream os;
  os << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
  os << "<testsuites name=\"valvebench regress\" tests=\"" << tests << "\" failures=\"" << failures
     << "\" errors=\"0\">\n";
  os << "  <testsuite name=\"" << XmlEscape(r.suite) << "\" tests=\"" << tests << "\" failures=\"" << failures
     << "\" errors=\"0\" skipped=\"0\">\n";
  os << "    <properties>\n"
     << "      <property name=\"baseline\" value=\"" << XmlEscape(r.baseline_name) << " v" << r.baseline_version
     << "\"/>\n"
     << "      <property name=\"batch\" value=\"" << r.batch_id << "\"/>\n"
     << "      <property name=\"seed\" value=\"" << r.seed << "\"/>\n"
     << "      <property name=\"noise_sigmas\" value=\"" << r.noise_sigmas << "\"/>\n"
     << "    </properties>\n";
  const std::string prefix = XmlEscape(r.suite) + ".";
  for (const auto& [c, list] : r.failures) {
    std::string text;
    for (const auto& s : list) text += s + "\n";
    os << "    <testcase classname=\"" << prefix << XmlEscape(c) << "\" name=\"run\">\n"
       << "      <failure type=\"run-failed\" message=\"" << XmlEscape(list.front()) << "\">" << XmlEscape(text)
       << "</failure>\n    </testcase>\n";
  }
  for (const auto& f : r.findings) {
    os << "    <testcase classname=\"" << prefix << XmlEscape(f.case_name) << "\" name=\"" << XmlEscape(f.metric)
       << "\"";
    if (f.verdict == Verdict::kRegressed) {
      std::ostringstream detail;
      detail << "case: " << f.case_name << "\nmetric: " << f.metric << "\nbaseline: " << Num(f.baseline.mean)
             << " (spread " << Num(f.baseline.spread) << ", n " << f.baseline.n << ")\nnow: " << Num(f.now.mean)
             << " (spread " << Num(f.now.spread) << ", n " << f.now.n << ")\ndelta: " << Num(f.delta)
             << "\nallowed: " << Num(f.allowed) << " (tolerance " << Num(f.tolerance) << " + noise " << Num(f.noise)
             << ")\n";
      os << ">\n      <failure type=\"regression\" message=\"" << XmlEscape(f.message) << "\">"
         << XmlEscape(detail.str()) << "</failure>\n    </testcase>\n";
    } else {
      os << ">\n      <system-out>" << XmlEscape(f.message) << "</system-out>\n    </testcase>\n";
    }
  }
  os << "  </testsuite>\n</testsuites>\n";
  return os.str();
}

std::string NightsJUnitXml(const std::vector<NightOutcome>& nights) {
  int failures = 0, errors = 0;
  for (const auto& n : nights) {
    if (n.verdict == "error") ++errors;
    else if (n.verdict != "passed") ++failures;
  }
  const int tests = static_cast<int>(nights.size());
  std::ostringstream os;
  os << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n";
  os << "<testsuites name=\"valvebench nights\" tests=\"" << tests << "\" failures=\"" << failures << "\" errors=\""
     << errors << "\">\n";
  os << "  <testsuite name=\"nights\" tests=\"" << tests << "\" failures=\"" << failures << "\" errors=\"" << errors
     << "\" skipped=\"0\">\n";
  for (const auto& n : nights) {
    // The body: what a person reads in the CI's page (the night's summary, its cases, the valve, the cause).
    std::ostringstream body;
    body << "night: " << n.date << "\nverdict: " << n.verdict << "\nsuite: " << n.suite << "\nbaseline: " << n.baseline
         << "\nbatch: " << n.batch_id << "\nsummary: " << n.summary << "\n";
    if (!n.regressed_cases.empty()) {
      body << "regressed cases:";
      for (const auto& c : n.regressed_cases) body << " " << c;
      body << "\n";
    }
    for (const auto& v : n.valve_changes) body << "valve changed: " << v << "\n";
    if (!n.cause.empty()) body << "cause: " << n.cause << ": " << n.cause_reason << "\n";
    // The message: the summary and, for a regressed night, its cause (the bench twin's verdict) up front.
    std::string message = n.summary;
    if (!n.cause.empty()) message = "cause: " + n.cause + " (" + n.cause_reason + "); " + message;
    os << "    <testcase classname=\"nights." << XmlEscape(n.suite) << "\" name=\"" << XmlEscape(n.date) << "\">\n";
    if (n.verdict == "error") {
      os << "      <error type=\"night-error\" message=\"" << XmlEscape(message) << "\">" << XmlEscape(body.str())
         << "</error>\n";
    } else if (n.verdict != "passed") {
      os << "      <failure type=\"regression\" message=\"" << XmlEscape(message) << "\">" << XmlEscape(body.str())
         << "</failure>\n";
    } else {
      os << "      <system-out>" << XmlEscape(body.str()) << "</system-out>\n";
    }
    os << "    </testcase>\n";
  }
  os << "  </testsuite>\n</testsuites>\n";
  return os.str();
}

}  // namespace vb::regress
