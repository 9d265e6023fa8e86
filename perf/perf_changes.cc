// Changes named against a reference identified from scratch, calibrated on draws (issue 35, points 3 and 4):
// valves of the independent plant (perf/independent_valve.h: a tabulated B-H steel in series with the gaps, a
// two-rung eddy ladder, Stribeck friction, a flow-dependent pressure force, a scope with offsets and spikes), each
// with one change of a valve in service applied between a reference session and a target session, and
// `Diagnose` asked what changed. The seeds (SEED*1000 + j, SEED 36) and the kinds (case j gets kind j mod 10) are
// fixed before any result is seen.
//
// Every verdict falls in one of three classes, and the rates of each, per kind and over all, are printed with
// their Wilson 95 % intervals:
//  - named: the verdict contains one of the kind's accept words (as gapbench's labels.json do);
//  - cannot tell: `undetermined` or `unknown` (the method says it could not see, with its reason);
//  - wrong: any other verdict: a confident wrong answer, including a `none` where something changed (a false
//    all-clear). This is the rate the method must keep low: "cannot tell" is an honest answer, "wrong" is not.
// "all, names kept" classes the same verdicts as they were before a name against a reference that is not
// identified was withheld (gap/diagnose.cc UntrustedName; the name stays in Diagnosis::untrusted_name).
//
// The kinds and their sizes (against the valve as drawn): none; heating (the winding's R +6 %); pressure (5 bar
// acting where 1 bar is declared, every run); preload (the spring's preload force -20 %); fatigue (stiffness
// -30 %, the preload force with it); wear (dry friction at 15 % of the preload); stuck (held by friction); connector
// (5 % of R in series with the supply); low_supply (the supply delivers 0.92x the declared); slow_driver (the
// coil's edge 80 us after the gate). Reference: 1, 2.5, 4 and 6 bar at the valve's supply; target: the same (1 bar
// thrice for pressure). The last run of each is held out, as a session without splits is.
//
// Usage: perf_changes [--cases N] [--seed SEED] [--only KIND] [--evaluations N] [--verbose]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "gap/diagnose.h"
#include "gap/moving_valve.h"
#include "model/params.h"
#include "perf/independent_session.h"
#include "perf/perf_stats.h"
#include "perf/independent_valve.h"

namespace {

using vb::perf::CpuSeconds;
using vb::perf::LoadAverage;
using vb::perf::Wilson;

using Clock = std::chrono::steady_clock;

struct Kind {
  const char* name;
  std::vector<std::string> accept;  // gapbench's words for the change, plus the catalog's name for it
};

const Kind kKinds[] = {
    {"none", {"none"}},
    {"heating", {"param:R", "resistance", "temperature", "heating"}},
    {"pressure", {"pressure", "fluid", "load", "force", "delta", "preload", "A1", "A2", "area"}},
    {"preload", {"delta", "preload", "spring", "param:k", "force"}},
    {"fatigue", {"param:k", "spring", "stiffness", "delta", "preload"}},
    {"wear", {"friction", "coulomb", "stiction", "F_c", "F_s", "damping", "param:b", "wear"}},
    {"stuck", {"stuck", "friction", "x_max", "stroke", "blocked", "no motion", "travel"}},
    {"connector", {"supply_resistance", "R_s"}},
    {"low_supply", {"supply_voltage"}},
    {"slow_driver", {"driver_delay", "delay"}},
};
constexpr int kKindCount = static_cast<int>(std::size(kKinds));

// The valve after the change, and the target's runs.
void Apply(const std::string& kind, vb::perf::IndependentValve* v, std::vector<vb::perf::SessionRun>* runs) {
  if (kind == "heating") v->R_ohm *= 1.06;
  if (kind == "pressure")
    for (auto& r : *runs) r.bar = 5.0, r.declared_bar = 1.0;
  if (kind == "preload") v->F0_N *= 0.8;
  if (kind == "fatigue") v->k_N_per_m *= 0.7, v->F0_N *= 0.7;
  if (kind == "wear") v->Fs_N = v->Fc_N = std::max(v->Fs_N, 0.15 * v->F0_N);
  if (kind == "stuck") v->Fs_N = v->Fc_N = 1e3;
  if (kind == "connector") v->R_ohm *= 1.05;  // a switch-on is all drive: R_s adds to R exactly
  if (kind == "low_supply") v->supply_gain = 0.92;
  if (kind == "slow_driver") v->delay_s = 80e-6;
}

bool Accepted(const std::string& verdict, const Kind& k) {
  for (const auto& w : k.accept)
    if (verdict.find(w) != std::string::npos) return true;
  return false;
}

}  // namespace

