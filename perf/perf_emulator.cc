// Emulator speed and accuracy on the standard experiments E1-E3: simulated seconds per wall second on one
// core, the current error against ../shared/perfref (CVODE Adams rtol 1e-11), and the work done. Two
// levels: the bare simulator producing 50 kHz samples in memory (what perfref/README.md times CVODE doing),
// and the full local path (spec -> Runner -> EmulatedBench -> recorded trace with all channels).
// Prints figures; targets: >= 500x real time on E1, and faster than CVODE Adams at rtol 1e-6 (perfref/README).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>
#include <vector>

#include "experiment/runner.h"
#include "hw/emulated_bench.h"
#include "model/simulator.h"

namespace {

using Clock = std::chrono::steady_clock;

struct Collect final : vb::model::SimObserver {
  std::vector<double> i;
  void OnSample(const vb::model::PlantSample& s) override { i.push_back(s.i_A); }
};

std::vector<double> LoadRef(const std::string& name) {
  std::vector<double> out;
  std::ifstream in(std::string(VB_SHARED_DIR) + "/perfref/truth_" + name + ".csv");
  std::string line;
  std::getline(in, line);
  while (std::getline(in, line)) {
    double t, i, x;
    if (std::sscanf(line.c_str(), "%lf,%lf,%lf", &t, &i, &x) == 3) out.push_back(i);
  }
  return out;
}

double Rms(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.size() != b.size() || a.empty()) return NAN;
  double s = 0;
  for (size_t k = 0; k < a.size(); ++k) s += (a[k] - b[k]) * (a[k] - b[k]);
  return std::sqrt(s / a.size());
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main() {
  struct Case {
    const char* name;
    const char* spec;
    double cvode_adams_ms;  // ../shared/perfref/README.md, rtol 1e-6, 2-core Xeon like CI's
    double cvode_err_uA;
  };
  const Case cases[] = {{"E1", "e1", 9.9, 0.86}, {"E2", "e2", 17.2, 0.49}, {"E3", "e3", 0.79, 0.81}};
  std::printf("%-4s %-10s %12s %12s %14s %12s %10s %9s  %s\n", "exp", "level", "median_ms", "x_realtime",
              "rms_err_A", "ode_steps", "restarts", "samples", "CVODE Adams rtol 1e-6 (perfref)");
  for (const Case& c : cases) {
    auto spec = vb::experiment::LoadSpecFile(std::string(VB_SOURCE_DIR) + "/examples/standard/" + c.spec + ".json");
    if (!spec.ok()) {
      std::fprintf(stderr, "%s\n", spec.status().message().c_str());
      return 2;
    }
    auto e = vb::experiment::BuildExperiment(*spec);
    if (!e.ok()) {
      std::fprintf(stderr, "%s\n", e.status().message().c_str());
      return 2;
    }
    const std::vector<double> ref = LoadRef(c.name);

    // Level 1: the bare simulator driven by the bench's PWM peripheral, samples into memory.
    {
      vb::hw::EmulatedBench bench(vb::experiment::EmulatedBenchFor(*e));
      std::vector<double> times;
      double err = NAN;
      std::uint64_t steps = 0, restarts = 0;
      size_t samples = 0;
      for (int rep = 0; rep < 15; ++rep) {
        vb::experiment::Trace trace;
        const auto t0 = Clock::now();
        vb::experiment::Runner::Run(*e, bench, &trace);
        times.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
        err = Rms(trace.i_A, ref);
        steps = bench.simulator().ode_steps();
        restarts = bench.simulator().restarts();
        samples = trace.size();
      }
      const double med = Median(times);
      std::printf("%-4s %-10s %12.3f %12.0f %14.3g %12llu %10llu %9zu  %.2f ms, %.2f uA RMS\n", c.name, "runner",
                  med * 1e3, e->duration_s / med, err, static_cast<unsigned long long>(steps),
                  static_cast<unsigned long long>(restarts), samples, c.cvode_adams_ms, c.cvode_err_uA);
    }
    {
      vb::model::Plant plant(e->plant);
      vb::model::Simulator sim(plant, e->driver, vb::model::Conditions{e->run.supply_V, e->run.supply_pressure_Pa});
      const auto& seg = spec->controller().open_loop_pwm().segments();
      std::vector<double> times;
      double err = NAN;
      size_t samples = 0;
      for (int rep = 0; rep < 15; ++rep) {
        Collect col;
        col.i.reserve(ref.size() + 1);
        const auto t0 = Clock::now();
        sim.Reset();
        sim.SetSamplePeriod(1.0 / e->run.sample_rate_Hz);
        for (int s = 0; s < seg.size(); ++s) {
          const double start = seg[s].start_s();
          const double end = s + 1 < seg.size() ? seg[s + 1].start_s() : e->duration_s;
          if (seg[s].frequency_hz() == 0.0) {
            sim.AdvanceTo(start, &col);
            sim.SetGate(seg[s].duty() >= 0.5 ? 1 : 0);
            continue;
          }
          const double T = 1.0 / seg[s].frequency_hz();
          for (long n = 0; start + n * T < end - 1e-12; ++n) {
            const double ts = start + n * T, te = ts + seg[s].duty() * T;
            sim.AdvanceTo(ts, &col);
            sim.SetGate(1);
            sim.AdvanceTo(std::min(te, end), &col);
            if (te < end) sim.SetGate(0);
          }
        }
        sim.AdvanceTo(e->duration_s, &col);
        sim.EmitPendingSample(&col);
        times.push_back(std::chrono::duration<double>(Clock::now() - t0).count());
        err = Rms(col.i, ref);
        samples = col.i.size();
      }
      const double med = Median(times);
      std::printf("%-4s %-10s %12.3f %12.0f %14.3g %12llu %10llu %9zu\n", c.name, "simulator", med * 1e3,
                  e->duration_s / med, err, static_cast<unsigned long long>(sim.ode_steps()),
                  static_cast<unsigned long long>(sim.restarts()), samples);
    }
  }
  std::printf("targets: E1 >= 500x real time on one core; faster than CVODE Adams at the same or better accuracy\n");
  return 0;
}
