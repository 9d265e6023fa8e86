// Moving valves identified from scratch and changes named against a reference identified from scratch (issue 35,
// docs/real-data.md "Moving valves"), on the labelled sets practice3 and practice4 (../shared/gapbench): the
// figures before and after a change to gap/moving_valve.*, measured, not asserted.
//  - predict cases: identify on the fit runs, predict the holdout runs; success when the holdout RMS is within
//    max(5 mA, 3x the noise floor) (the criterion: 5 mA is the goal on a quiet chain, 3x the noise
//    where the chain itself is noisier: a correct model leaves the noise, sigma, and 3 sigma RMS means at least
//    sqrt(8) sigma of systematic error).
//  - withheld cases: diagnose target/ against reference/; success when the verdict contains one of the label's
//    accept words. labels.json is read for scoring only; valves.json (the truth) is never read.
// Prints one row per case, the success rate with its Wilson 95 % interval, the wall and CPU time per case, and the
// load average before and after (/proc/loadavg). The identification's budget is a count of evaluations
// (--evaluations N, default MovingIdentifyOptions's), so the rates do not depend on the load; the times do, and the
// CPU time (both threads) bounds the wall time the same case takes on 2 idle cores.
//
// --population N: also N valves of the independent population (perf/independent_valve.h: a plant written
// apart from model/, with a tabulated B-H steel, an eddy ladder, Stribeck friction and a flow-dependent
// pressure force), drawn with seeds SEED*1000 + j fixed before any result was seen (SEED 35, the number);
// each is identified on 1, 2 and 4 bar and predicts 6 bar and 0.75x supply. Success as for the predict cases;
// "strict" when fit and holdout are both within 3x the noise floor.
//
// Usage: perf_identify [--sets practice3,practice4 | --sets none] [--only SUBSTRING] [--evaluations N] [--verbose]
//                      [--edges] [--population N] [--valves J,K,...] [--seed SEED] [--ablate flow,stribeck,ladder,eddy,core,scope]
//                      [--design one-supply|two-supplies] [--noise]
// --valves J,K,...: only these draws of the population (indep_J; each draw has its own seed, so a subset is the
// same valves as in the whole run).
// --design two-supplies: each draw's session gets a fourth fit run, at 0.75x the supply and 1 bar (appended, so
// the other runs' noise is the same as without it): whether a pulling-in run at a second supply pins what runs
// at one supply leave open (the lift against the flight, docs/real-data.md "Ninth round"). Default one-supply.
// --edges: for each holdout run of a draw, one line "edge" with the identified valve's distance to its pull-in
// edge along the supply (RunMarks::edge_log_supply) and the same for the drawn valve itself (noise-free, the
// same dip threshold), the fit's multiple of the noise floor and whether the prediction was trusted: the data
// the pull-in-edge rule is calibrated on (docs/real-data.md, "Eighth round").
// --noise: no identification; each drawn run's noise estimate from second differences, with every sample and
// between the gate's edges, against the chain's own noise (the draw's), as percentiles (docs/real-data.md,
// "Eleventh round").
#include <nlohmann/json.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "gap/dataset.h"
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

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

std::string Lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

struct Tally {
  int ok = 0, n = 0;
  double seconds = 0.0, worst_s = 0.0, cpu_s = 0.0, worst_cpu_s = 0.0;
};

}  // namespace

// A whole number for a flag, in [lo, hi] ("1e8" is read as 100000000); false with the flag named on stderr.
static bool ParseWhole(const char* flag, const char* text, double lo, double hi, double* out) {
  char* end = nullptr;
  const double v = std::strtod(text, &end);
  if (end == text || *end != '\0' || !std::isfinite(v) || v != std::floor(v) || v < lo || v > hi) {
    std::fprintf(stderr, "%s: '%s' is not a whole number in [%.0f, %.0f]\n", flag, text, lo, hi);
    return false;
  }
  *out = v;
  return true;
}