int main(int argc, char** argv) {
  int cases = 20, evaluations = vb::gap::MovingIdentifyOptions{}.max_evaluations;
  unsigned seed = 36;
  std::string only;
  bool verbose = false;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg == "--cases" && a + 1 < argc) {
      cases = std::atoi(argv[++a]);
    } else if (arg == "--seed" && a + 1 < argc) {
      seed = static_cast<unsigned>(std::atoi(argv[++a]));
    } else if (arg == "--only" && a + 1 < argc) {
      only = argv[++a];
    } else if (arg == "--evaluations" && a + 1 < argc) {
      evaluations = std::atoi(argv[++a]);
    } else if (arg == "--verbose") {
      verbose = true;
    } else {
      std::fprintf(stderr, "usage: perf_changes [--cases N] [--seed SEED] [--only KIND] [--evaluations N] [--verbose]\n");
      return 2;
    }
  }
  const auto family = vb::model::Preset("taghizadeh2009");
  if (!family.ok()) return 1;
  std::printf("load average at the start: %s; %d evaluations per identification\n", LoadAverage().c_str(), evaluations);
  std::printf("%-9s %-12s %-7s %-80s %-11s %7s\n", "case", "kind", "valve", "verdict (reference fit / noise)", "class",
              "cpu_s");
  struct Count {
    int named = 0, cannot = 0, wrong = 0, n = 0;
  };
  std::map<std::string, Count> by_kind;
  Count all;
  // The same cases as they were classed before names against references that are not identified were withheld
  // (Diagnosis::untrusted_name is what the data pointed to): the trade that rule makes, measured on the same draws.
  Count before;
  double cpu_total = 0.0;
  for (int j = 0; j < cases; ++j) {
    const Kind& kind = kKinds[j % kKindCount];
    if (!only.empty() && only != kind.name) continue;
    std::mt19937 rng(seed * 1000u + static_cast<unsigned>(j));
    const vb::perf::IndependentValve v = vb::perf::DrawValve(rng);
    const std::vector<vb::perf::SessionRun> plan = {{v.supply_V, 1}, {v.supply_V, 2.5}, {v.supply_V, 4}, {v.supply_V, 6}};
    auto target_plan = plan;
    vb::perf::IndependentValve later = v;
    Apply(kind.name, &later, &target_plan);
    const vb::gap::Dataset reference = vb::perf::IndependentSession(v, plan, rng, "indep-" + std::to_string(j), false);
    const vb::gap::Dataset target = vb::perf::IndependentSession(later, target_plan, rng, "indep-" + std::to_string(j), false);
    const double c0 = CpuSeconds();
    vb::gap::DiagnoseOptions o;
    o.reference = &reference;
    o.reference_fit.scratch_max_evaluations = evaluations;
    if (verbose) o.reference_fit.scratch_progress = [](const std::string& l) { std::fprintf(stderr, "  %s\n", l.c_str()); };
    auto d = vb::gap::Diagnose(target, *family, o);
    const double cpu = CpuSeconds() - c0;
    cpu_total += cpu;
    std::string verdict, cls;
    Count& c = by_kind[kind.name];
    if (!d.ok()) {
      verdict = "refused: " + d.status().message();
      cls = "cannot tell";
      ++c.cannot, ++all.cannot;
    } else {
      char buf[200];
      std::snprintf(buf, sizeof buf, "%s (%.1f / %.2f mA)", d->verdict.c_str(), d->reference.fit_rmse_A * 1e3,
                    d->reference.noise_floor_A * 1e3);
      verdict = buf;
      if (Accepted(d->verdict, kind)) {
        cls = "named";
        ++c.named, ++all.named;
      } else if (d->verdict_kind == vb::gap::VerdictKind::kUndetermined || d->verdict_kind == vb::gap::VerdictKind::kUnknown) {
        cls = "cannot tell";
        ++c.cannot, ++all.cannot;
      } else {
        cls = "WRONG";
        ++c.wrong, ++all.wrong;
      }
      if (verbose) std::printf("    reason: %s\n", d->verdict_reason.c_str());
      const std::string said = d->untrusted_name.empty() ? d->verdict : d->untrusted_name;
      if (Accepted(said, kind)) ++before.named;
      else if (d->untrusted_name.empty() && cls == "cannot tell") ++before.cannot;
      else ++before.wrong;
      if (!d->untrusted_name.empty()) verdict += " [" + d->untrusted_name + "]";
    }
    if (!d.ok()) ++before.cannot;
    ++before.n;
    ++c.n, ++all.n;
    if (verdict.size() > 80) verdict = verdict.substr(0, 80);
    char valve[32];
    std::snprintf(valve, sizeof valve, "%gV", v.supply_V);
    std::printf("%-9s %-12s %-7s %-80s %-11s %7.1f\n", ("case_" + std::to_string(j)).c_str(), kind.name, valve,
                verdict.c_str(), cls.c_str(), cpu);
    std::fflush(stdout);
  }
  auto line = [](const std::string& what, const Count& c) {
    auto pct = [&](int k) {
      const auto [lo, hi] = Wilson(k, c.n);
      char b[64];
      std::snprintf(b, sizeof b, "%2d (%.0f-%.0f %%)", k, 100.0 * lo, 100.0 * hi);
      return std::string(b);
    };
    std::printf("%-12s of %2d: named %s, cannot tell %s, wrong %s\n", what.c_str(), c.n, pct(c.named).c_str(),
                pct(c.cannot).c_str(), pct(c.wrong).c_str());
  };
  for (const Kind& k : kKinds)
    if (by_kind.count(k.name)) line(k.name, by_kind[k.name]);
  line("all", all);
  line("all, names kept", before);
  std::printf("CPU %.1f s per case; load average at the end: %s\n", all.n ? cpu_total / all.n : 0.0, LoadAverage().c_str());
  return 0;
}
