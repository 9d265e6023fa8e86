// The gap diagnosis on labelled datasets: time per dataset (target: < 60 s for a 12-run session on 2 cores)
// and whether the verdict names the labelled effect. Prints a table; it is a benchmark, not a test.
//
// Usage: perf_diagnose [DATASET_DIR...]   (default: every dataset under ../shared/gapbench/practice, with
//        labels.json beside them when present)
#include <nlohmann/json.hpp>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "gap/dataset.h"
#include "gap/diagnose.h"
#include "model/params.h"

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  std::vector<std::string> dirs;
  for (int k = 1; k < argc; ++k) dirs.push_back(argv[k]);
  const fs::path practice = fs::path(VB_SHARED_DIR) / "gapbench" / "practice";
  if (dirs.empty()) {
    for (const auto& e : fs::directory_iterator(practice))
      if (e.is_directory()) dirs.push_back(e.path().string());
    std::sort(dirs.begin(), dirs.end());
  }
  nlohmann::json labels;
  if (std::ifstream in(practice / "labels.json"); in) labels = nlohmann::json::parse(in, nullptr, false);
  std::printf("%-6s %-22s %-40s %7s %7s %6s %7s  %s\n", "data", "label", "verdict", "before", "after", "closed",
              "time_s", "runner-up / confusable");
  int right = 0, labelled = 0;
  double total_s = 0.0, worst_s = 0.0;
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
    auto d = vb::gap::Diagnose(*ds, *plant);
    const double secs = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    total_s += secs;
    worst_s = std::max(worst_s, secs);
    if (!d.ok()) {
      std::printf("%-6s diagnose failed: %s\n", name.c_str(), d.status().message().c_str());
      continue;
    }
    std::string label = "?";
    if (labels.is_object() && labels.contains(name)) label = labels[name].value("effect", "?");
    if (label != "?") {
      ++labelled;
      right += d->verdict == label;
    }
    std::string others;
    if (d->ranking.size() > 1) others = d->ranking[1].name;
    for (const auto& c : d->confusable) others += (others.empty() ? "" : ", ") + ("~" + c);
    const double before = d->ranking.empty() ? d->holdout_rmse_A : d->ranking.front().holdout_rmse_before_A;
    const double after = d->ranking.empty() ? d->holdout_rmse_A : d->ranking.front().holdout_rmse_after_A;
    const double closed = d->ranking.empty() ? 0.0 : d->ranking.front().closed;
    std::printf("%-6s %-22s %-40s %7.2f %7.2f %5.0f%% %7.1f  %s\n", name.c_str(), label.c_str(),
                (d->verdict + (d->verdict == label ? "" : label == "?" ? "" : "  (WRONG)")).c_str(), before * 1e3,
                after * 1e3, 100.0 * closed, secs, others.c_str());
    std::fflush(stdout);
  }
  std::printf("\n%d of %d labelled verdicts right; %.1f s in all, slowest dataset %.1f s (target < 60 s)\n", right,
              labelled, total_s, worst_s);
  return 0;
}