int main(int argc, char** argv) {
  std::string sets = "practice3,practice4", only;
  int evaluations = vb::gap::MovingIdentifyOptions{}.max_evaluations;
  std::int64_t ode_steps = -1;  // -1: MovingIdentifyOptions's
  int population = 0;
  // --ablate flow,stribeck,ladder,eddy,core,scope: the same draws with forms of the independent plant taken out,
  // to see which of them the identification's family misses (the draws are made first, so the valves are the same).
  std::string ablate;
  bool verbose = false, edges = false, two_supplies = false, noise_only = false;
  unsigned seed = 35;
  std::set<int> valves;  // --valves: empty = every draw
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg == "--sets" && a + 1 < argc) {
      sets = argv[++a];
    } else if (arg == "--only" && a + 1 < argc) {
      only = argv[++a];
    } else if (arg == "--evaluations" && a + 1 < argc) {
      double v = 0.0;
      if (!ParseWhole("--evaluations", argv[++a], 100, 1e7, &v)) return 2;
      evaluations = static_cast<int>(v);
    } else if (arg == "--ode-steps" && a + 1 < argc) {
      double v = 0.0;  // 0: no budget
      if (!ParseWhole("--ode-steps", argv[++a], 0, 1e15, &v)) return 2;
      ode_steps = static_cast<std::int64_t>(v);
    } else if (arg == "--verbose") {
      verbose = true;
    } else if (arg == "--edges") {
      edges = true;
    } else if (arg == "--noise") {
      noise_only = true;
    } else if (arg == "--ablate" && a + 1 < argc) {
      ablate = argv[++a];
      std::stringstream forms(ablate);
      for (std::string form; std::getline(forms, form, ',');) {
        if (form == "none" || form == "flow" || form == "stribeck" || form == "ladder" || form == "eddy" ||
            form == "core" || form == "scope")
          continue;
        std::fprintf(stderr, "--ablate: unknown form '%s' (flow, stribeck, ladder, eddy, core, scope, none)\n",
                     form.c_str());
        return 2;
      }
    } else if (arg == "--population" && a + 1 < argc) {
      double v = 0.0;
      if (!ParseWhole("--population", argv[++a], 0, 100000, &v)) return 2;
      population = std::max(population, static_cast<int>(v));
    } else if (arg == "--valves" && a + 1 < argc) {
      std::stringstream list(argv[++a]);
      for (std::string j; std::getline(list, j, ',');) {
        char* end = nullptr;
        const long n = std::strtol(j.c_str(), &end, 10);
        if (j.empty() || *end != '\0' || n < 0 || n > 100000) {
          std::fprintf(stderr, "--valves: '%s' is not a draw's number (0-100000, comma-separated)\n", j.c_str());
          return 2;
        }
        valves.insert(static_cast<int>(n));
        population = std::max(population, static_cast<int>(n) + 1);
      }
    } else if (arg == "--seed" && a + 1 < argc) {
      double v = 0.0;
      if (!ParseWhole("--seed", argv[++a], 0, 4000000, &v)) return 2;
      seed = static_cast<unsigned>(v);
    } else if (arg == "--design" && a + 1 < argc) {
      const std::string d = argv[++a];
      if (d != "one-supply" && d != "two-supplies") {
        std::fprintf(stderr, "--design: unknown design '%s' (one-supply, two-supplies)\n", d.c_str());
        return 2;
      }
      two_supplies = d == "two-supplies";
    } else {
      std::fprintf(stderr, "usage: perf_identify [--sets practice3,practice4|none] [--only SUBSTRING] [--evaluations N] "
                           "[--ode-steps N] [--population N] [--valves J,K,...] [--seed SEED] [--ablate flow,stribeck,ladder,eddy,core,scope] "
                           "[--design one-supply|two-supplies] [--verbose] [--edges] [--noise]\n");
      return 2;
    }
  }
  const auto family = vb::model::Preset("taghizadeh2009");
  if (!family.ok()) return 1;
  std::printf("load average at the start: %s; %d evaluations and %lld solver steps per identification\n",
              LoadAverage().c_str(), evaluations,
              static_cast<long long>(ode_steps >= 0 ? ode_steps : vb::gap::MovingIdentifyOptions{}.max_ode_steps));
  std::printf("%-18s %-9s %-9s %-52s %-4s %7s %7s\n", "case", "kind", "truth", "result", "ok", "s", "cpu_s");
  Tally all, predict, withheld;
  // The identification's verdict on its own prediction against what the holdouts show (valves), and the band's
  // coverage (holdout runs): for practice4's predict cases and for the population.
  struct Band {
    int pass = 0, miss = 0, flagged_pass = 0, flagged_miss = 0;  // valves
    int runs = 0, covered = 0, outcome_seen = 0;                 // holdout runs
  } pband, band;
  std::stringstream names(sets);
  for (std::string set; std::getline(names, set, ',');) {
    if (set == "none") continue;
    const fs::path root = fs::path(VB_SHARED_DIR) / "gapbench" / set;
    std::ifstream lf(root / "labels.json");
    if (!lf) {
      std::printf("%s: no labels.json, skipped\n", root.c_str());
      continue;
    }
    const nlohmann::json labels = nlohmann::json::parse(lf);
    for (const auto& [name, label] : labels.items()) {
      if (!only.empty() && name.find(only) == std::string::npos) continue;
      const std::string kind = label.value("kind", "");
      const auto t0 = Clock::now();
      const double c0 = CpuSeconds();
      bool ok = false;
      std::string result, truth = label.value("truth", "-");
      if (kind == "predict") {
        auto ds = vb::gap::LoadDataset((root / name).string(), vb::model::PresetNames());
        if (!ds.ok()) {
          result = "load: " + ds.status().message();
        } else {
          vb::gap::MovingIdentifyOptions mo;
          mo.max_evaluations = evaluations;
          if (ode_steps >= 0) mo.max_ode_steps = ode_steps;
          if (verbose) mo.progress = [](const std::string& l) { std::fprintf(stderr, "  %s\n", l.c_str()); };
          auto id = vb::gap::IdentifyMovingValve(*ds, *family, mo);
          if (!id.ok()) {
            result = "refused: " + id.status().message();
          } else {
            const double limit = std::max(5e-3, 3.0 * id->noise_floor_A);
            char buf[160];
            std::snprintf(buf, sizeof buf, "fit %.2f holdout %.2f mA (limit %.1f, noise %.2f)", id->fit_rmse_A * 1e3,
                          id->holdout_rmse_after_A * 1e3, limit * 1e3, id->noise_floor_A * 1e3);
            result = buf;
            ok = std::isfinite(id->holdout_rmse_after_A) && id->holdout_rmse_after_A <= limit;
            (ok ? pband.flagged_pass : pband.flagged_miss) += !id->prediction_undetermined.empty();
            if (verbose && !id->prediction_undetermined.empty())
              std::printf("    prediction undetermined: %s\n", id->prediction_undetermined.c_str());
            (ok ? pband.pass : pband.miss) += 1;
          }
        }
      } else if (kind == "withheld") {
        auto target = vb::gap::LoadDataset((root / name / "target").string(), vb::model::PresetNames());
        auto reference = vb::gap::LoadDataset((root / name / "reference").string(), vb::model::PresetNames());
        if (!target.ok() || !reference.ok()) {
          result = "load: " + (target.ok() ? reference.status() : target.status()).message();
        } else {
          vb::gap::DiagnoseOptions o;
          o.reference = &*reference;
          o.reference_fit.scratch_max_evaluations = evaluations;
          if (ode_steps >= 0) o.reference_fit.scratch_max_ode_steps = ode_steps;
          if (verbose) o.reference_fit.scratch_progress = [](const std::string& l) { std::fprintf(stderr, "  %s\n", l.c_str()); };
          auto d = vb::gap::Diagnose(*target, *family, o);
          if (!d.ok()) {
            result = "refused: " + d.status().message();
          } else {
            char buf[200];
            std::snprintf(buf, sizeof buf, "%s (ref fit %.2f mA)", d->verdict.c_str(), d->reference.fit_rmse_A * 1e3);
            result = buf;
            for (const auto& w : label.at("accept"))
              ok = ok || Lower(d->verdict).find(Lower(w.get<std::string>())) != std::string::npos;
          }
        }
      } else {
        continue;
      }
      const double s = std::chrono::duration<double>(Clock::now() - t0).count();
      const double cpu = CpuSeconds() - c0;
      if (result.size() > 52) result = result.substr(0, 52);
      std::printf("%-18s %-9s %-9s %-52s %-4s %7.1f %7.1f\n", name.c_str(), kind.c_str(), truth.c_str(), result.c_str(),
                  ok ? "yes" : "NO", s, cpu);
      std::fflush(stdout);
      for (Tally* t : {&all, kind == "predict" ? &predict : &withheld}) {
        t->ok += ok;
        ++t->n;
        t->seconds += s;
        t->worst_s = std::max(t->worst_s, s);
        t->cpu_s += cpu;
        t->worst_cpu_s = std::max(t->worst_cpu_s, cpu);
      }
    }
  }
  Tally pop, strict;
  // --edges: each holdout run of a draw whose fit runs are within 3x the noise floor (the only predictions the
  // verdict could otherwise trust), for the edge's bias and the rule's trade printed at the end.
  struct EdgeRun {
    double bias;             // |identified - true| edge, log supply
    double e_id;             // the identified edge's distance (+-log 2 when beyond the range)
    bool wrong_outcome, miss;
    double applied;          // the bias the identification judged its edges with (its fit runs' design)
  };
  std::vector<EdgeRun> edge_runs;
  // --noise: each run's noise estimate from second differences over the chain's own noise, with every sample and
  // between the gate's edges (gap/dataset.h), without identifying anything.
  std::vector<double> noise_ratio_all, noise_ratio_between;
  for (int j = 0; j < population; ++j) {
    if (!valves.empty() && !valves.count(j)) continue;
    std::mt19937 rng(seed * 1000u + static_cast<unsigned>(j));
    vb::perf::IndependentValve v = vb::perf::DrawValve(rng);
    auto has = [&](const char* form) { return ablate.find(form) != std::string::npos; };
    if (has("flow")) v.c_flow = 0.0;
    if (has("stribeck")) v.Fc_N = v.Fs_N = 0.0;
    if (has("ladder") || has("eddy")) v.Re2_ohm = 1e12, v.Le2_H = 1e12;  // the second rung carries nothing (tau 1 s)
    if (has("eddy")) v.Re1_ohm = 1e12;
    if (has("core")) v.linear_core_mu_r = 3000.0;
    if (has("scope")) v.offset_A = v.spike_A = 0.0;
    std::vector<vb::perf::SessionRun> runs = {
        {v.supply_V, 1}, {v.supply_V, 2}, {v.supply_V, 4}, {v.supply_V, 6, true}, {0.75 * v.supply_V, 4, true}};
    if (two_supplies) runs.push_back({0.75 * v.supply_V, 1});
    const vb::gap::Dataset ds = vb::perf::IndependentSession(v, runs, rng, "independent-" + std::to_string(j), true);
    if (noise_only) {
      // The chain's own noise per sample: one sweep's noise averaged over the sweeps, and the rounding to the
      // scope's step (uniform, step^2 / 12).
      const double chain_A = std::sqrt(v.noise_A * v.noise_A / v.averaged + v.lsb_A * v.lsb_A / 12.0);
      for (const auto& run : ds.runs) {
        noise_ratio_all.push_back(vb::gap::SecondDifferenceSigma(run.i_A) / chain_A);
        noise_ratio_between.push_back(vb::gap::SecondDifferenceSigma(run.i_A, run.gate, run.sample_period_s) / chain_A);
      }
      continue;
    }
    const auto t0 = Clock::now();
    const double c0 = CpuSeconds();
    vb::gap::MovingIdentifyOptions mo;
    mo.max_evaluations = evaluations;
    if (ode_steps >= 0) mo.max_ode_steps = ode_steps;
    if (verbose) mo.progress = [](const std::string& l) { std::fprintf(stderr, "  %s\n", l.c_str()); };
    auto id = vb::gap::IdentifyMovingValve(ds, *family, mo);
    if (id.ok() && verbose)
      std::fprintf(stderr, "  %s: %.4g solver steps, %d evaluations, %.3g us of CPU per step\n",
                   ("indep_" + std::to_string(j)).c_str(), static_cast<double>(id->ode_steps), id->evaluations,
                   1e6 * (CpuSeconds() - c0) / std::max<double>(1.0, static_cast<double>(id->ode_steps)));
    const double s = std::chrono::duration<double>(Clock::now() - t0).count();
    const double cpu = CpuSeconds() - c0;
    char buf[200];
    bool ok = false, tight = false;
    if (!id.ok()) {
      std::snprintf(buf, sizeof buf, "refused: %.44s", id.status().message().c_str());
    } else {
      const double limit = std::max(5e-3, 3.0 * id->noise_floor_A);
      ok = id->holdout_rmse_after_A <= limit;
      tight = id->fit_rmse_A <= 3.0 * id->noise_floor_A && id->holdout_rmse_after_A <= 3.0 * id->noise_floor_A;
      std::snprintf(buf, sizeof buf, "fit %.2f holdout %.2f mA (limit %.1f, noise %.2f)", id->fit_rmse_A * 1e3,
                    id->holdout_rmse_after_A * 1e3, limit * 1e3, id->noise_floor_A * 1e3);
    }
    char name[32], truth[32];
    std::snprintf(name, sizeof name, "indep_%d", j);
    std::snprintf(truth, sizeof truth, "%gV %.2gA", v.supply_V, v.supply_V / v.R_ohm);
    std::printf("%-18s %-9s %-9s %-52s %-4s %7.1f %7.1f\n", name, "predict", truth, buf, ok ? (tight ? "yes" : "yes~") : "NO",
                s, cpu);
    // Where the work budget (MovingIdentifyOptions::max_ode_steps) ended a stage: the valves it changed.
    if (id.ok()) {
      for (const auto& n : id->notes)
        if (n.rfind("the work budget", 0) == 0 || n.find("share of the work (") != std::string::npos)
          std::printf("    %s: %.3g solver steps; %s\n", name, static_cast<double>(id->ode_steps), n.c_str());
    }
    // Is a miss said beforehand (the identification's own verdict on its prediction,
    // MovingIdentification::prediction_undetermined)? And does the band cover what the holdout shows (RMSE within
    // 3x the noise and the band's spread together)?
    if (id.ok()) {
      const bool warned = !id->prediction_undetermined.empty();
      for (const auto& m : id->landmarks) {
        if (m.split != vb::Split::kHoldout || m.band_draws == 0) continue;
        ++band.runs;
        const double spread = std::isfinite(m.band_spread_A) ? m.band_spread_A : 0.0;
        band.covered += m.rmse_A <= 3.0 * std::hypot(id->noise_floor_A, spread);
        band.outcome_seen += m.measured.pulls_in ? m.band_pull_in_draws > 0 : m.band_pull_in_draws < m.band_draws;
      }
      (ok ? band.flagged_pass : band.flagged_miss) += warned;
      if (!ok && !warned) std::printf("    a miss the identification trusted: %s\n", name);
      (ok ? band.pass : band.miss) += 1;
    }
    if (edges && id.ok()) {
      for (std::size_t r = 0; r < ds.runs.size(); ++r) {
        const auto& m = id->landmarks[r];
        if (m.split != vb::Split::kHoldout) continue;
        const auto& run = ds.runs[r];
        std::size_t on = 0;
        while (on < run.gate.size() && run.gate[on] == 0) ++on;
        auto truth_pulls = [&](double ratio) {
          const auto i =
              vb::perf::SimulateSwitchOn(v, ratio * run.supply_V, run.supply_pressure_Pa, run.i_A.size(), on);
          return vb::gap::FindSwitchOnMarks(i, run.gate, run.sample_period_s, 4.0 * id->noise_floor_A).pulls_in;
        };
        bool outside = false;
        const double e_true = vb::gap::PullInEdgeLogSupply(truth_pulls, &outside);
        const double limit = std::max(5e-3, 3.0 * id->noise_floor_A);
        // Both beyond the range on one side: the bias is not known, and neither run is near an edge.
        const bool both_beyond = outside && m.edge_outside && e_true * m.edge_log_supply > 0.0;
        if (id->fit_rmse_A <= 3.0 * id->noise_floor_A && std::isfinite(m.edge_log_supply) && !both_beyond)
          edge_runs.push_back({std::abs(m.edge_log_supply - e_true), m.edge_log_supply,
                               m.measured.pulls_in != m.predicted.pulls_in, m.rmse_A > limit,
                               id->pull_in_edge_bias_log_supply});
        std::printf("    edge %s %s run %-12s id %+.4f%s true %+.4f%s fit/noise %.2f trusted %s rmse %.2f limit %.2f "
                    "measured %s predicted %s bias %.3f\n",
                    name, ablate.empty() ? "full" : "ablated", m.run.c_str(), m.edge_log_supply,
                    m.edge_outside ? "*" : "", e_true, outside ? "*" : "", id->fit_rmse_A / id->noise_floor_A,
                    id->prediction_undetermined.empty() ? "yes" : "no", m.rmse_A * 1e3,
                    std::max(5e-3, 3.0 * id->noise_floor_A) * 1e3, m.measured.pulls_in ? "pull" : "none",
                    m.predicted.pulls_in ? "pull" : "none", id->pull_in_edge_bias_log_supply);
      }
    }
    if (verbose && id.ok() && !id->prediction_undetermined.empty())
      std::printf("    prediction undetermined: %s\n", id->prediction_undetermined.c_str());
    if (verbose && id.ok())
      for (const auto& n : id->notes) std::printf("    note: %s\n", n.c_str());
    if (verbose && id.ok()) {  // each run: measured and predicted pull-in (the dip), its RMSE and band
      for (const auto& m : id->landmarks) {
        std::printf("    %-12s %s %4.1f V %3.0f bar  pull-in measured %s %.2f ms, model %s %.2f ms  rmse %.2f mA\n",
                    m.run.c_str(), m.split == vb::Split::kHoldout ? "holdout" : "fit    ", m.supply_V,
                    m.pressure_Pa / 1e5, m.measured.pulls_in ? "yes" : "no ", m.measured.pull_in_s * 1e3,
                    m.predicted.pulls_in ? "yes" : "no ", m.predicted.pull_in_s * 1e3, m.rmse_A * 1e3);
        if (m.band_draws > 0)
          std::printf("    %-12s band: spread %.2f mA, %d of %d draws pull in%s\n", m.run.c_str(),
                      m.band_spread_A * 1e3, m.band_pull_in_draws, m.band_draws,
                      m.pull_in_undetermined ? " (UNDETERMINED)" : "");
      }
    }
    std::fflush(stdout);
    for (Tally* t : {&pop}) {
      t->ok += ok;
      ++t->n;
      t->seconds += s;
      t->worst_s = std::max(t->worst_s, s);
      t->cpu_s += cpu;
      t->worst_cpu_s = std::max(t->worst_cpu_s, cpu);
    }
    strict.ok += tight;
    ++strict.n;
  }
  auto line = [](const char* what, const Tally& t) {
    const auto [lo, hi] = Wilson(t.ok, t.n);
    std::printf("%-9s %2d of %2d (%.0f %%, Wilson 95 %% %.0f-%.0f %%); %.1f s per case, worst %.1f s; CPU %.1f s per "
                "case, worst %.1f s\n",
                what, t.ok, t.n, t.n ? 100.0 * t.ok / t.n : 0.0, 100.0 * lo, 100.0 * hi, t.n ? t.seconds / t.n : 0.0,
                t.worst_s, t.n ? t.cpu_s / t.n : 0.0, t.worst_cpu_s);
  };
  line("predict", predict);
  if (pband.pass + pband.miss > 0)
    std::printf("predict  prediction undetermined: on %d of %d misses, on %d of %d passes\n", pband.flagged_miss,
                pband.miss, pband.flagged_pass, pband.pass);
  line("withheld", withheld);
  line("all", all);
  if (population > 0) {
    line("indep.", pop);
    line("strict", strict);
    const auto [mlo, mhi] = Wilson(band.flagged_miss, band.miss);
    const auto [plo, phi] = Wilson(band.flagged_pass, band.pass);
    const auto [clo, chi] = Wilson(band.covered, band.runs);
    std::printf("band     misses said beforehand (prediction undetermined): %d of %d (Wilson 95 %% %.0f-%.0f %%); "
                "passes flagged anyway: %d of %d (%.0f-%.0f %%)\n",
                band.flagged_miss, band.miss, 100.0 * mlo, 100.0 * mhi, band.flagged_pass, band.pass, 100.0 * plo,
                100.0 * phi);
    std::printf("band     holdout runs within 3x hypot(noise, band spread): %d of %d (%.0f-%.0f %%); measured pull-in "
                "among the draws' outcomes: %d of %d\n",
                band.covered, band.runs, 100.0 * clo, 100.0 * chi, band.outcome_seen, band.runs);
  }
  if (noise_only && !noise_ratio_all.empty()) {
    // How far each estimate lies from the chain's noise, over every run of the draws: its percentiles and how
    // many runs it reads over 1.5x (a fit at the noise would then be judged against a floor half again too high)
    // or under 0.67x.
    for (auto* pr : {&noise_ratio_all, &noise_ratio_between}) {
      std::vector<double> r = *pr;
      std::sort(r.begin(), r.end());
      const int n = static_cast<int>(r.size());
      auto q = [&](double f) { return r[static_cast<std::size_t>(std::clamp(static_cast<int>(std::ceil(f * n)) - 1, 0, n - 1))]; };
      const int over = static_cast<int>(std::count_if(r.begin(), r.end(), [](double x) { return x > 1.5; }));
      const int under = static_cast<int>(std::count_if(r.begin(), r.end(), [](double x) { return x < 1.0 / 1.5; }));
      const auto [olo, ohi] = Wilson(over, n);
      std::printf("noise    %s: estimate / chain over %d runs: 5th %.2f, median %.2f, 95th %.2f, largest %.2f; over 1.5x "
                  "%d (%.1f %%, Wilson 95 %% %.1f-%.1f %%), under 1/1.5 %d\n",
                  pr == &noise_ratio_all ? "every sample       " : "between gate edges", n, q(0.05), q(0.5), q(0.95),
                  r.back(), over, 100.0 * over / n, 100.0 * olo, 100.0 * ohi, under);
    }
  }
  // One block per fit-run design the identifications judged their edges with (MovingIdentification::
  // pull_in_edge_design: pulling-in fit runs at one supply or at two), each with the bias its rule applies: a
  // rule is calibrated on the runs of its own design.
  for (const double design_bias : {vb::gap::kPullInEdgeBiasLogSupply, vb::gap::kPullInEdgeBiasLogSupplyTwoSupplies}) {
    if (!edges) break;
    // The bias's percentiles, each with a 95 % interval from the order statistics (the ranks a binomial(n, q)
    // count of samples below the percentile reaches with 2.5 % and 97.5 %).
    std::vector<double> b;
    for (const auto& r : edge_runs)
      if (r.applied == design_bias) b.push_back(r.bias);
    if (b.empty()) continue;
    std::sort(b.begin(), b.end());
    const int n = static_cast<int>(b.size());
    auto rank = [&](double q, double p) {  // smallest k with P(Binomial(n, q) <= k) >= p
      double acc = 0.0;
      for (int k = 0; k <= n; ++k) {
        acc += std::exp(std::lgamma(n + 1.0) - std::lgamma(k + 1.0) - std::lgamma(n - k + 1.0) + k * std::log(q) +
                        (n - k) * std::log1p(-q));
        if (acc >= p) return k;
      }
      return n;
    };
    const bool two = design_bias == vb::gap::kPullInEdgeBiasLogSupplyTwoSupplies;
    std::printf("edges    pulling-in fit runs at %s: bias |log(V_edge,identified / V_edge,true)| over %d holdout runs "
                "of valves fitted within 3x the noise:\n", two ? "two supplies" : "one supply", n);
    for (double q : {0.5, 0.9, 0.95}) {
      const int k = std::clamp(static_cast<int>(std::ceil(q * n)) - 1, 0, n - 1);
      const int lo = std::clamp(rank(q, 0.025) - 1, 0, n - 1), hi = std::clamp(rank(q, 0.975), 0, n - 1);
      std::printf("edges      %2.0fth percentile %.3f (95 %% interval %.3f-%.3f)\n", 100.0 * q, b[k], b[lo], b[hi]);
    }
    const double c = design_bias;
    std::printf("edges    the rule's trade (the bias applied, %.3f): runs by the identified edge's distance\n", c);
    const std::pair<double, double> bins[] = {{0.0, std::min(0.1, c)}, {std::min(0.1, c), c}, {c, INFINITY}};
    for (const auto& [lo, hi] : bins) {
      if (!(hi > lo)) continue;
      int runs = 0, wrong = 0, miss = 0;
      for (const auto& r : edge_runs)
        if (r.applied == design_bias && std::abs(r.e_id) >= lo && std::abs(r.e_id) < hi) {
          ++runs;
          wrong += r.wrong_outcome;
          miss += r.miss;
        }
      const auto [mlo, mhi] = Wilson(miss, runs);
      std::printf("edges      [%.3f, %.3f): %3d runs, wrong outcome %3d, over the limit %3d (%.0f-%.0f %%)\n", lo, hi,
                  runs, wrong, miss, 100.0 * mlo, 100.0 * mhi);
    }
  }
  std::printf("load average at the end: %s\n", LoadAverage().c_str());
  return 0;
}
