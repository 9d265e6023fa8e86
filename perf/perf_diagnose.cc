// The gap diagnosis on labelled datasets: time per dataset (target: < 60 s for a 12-run session on 2 cores)
// and whether the verdict names the labelled effect. Prints a table; it is a benchmark, not a test.
//
// Usage: perf_diagnose [--budget-scale X] [--rule evidence|issue26] [--level L] [DATASET_DIR...]   (default: every dataset under
//        ../shared/gapbench/practice, with labels.json beside them when present)
// --budget-scale X multiplies the diagnosis's wall-time budgets (whole and per candidate): on a machine shared
// with other work the wall clock runs out before the CPU work is done, which changes verdicts, not speed. The
// cpu_s column (process CPU time, both threads) is the figure that does not depend on the load.
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <cmath>
#include <cstdlib>
#include <ctime>
#include <set>
#include <string>
#include <vector>

#include "gap/dataset.h"
#include "gap/diagnose.h"
#include "model/params.h"

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  std::vector<std::string> dirs;
  double budget_scale = 1.0;
  int rule = -1;  // --rule: 0 the evidence rule, 1 issue 26's rules; -1 the library's default
  double level = 0.0;  // --level: the evidence rule's level; 0 the library's default
  for (int k = 1; k < argc; ++k) {
    if (std::string(argv[k]) == "--level" && k + 1 < argc) {
      level = std::atof(argv[++k]);
      if (!(level > 0.0)) {
        std::fprintf(stderr, "--level: must be > 0, got %s\n", argv[k]);
        return 2;
      }
      continue;
    }
    if (std::string(argv[k]) == "--rule" && k + 1 < argc) {
      const std::string v = argv[++k];
      if (v != "evidence" && v != "issue26") {
        std::fprintf(stderr, "--rule: evidence or issue26, got %s\n", v.c_str());
        return 2;
      }
      rule = v == "issue26" ? 1 : 0;
      continue;
    }
    if (std::string(argv[k]) == "--budget-scale" && k + 1 < argc) {
      budget_scale = std::atof(argv[++k]);
      if (!(budget_scale > 0.0)) {
        std::fprintf(stderr, "--budget-scale: must be > 0, got %s\n", argv[k]);
        return 2;
      }
      continue;
    }
    dirs.push_back(argv[k]);
  }
  const fs::path practice = fs::path(VB_SHARED_DIR) / "gapbench" / "practice";  // the default sets
  if (dirs.empty()) {
    for (const auto& e : fs::directory_iterator(practice))
      if (e.is_directory()) dirs.push_back(e.path().string());
    std::sort(dirs.begin(), dirs.end());
  }
  // Labels: labels.json beside each dataset (practice/, practice2/, or any set laid out the same way).
  auto labels_of = [](const fs::path& dataset_dir) {
    nlohmann::json labels;
    const fs::path parent = fs::absolute(dataset_dir).lexically_normal().parent_path();
    if (std::ifstream in(parent / "labels.json"); in) labels = nlohmann::json::parse(in, nullptr, false);
    return labels;
  };
  std::printf("%-6s %-22s %-40s %7s %7s %6s %7s %7s  %s\n", "data", "label", "verdict", "before", "after", "closed",
              "time_s", "cpu_s", "runner-up / confusable");
  int right = 0, labelled = 0;
  struct Score {
    int sets = 0;
    double hits = 0.0;
  };
  std::map<std::string, Score> scores;  // by label kind: single, multi, unknown, none
  std::vector<double> closure_raw, closure_floor;
  double total_s = 0.0, worst_s = 0.0, worst_cpu_s = 0.0;
  for (const auto& dir : dirs) {
    const std::string name = fs::path(dir).filename().string();
    auto ds = vb::gap::LoadDataset(dir, vb::model::PresetNames());
    if (!ds.ok()) {
      std::printf("%-6s load failed: %s\n", name.c_str(), ds.status().message().c_str());
      continue;
    }
    auto plant = vb::model::Preset(ds->model);
    if (!plant.ok()) continue;
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    vb::gap::DiagnoseOptions dopt;
    dopt.budget_s *= budget_scale;
    dopt.attribution.candidate_budget_s *= budget_scale;
    if (rule >= 0) dopt.issue26_rules = rule == 1;
    if (level > 0.0) dopt.addition_evidence = level;
    auto d = vb::gap::Diagnose(*ds, *plant, dopt);
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const double cpu_s = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
    worst_s = std::max(worst_s, secs);
    worst_cpu_s = std::max(worst_cpu_s, cpu_s);
    total_s += secs;
    if (!d.ok()) {
      std::printf("%-6s diagnose failed: %s\n", name.c_str(), d.status().message().c_str());
      continue;
    }
    std::string label = "?";
    const nlohmann::json labels = labels_of(fs::path(dir));
    std::set<std::string> want;  // several effects at once: any order
    std::string kind, cause;
    if (labels.is_object() && labels.contains(name) && labels[name].is_object() && labels[name].contains("effect")) {
      const auto& l = labels[name];
      const auto& e = l["effect"];
      if (e.is_string()) want.insert(e.get<std::string>());
      if (e.is_array())
        for (const auto& x : e)
          if (x.is_string()) want.insert(x.get<std::string>());
      if (!want.empty()) {
        label.clear();
        for (const auto& w : want) label += (label.empty() ? "" : "+") + w;
      }
      kind = l.contains("kind") && l["kind"].is_string() ? l["kind"].get<std::string>()
             : want.count("none")                      ? "none"
             : want.count("unknown")                   ? "unknown"
             : want.size() > 1                          ? "multi"
                                                        : "single";
      if (l.contains("cause") && l["cause"].is_string()) cause = l["cause"].get<std::string>();
    }
    std::set<std::string> got;
    for (std::size_t a = 0, b; a <= d->verdict.size(); a = b + 1) {
      b = d->verdict.find('+', a);
      if (b == std::string::npos) b = d->verdict.size();
      got.insert(d->verdict.substr(a, b - a));
    }
    // An effect outside the vocabulary: "unknown" is right, and naming the cause (where our catalog has it) is
    // better (gapbench README).
    const bool names_cause = !cause.empty() && got.count(cause) > 0;
    const bool is_right = !want.empty() && (got == want || (kind == "unknown" && names_cause));
    const double before = d->ranking.empty() ? d->holdout_rmse_A : d->ranking.front().holdout_rmse_before_A;
    const double after = d->ranking.empty() ? d->holdout_rmse_A : d->ranking.front().holdout_rmse_after_A;
    const double closed = d->ranking.empty() ? 0.0 : d->ranking.front().closed;
    if (label != "?") {
      ++labelled;
      right += is_right;
      Score& s = scores[kind];
      ++s.sets;
      if (kind == "multi") {
        std::size_t found = 0;
        for (const auto& w : want) found += got.count(w);
        s.hits += static_cast<double>(found) / static_cast<double>(want.size());
      } else {
        s.hits += is_right;
      }
      // Closure on sets with an effect: the verdict's holdout RMSE against the nominal's, 1 - after/before (noise
      // included, so a weak effect at 3 sigma cannot reach 1), and above the noise floor; 0 when unknown.
      if (kind == "single" || kind == "multi" || (kind == "unknown" && names_cause)) {
        const bool named = d->verdict != "unknown" && d->verdict != "none";
        closure_raw.push_back(named && before > 0.0 ? std::max(0.0, 1.0 - after / before) : 0.0);
        closure_floor.push_back(named ? closed : 0.0);
      }
    }
    std::string others;
    if (d->ranking.size() > 1) others = d->ranking[1].name;
    for (const auto& c : d->confusable) others += (others.empty() ? "" : ", ") + ("~" + c);
    std::printf("%-6s %-22s %-40s %7.2f %7.2f %5.0f%% %7.1f %7.1f  %s\n", name.c_str(), label.c_str(),
                (d->verdict + (is_right || label == "?" ? "" : "  (WRONG)")).c_str(), before * 1e3,
                after * 1e3, 100.0 * closed, secs, cpu_s, others.c_str());
    std::fflush(stdout);
  }
  auto mean = [](const std::vector<double>& v) {
    double s = 0.0;
    for (double x : v) s += x;
    return v.empty() ? NAN : s / static_cast<double>(v.size());
  };
  auto rate = [&](const char* k) {
    auto it = scores.find(k);
    return it == scores.end() || it->second.sets == 0 ? NAN : it->second.hits / it->second.sets;
  };
  std::printf("\nscores: top-1 %.2f (single-effect sets), out-of-vocabulary %.2f, multi-effect recall %.2f, "
              "none %.2f, closure %.2f (1 - after/before; %.2f above the noise floor)\n",
              rate("single"), rate("unknown"), rate("multi"), rate("none"), mean(closure_raw), mean(closure_floor));
  std::printf("\n%d of %d labelled verdicts right; %.1f s in all, slowest dataset %.1f s (target < 60 s), the most CPU "
              "%.1f s (budget scale %g)\n", right, labelled, total_s, worst_s, worst_cpu_s, budget_scale);
  return 0;
}
