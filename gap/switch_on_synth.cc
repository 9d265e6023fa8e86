#include "gap/switch_on_synth.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>

#include "gap/replay.h"

namespace vb::gap {

Status WriteSwitchOnSession(const std::string& directory, const model::PlantParams& truth,
                            const std::vector<SwitchOnRunPlan>& runs, const ScopeChain& scope,
                            const std::string& device, const std::string& model_family, double t_start_s) {
  if (runs.empty()) return Status::InvalidArgument("runs: at least one run");
  if (!(scope.sample_period_s > 0.0) || !(scope.duration_s > scope.pre_trigger_s) || scope.pre_trigger_s < 0.0)
    return Status::InvalidArgument("scope: sample_period_s > 0 and duration_s > pre_trigger_s >= 0");
  if (scope.averaged < 1 || !(scope.noise_A >= 0.0) || !(scope.lsb_A >= 0.0))
    return Status::InvalidArgument("scope: averaged >= 1, noise_A >= 0, lsb_A >= 0");
  std::error_code ec;
  std::filesystem::create_directories(directory, ec);
  if (ec) return Status::InvalidArgument(directory + ": " + ec.message());
  const std::size_t n = static_cast<std::size_t>(std::llround(scope.duration_s / scope.sample_period_s)) + 1;
  std::vector<std::int8_t> gate(n, 0);
  for (std::size_t k = 0; k < n; ++k)
    gate[k] = static_cast<double>(k) * scope.sample_period_s >= scope.pre_trigger_s - 1e-12 ? 1 : 0;
  std::vector<SessionRun> session;
  for (std::size_t r = 0; r < runs.size(); ++r)
    session.push_back({runs[r].supply_V, runs[r].supply_pressure_Pa, scope.sample_period_s, t_start_s + 2.0 * r, &gate});
  auto reps = ReplaySession(truth, model::DriverParams{}, session);
  if (!reps.ok()) return reps.status().WithContext("synthetic session");
  std::mt19937 rng(scope.seed);
  std::normal_distribution<double> noise(0.0, scope.noise_A);
  nlohmann::ordered_json m;
  m["format"] = "valve-runs/2";
  m["model"] = model_family;
  m["device"] = device;
  m["description"] = "synthetic switch-on session (gap/switch_on_synth.h)";
  m["sensor"] = {{"noise_A", scope.noise_A}, {"averaged", scope.averaged}, {"adc_lsb_A", scope.lsb_A}};
  nlohmann::ordered_json list = nlohmann::ordered_json::array();
  std::uniform_int_distribution<std::size_t> where(0, n - 1);
  std::size_t on = 0;
  while (on < n && gate[on] == 0) ++on;
  for (std::size_t r = 0; r < runs.size(); ++r) {
    const auto& plan = runs[r];
    std::vector<bool> glitch(n, false);
    for (int g = 0; g < scope.glitches; ++g) glitch[where(rng)] = true;
    const std::string file = plan.id + ".csv";
    std::ofstream out(directory + "/" + file);
    if (!out) return Status::InvalidArgument(directory + "/" + file + ": cannot write");
    out << "t_s,gate,i_A\n";
    char buf[96];
    for (std::size_t k = 0; k < n; ++k) {
      double sum = 0.0;
      const double truth_A = scope.open_coil ? 0.0 : (*reps)[r].i_A[k];
      for (int s = 0; s < scope.averaged; ++s) sum += truth_A + noise(rng);
      double i = sum / scope.averaged + scope.offset_A;
      if (k >= on && k < on + static_cast<std::size_t>(std::max(scope.spike_samples, 0)))
        i += scope.spike_A * std::pow(0.5, static_cast<double>(k - on));
      const double t = static_cast<double>(k) * scope.sample_period_s + t_start_s + 2.0 * static_cast<double>(r);
      i += scope.ripple_A * std::sin(2.0 * M_PI * scope.ripple_Hz * t);
      if (glitch[k]) i += scope.glitch_A;
      if (scope.clip_A > 0.0) i = std::clamp(i, -scope.clip_A, scope.clip_A);
      if (scope.inverted) i = -i;
      if (scope.lsb_A > 0.0) i = std::round(i / scope.lsb_A) * scope.lsb_A;
      std::snprintf(buf, sizeof buf, "%.5f,%d,%.6g\n", static_cast<double>(k) * scope.sample_period_s, gate[k], i);
      out << buf;
    }
    nlohmann::ordered_json run = {{"id", plan.id},
                                  {"file", file},
                                  {"supply_V", plan.supply_V},
                                  {"supply_pressure_Pa", plan.declared_pressure_Pa >= 0.0 ? plan.declared_pressure_Pa
                                                                                          : plan.supply_pressure_Pa},
                                  {"t_start_s", t_start_s + 2.0 * static_cast<double>(r)}};
    if (!plan.split.empty()) run["split"] = plan.split;
    list.push_back(run);
  }
  m["runs"] = list;
  std::ofstream mf(directory + "/manifest.json");
  if (!mf) return Status::InvalidArgument(directory + "/manifest.json: cannot write");
  mf << m.dump(1) << "\n";
  return Status::Ok();
}

}  // namespace vb::gap
