#include "regress/suite.h"

#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "experiment/metrics.h"
#include "experiment/spec.h"
#include "model/params.h"

namespace vb::regress {
namespace {

namespace v1 = valvebench::v1;
namespace pb = google::protobuf;

constexpr double kDefaultNoiseSigmas = 3.0;
constexpr double kJitterClip = 3.0;  // z clipped to +/-3: a jittered run is never absurd

std::string Idx(const char* field, int k) { return std::string(field) + "[" + std::to_string(k) + "]"; }

// splitmix64: a small, fully specified generator, so a seed gives the same runs on every platform
// (std::normal_distribution's algorithm is implementation-defined).
struct SplitMix {
  std::uint64_t s;
  std::uint64_t Next() {
    std::uint64_t z = (s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  double Uniform() { return (static_cast<double>(Next() >> 11) + 0.5) * 0x1.0p-53; }  // (0, 1)
  double Normal() {  // Box-Muller
    const double u1 = Uniform(), u2 = Uniform();
    const double z = std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
    return std::clamp(z, -kJitterClip, kJitterClip);
  }
};

Status ValidateTolerance(const v1::Tolerance& t, const std::string& where) {
  if (t.metric().empty()) return Status::InvalidArgument(where + ".metric: must name a metric");
  const auto& known = KnownMetrics();
  if (std::find(known.begin(), known.end(), t.metric()) == known.end()) {
    std::string list;
    for (const auto& m : known) list += (list.empty() ? "" : ", ") + m;
    return Status::InvalidArgument(where + ".metric: unknown metric '" + t.metric() + "' (known: " + list + ")");
  }
  if (!std::isfinite(t.absolute()) || t.absolute() < 0)
    return Status::InvalidArgument(where + ".absolute: must be finite and >= 0, got " + std::to_string(t.absolute()));
  if (!std::isfinite(t.relative()) || t.relative() < 0)
    return Status::InvalidArgument(where + ".relative: must be finite and >= 0, got " + std::to_string(t.relative()));
  return Status::Ok();
}

// Reads a field for jitter; an absent perturbation.param_scale[X] is the neutral scale 1.
StatusOr<double> JitterBase(const v1::ExperimentSpec& spec, const std::string& field) {
  auto v = experiment::GetFieldByPath(spec, field);
  if (v.ok()) return v;
  if (v.status().code() == StatusCode::kNotFound && field.rfind("perturbation.param_scale[", 0) == 0) return 1.0;
  if (v.status().code() == StatusCode::kNotFound && field.rfind("perturbation.", 0) == 0) return 0.0;
  return v.status();
}

Status ApplyJitter(const v1::SuiteEntry& entry, SplitMix* rng, v1::ExperimentSpec* spec) {
  for (int j = 0; j < entry.jitter_size(); ++j) {
    const auto& jit = entry.jitter(j);
    auto base = JitterBase(*spec, jit.field());
    if (!base.ok()) return base.status().WithContext(Idx("jitter", j) + ".field");
    const double z1 = rng->Normal(), z2 = rng->Normal();
    const double v = *base * (1.0 + jit.relative_sd() * z1) + jit.absolute_sd() * z2;
    VB_RETURN_IF_ERROR(experiment::SetFieldByPath(spec, jit.field(), v).WithContext(Idx("jitter", j) + ".field"));
  }
  return Status::Ok();
}

}  // namespace

const std::vector<std::string>& KnownMetrics() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> out;
    for (const auto& [name, value] : experiment::MetricList(experiment::Metrics{})) out.push_back(name);
    return out;
  }();
  return names;
}

v1::Direction DefaultDirection(const std::string& metric) {
  static const std::set<std::string> lower = {"rmse",       "iae",      "max_abs_error", "overshoot",
                                              "settling_time_s", "effort_l2", "effort_rms", "energy_J",
                                              "switches"};
  return lower.count(metric) ? v1::LOWER_IS_BETTER : v1::BOTH;
}

const char* DirectionName(v1::Direction d) {
  switch (d) {
    case v1::LOWER_IS_BETTER: return "lower";
    case v1::HIGHER_IS_BETTER: return "higher";
    default: return "both";
  }
}

double NoiseSigmas(const Suite& suite) {
  return suite.has_noise_sigmas() ? suite.noise_sigmas() : kDefaultNoiseSigmas;
}

std::vector<ResolvedTolerance> TolerancesFor(const Suite& suite, int entry) {
  std::vector<ResolvedTolerance> out;
  auto put = [&](const v1::Tolerance& t) {
    ResolvedTolerance r{t.metric(), t.absolute(), t.relative(),
                        t.direction() == v1::DIRECTION_DEFAULT ? DefaultDirection(t.metric()) : t.direction()};
    for (auto& o : out)
      if (o.metric == r.metric) {
        o = r;
        return;
      }
    out.push_back(r);
  };
  for (const auto& t : suite.tolerances()) put(t);
  if (entry >= 0 && entry < suite.experiments_size())
    for (const auto& t : suite.experiments(entry).tolerances()) put(t);
  return out;
}

StatusOr<LoadedSuite> ParseSuite(const std::string& json, const std::string& base_dir) {
  LoadedSuite out;
  pb::util::JsonParseOptions opts;
  opts.ignore_unknown_fields = false;
  auto st = pb::util::JsonStringToMessage(json, &out.suite, opts);
  if (!st.ok()) return Status::InvalidArgument(std::string(st.message()));
  Suite& s = out.suite;
  if (s.name().empty()) return Status::InvalidArgument("name: must not be empty");
  if (s.experiments_size() == 0) return Status::InvalidArgument("experiments: a suite needs at least one entry");
  if (s.has_noise_sigmas() && (!std::isfinite(s.noise_sigmas()) || s.noise_sigmas() < 0))
    return Status::InvalidArgument("noise_sigmas: must be finite and >= 0, got " + std::to_string(s.noise_sigmas()));
  for (int k = 0; k < s.tolerances_size(); ++k)
    VB_RETURN_IF_ERROR(ValidateTolerance(s.tolerances(k), Idx("tolerances", k)));
  std::set<std::string> names;
  for (int e = 0; e < s.experiments_size(); ++e) {
    v1::SuiteEntry* entry = s.mutable_experiments(e);
    const std::string where = Idx("experiments", e);
    if (entry->spec_file().empty() == !entry->has_spec())
      return Status::InvalidArgument(where + ": give exactly one of spec_file and spec");
    if (!entry->spec_file().empty()) {
      std::filesystem::path p(entry->spec_file());
      if (p.is_relative() && !base_dir.empty()) p = std::filesystem::path(base_dir) / p;
      auto spec = experiment::LoadSpecFile(p.string());
      if (!spec.ok()) return spec.status().WithContext(where + ".spec_file");
      *entry->mutable_spec() = *spec;
    }
    if (!entry->name().empty()) entry->mutable_spec()->set_name(entry->name());
    if (entry->spec().name().empty()) return Status::InvalidArgument(where + ".name: the entry or its spec needs a name");
    entry->set_name(entry->spec().name());
    if (!names.insert(entry->name()).second)
      return Status::InvalidArgument(where + ".name: duplicate case name '" + entry->name() + "'");
    if (entry->repeats() > 0) entry->mutable_spec()->set_repeats(entry->repeats());
    const std::string cls = BenchClassOf(entry->spec());
    if (entry->bench_class().empty()) {
      entry->set_bench_class(cls);
    } else if (entry->bench_class() != cls) {
      return Status::InvalidArgument(where + ".bench_class: '" + entry->bench_class() + "' but the spec runs on '" +
                                     cls + "'");
    }
    for (int k = 0; k < entry->tolerances_size(); ++k)
      VB_RETURN_IF_ERROR(ValidateTolerance(entry->tolerances(k), where + "." + Idx("tolerances", k)));
    if (TolerancesFor(s, e).empty())
      return Status::InvalidArgument(where + ".tolerances: no metric to compare (give tolerances here or suite-wide)");
    for (int j = 0; j < entry->jitter_size(); ++j) {
      const auto& jit = entry->jitter(j);
      const std::string jw = where + "." + Idx("jitter", j);
      if (jit.field().empty()) return Status::InvalidArgument(jw + ".field: must name a numeric spec field");
      if (!std::isfinite(jit.relative_sd()) || jit.relative_sd() < 0)
        return Status::InvalidArgument(jw + ".relative_sd: must be finite and >= 0");
      if (!std::isfinite(jit.absolute_sd()) || jit.absolute_sd() < 0)
        return Status::InvalidArgument(jw + ".absolute_sd: must be finite and >= 0");
    }
  }
  // Every run must build (a bad point fails the suite before anything runs), and jitter paths must exist.
  auto runs = ExpandSuite(s, s.seed());
  if (!runs.ok()) return runs.status();
  for (const auto& r : *runs) {
    auto e = experiment::BuildExperiment(r.spec);
    if (!e.ok()) return e.status().WithContext(Idx("experiments", r.entry) + " (" + r.case_name + ")");
  }
  return out;
}

StatusOr<LoadedSuite> LoadSuite(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Status::NotFound(path + ": cannot open the suite file");
  std::stringstream ss;
  ss << in.rdbuf();
  auto s = ParseSuite(ss.str(), std::filesystem::path(path).parent_path().string());
  if (!s.ok()) return s.status().WithContext(path);
  s->path = path;
  return s;
}

StatusOr<std::vector<SuiteRun>> ExpandSuite(const Suite& suite, std::uint64_t seed) {
  std::vector<SuiteRun> out;
  for (int e = 0; e < suite.experiments_size(); ++e) {
    const auto& entry = suite.experiments(e);
    auto points = experiment::ExpandRuns(entry.spec());
    if (!points.ok()) return points.status().WithContext(Idx("experiments", e));
    for (auto& p : *points) {
      SuiteRun r;
      r.entry = e;
      r.spec = std::move(p.spec);
      r.key = std::move(p.key);
      SplitMix rng{seed * 0x100000001B3ull + out.size() * 0x9E3779B97F4A7C15ull + 1};
      VB_RETURN_IF_ERROR(ApplyJitter(entry, &rng, &r.spec).WithContext(Idx("experiments", e)));
      r.case_name = r.key.CaseName();
      out.push_back(std::move(r));
    }
  }
  return out;
}

}  // namespace vb::regress
