// Regression comparison (docs/regress.md): metric values of a suite run, summarised per case over repeats, held
// against a baseline with per-metric tolerances and the repeat spread. A change inside tolerance + noise band is
// "unchanged"; beyond it in the better direction "improved", in the worse direction (or either, for
// two-sided metrics) "regressed". Also baselines as JSON, the result as JSON, a table and JUnit XML.
#pragma once

#include <nlohmann/json.hpp>

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "common/status.h"
#include "regress/suite.h"

namespace vb::regress {

using Json = nlohmann::ordered_json;

struct Stat {
  double mean = 0.0;
  double spread = 0.0;  // sample standard deviation over repeats (0 for one run)
  int n = 0;            // finite values
};

// case name -> metric -> statistic
using CaseStats = std::map<std::string, std::map<std::string, Stat>>;

// One executed run, as the local runner or the server reports it.
struct RunMetrics {
  std::int64_t run_id = 0;
  std::string name;                       // run name for people (RunKey::DisplayName)
  std::string case_name;                  // the case it belongs to (RunKey::CaseName): repeats share it
  bool ok = true;                         // done (not failed/cancelled)
  std::string reason;                     // why not
  std::map<std::string, double> metrics;  // NaN/absent = not applicable
};

struct Measured {
  CaseStats stats;                                          // over the ok runs of each case
  std::map<std::string, std::vector<std::string>> failures; // case -> "run 12: reason" of runs that did not succeed
};
Measured Summarise(const std::vector<RunMetrics>& runs);

struct Baseline {
  std::string name;
  int version = 0;                        // 1, 2, ... (0 = not stored yet)
  double created_unix_s = 0.0;
  std::string source;                     // e.g. "local batch 12", "server 127.0.0.1:50051 batch 3"
  std::string note;
  CaseStats cases;
};
Json BaselineToJson(const Baseline& b);
// Errors name the field ("cases.pi.rmse.spread: must be finite and >= 0").
StatusOr<Baseline> BaselineFromJson(const Json& j);

// Whether `baseline` is the summary of `runs` ("benchctl baseline set --batch B" stores Summarise(runs).stats):
// "" when every case and metric of the baseline is the runs' own (the same count, mean and spread to 1e-9
// relative), else the first difference, for people ("case pi, metric rmse: the baseline holds 0.00081 over 3
// runs, the runs give 0.00093 over 3"). A baseline's source names a batch by number only, and the same number on
// another lab's server is another batch: this tells the two apart before its runs are read as the baseline's.
std::string BaselineNotOfRuns(const Baseline& baseline, const std::vector<RunMetrics>& runs);

enum class Verdict { kImproved, kUnchanged, kRegressed, kNew };
const char* VerdictName(Verdict v);  // "improved", "unchanged", "regressed", "new"

struct Finding {
  std::string case_name;
  std::string metric;
  Verdict verdict = Verdict::kUnchanged;
  valvebench::v1::Direction direction = valvebench::v1::BOTH;
  Stat baseline, now;
  double delta = 0.0;        // now.mean - baseline.mean (NaN when one side has no value)
  double tolerance = 0.0;    // max(absolute, relative * |baseline mean|)
  double noise = 0.0;        // noise_sigmas * sqrt(s_b^2 + s_now^2)
  double allowed = 0.0;      // tolerance + noise
  std::string message;       // one line for people: the metric and both numbers
};

struct RegressResult {
  std::int64_t id = 0;       // in the store (0 = not stored)
  std::string suite;
  std::string baseline_name;
  int baseline_version = 0;
  std::int64_t batch_id = 0;
  std::string where;         // "local" or the server address
  std::string night;         // YYYY-MM-DD for a scheduled night, else ""
  std::uint64_t seed = 0;
  double created_unix_s = 0.0;
  double noise_sigmas = 0.0;
  std::vector<Finding> findings;                             // case order, then the entry's metric order
  std::map<std::string, std::vector<std::string>> failures;  // runs that did not succeed, by case
  int Count(Verdict v) const;
  bool regressed() const { return Count(Verdict::kRegressed) > 0 || !failures.empty(); }
  const char* verdict() const { return regressed() ? "regressed" : "passed"; }
};

// Compares the measured cases of a suite with a baseline. A case of the suite's entries that the baseline
// lacks is "new" (not a failure); a baseline value the run no longer produces is "regressed".
RegressResult Compare(const Suite& suite, const Baseline& baseline, const Measured& measured);

// The verdict for one metric (exposed for tests).
Finding Judge(const std::string& case_name, const ResolvedTolerance& tol, double noise_sigmas, const Stat* baseline,
              const Stat* now);

Json ResultToJson(const RegressResult& r);
StatusOr<RegressResult> ResultFromJson(const Json& j);
std::string ResultTable(const RegressResult& r);   // for people: summary line, then every non-unchanged finding
// JUnit XML: one testsuite per suite, one testcase per case and metric (classname "<suite>.<case>", name the
// metric); a regression is a <failure> whose message names the metric and both numbers; runs that failed are
// a testcase "run" with a <failure>.
std::string JUnitXml(const RegressResult& r);

// A scheduled night as ListNights gives it (the server's record), for its JUnit XML.
struct NightOutcome {
  std::string date, verdict, suite, baseline, summary, cause, cause_reason;
  std::int64_t batch_id = 0;
  std::vector<std::string> regressed_cases, valve_changes;
};
// JUnit XML of nights: one testcase per night (classname "nights.<suite>", name its date); a regressed night is a
// <failure> whose message starts with its cause ("cause: valve (...)"; the bench twin, docs/track.md), an error
// night an <error>; the body lists the summary, the regressed cases, the valve changes and the cause.
std::string NightsJUnitXml(const std::vector<NightOutcome>& nights);
// Text escaped for XML attributes and character data (control characters XML 1.0 forbids dropped).
std::string XmlEscape(const std::string& s);

}  // namespace vb::regress
