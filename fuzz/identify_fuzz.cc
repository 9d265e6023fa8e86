// A moving valve identified from scratch (gap::IdentifyMovingValve, `benchctl identify DIR` on switch-on runs) on
// any capture: it must end in a finite fit or a refusal, never a NaN in what it returns, a crash, UB or a hang
// (issue 35, point 2). The input is the session, built in memory (no files: the loader has its own target):
//   byte 0: the supply (12 + byte/4 V), byte 1: the number of runs (1 + byte % 4), byte 2: the sample period
//   (10 us x (1 + byte % 10)), byte 3: bit 0 = the first run is a holdout run, bit 1 = runs share one pressure,
//   bits 2-3 = the current's scale (0.1, 0.3, 1, 3 A full scale over a byte); then each run's samples, one byte
//   each (the current on a 0..255 grid), the runs cut in equal parts (at most 300 samples each), the gate rising
//   at the fifth sample. The search runs on a small budget, one thread: each input takes well under a second.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "gap/dataset.h"
#include "gap/moving_valve.h"
#include "model/params.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const vb::model::PlantParams family = *vb::model::Preset("taghizadeh2009");
  if (size < 4 + 16) return 0;
  const double supply_V = 12.0 + data[0] / 4.0;
  const std::size_t runs = 1 + data[1] % 4;
  const double dt = 1e-5 * (1 + data[2] % 10);
  const bool holdout_first = data[3] & 1, one_pressure = data[3] & 2;
  static const double kFullScale_A[] = {0.1, 0.3, 1.0, 3.0};
  const double scale_A = kFullScale_A[(data[3] >> 2) & 3] / 255.0;
  const std::size_t per_run = std::min<std::size_t>((size - 4) / runs, 300);
  if (per_run < 8) return 0;
  vb::gap::Dataset ds;
  ds.format = vb::gap::kFormatValveRuns2;
  ds.model = "taghizadeh2009";
  ds.device = "fuzz";
  for (std::size_t r = 0; r < runs; ++r) {
    vb::gap::RunData run;
    run.id = "run" + std::to_string(r);
    run.supply_V = supply_V;
    run.supply_pressure_Pa = one_pressure ? 3e5 : 1e5 * static_cast<double>(r + 1);
    run.t_start_s = 2.0 * static_cast<double>(r);
    run.split = runs > 1 && holdout_first && r == 0 ? vb::Split::kHoldout : vb::Split::kFit;
    run.sample_period_s = dt;
    for (std::size_t k = 0; k < per_run; ++k) {
      run.t_s.push_back(static_cast<double>(k) * dt);
      run.gate.push_back(k >= 4 ? 1 : 0);
      run.i_A.push_back(data[4 + r * per_run + k] * scale_A);
    }
    ds.runs.push_back(std::move(run));
  }
  vb::gap::MovingIdentifyOptions o;
  o.max_evaluations = 300;  // a few stages' worth: the fuzzer checks guards, not fits
  o.threads = 1;
  auto id = vb::gap::IdentifyMovingValve(ds, family, o);
  if (!id.ok()) {
    if (id.status().message().empty()) std::abort();
    return 0;
  }
  // A fit that returns must be finite in everything it states.
  if (!std::isfinite(id->fit_rmse_A)) std::abort();
  for (const auto& [name, v] : id->values)
    if (!std::isfinite(v)) {
      std::fprintf(stderr, "identified %s is not finite\n", name.c_str());
      std::abort();
    }
  for (const auto& [name, v] : id->fitted)
    if (!std::isfinite(v)) {
      std::fprintf(stderr, "fitted %s is not finite\n", name.c_str());
      std::abort();
    }
  (void)vb::gap::MovingIdentificationJson(*id);
  (void)vb::gap::MovingIdentificationReport(*id);
  return 0;
}
