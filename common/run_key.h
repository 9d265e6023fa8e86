// A run's identity inside its batch, as typed fields: which spec (its name, with a variant's suffix), which
// point of its sweep ((field, value) pairs in axis order) and which repeat. Sweeps and repeats produce it
// (experiment::ExpandRuns), the store keeps it in columns (docs/store.md), comparisons and baselines group on
// it. The text forms below are for people and for baseline case names; nothing parses them back.
#pragma once

#include <string>
#include <vector>

namespace vb {

struct SweepCoordinate {
  std::string field;   // spec field path, e.g. "conditions.supply_V"
  double value = 0.0;  // in the field's own unit

  bool operator==(const SweepCoordinate&) const = default;
};

struct RunKey {
  std::string name;                    // spec name ("e1", "compare/pi" for a variant)
  std::vector<SweepCoordinate> sweep;  // empty unless the spec has sweep axes
  int repeat = -1;                     // 0, 1, ... when the spec has repeats > 1; -1: not repeated

  bool operator==(const RunKey&) const = default;

  // The configuration repeats share: "name sweep:<field>=<value> ..." (values to 10 significant digits).
  // Baselines and comparisons are keyed on it.
  std::string CaseName() const;
  // The run as people see it: CaseName() plus " repeat:<k>" for a repeated run.
  std::string DisplayName() const;
};

// A run that did not come out of a sweep: only a name.
inline RunKey NamedRun(std::string name) { return RunKey{std::move(name), {}, -1}; }

}  // namespace vb
