// Regression suites (proto/valvebench/v1/suite.proto, docs/regress.md): load and validate a suite file (errors
// name the field), and expand it into the single runs to execute, with seeded run-to-run jitter.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "common/run_key.h"
#include "common/status.h"
#include "experiment/spec.h"
#include "valvebench/v1/spec.pb.h"
#include "valvebench/v1/suite.pb.h"

namespace vb::regress {

using valvebench::v1::Suite;

// A suite with every entry's spec resolved (spec_file read and parsed) and validated.
struct LoadedSuite {
  Suite suite;                                        // entries carry their spec inline after loading
  std::string path;                                   // where it was read from ("" when parsed from text)
};

// Parses protobuf JSON (unknown fields are errors); base_dir resolves spec_file. Validates: name, at least one
// entry, exactly one of spec/spec_file per entry, unique case names, bench_class matching the spec, known
// metrics and non-negative tolerances, jitter fields that exist, and that every spec expands and builds.
StatusOr<LoadedSuite> ParseSuite(const std::string& json, const std::string& base_dir);
StatusOr<LoadedSuite> LoadSuite(const std::string& path);

// "emulated:<preset>" (the server's bench classes; docs/server.md), or the kind for non-emulated benches: the
// one definition, experiment::BenchClassOf.
using experiment::BenchClassOf;

// One run to execute: the single-run spec, its identity (RunKey as ExpandRuns gives it) and the case it
// belongs to (key.CaseName(): entry name + sweep point; repeats of one configuration share a case).
struct SuiteRun {
  int entry = 0;                                      // index into suite.experiments
  std::string case_name;
  RunKey key;
  valvebench::v1::ExperimentSpec spec;
};

// Expands every entry (variants, sweeps, repeats), then applies the entry's jitter with a generator seeded by
// (seed, run index): the same seed gives the same runs, bit for bit.
StatusOr<std::vector<SuiteRun>> ExpandSuite(const Suite& suite, std::uint64_t seed);

// The metrics compared for an entry (its tolerances over the suite's), in order, and the tolerance of each.
struct ResolvedTolerance {
  std::string metric;
  double absolute = 0.0;
  double relative = 0.0;
  valvebench::v1::Direction direction = valvebench::v1::BOTH;  // never DIRECTION_DEFAULT
};
std::vector<ResolvedTolerance> TolerancesFor(const Suite& suite, int entry);
double NoiseSigmas(const Suite& suite);

// The metric names runs produce (experiment::MetricList order) and the default direction of each.
const std::vector<std::string>& KnownMetrics();
valvebench::v1::Direction DefaultDirection(const std::string& metric);
const char* DirectionName(valvebench::v1::Direction d);  // "lower", "higher", "both"

}  // namespace vb::regress
