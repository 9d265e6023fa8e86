// A health check's hold measured without a model of the valve (gap::MeasureHold, gap::HoldValues: the hold runs of
// `benchctl track` sessions and of the server's nightly check; docs/track.md "The hold") on any capture: it must
// end in finite values or a refusal that says why, never a NaN in what it returns, a crash, UB or a hang. The
// input is one run, built in memory (the loader has its own target):
//   byte 0: bit 0 = v_coil_V recorded, bits 1-2 = the driver (low-side flyback, H-bridge, internal electronics,
//           low-side flyback again), bit 3 = the gate from the data (else a PWM pattern), bits 4-5 = the
//           current's full scale over a byte (0.03, 0.3, 3, 30 A), bit 6 = a sample is NaN, bit 7 = the current
//           inverted;
//   byte 1: the supply, byte / 8 V (0 included: not given);
//   byte 2: the sample period, 1 us x (1 + byte);
//   byte 3: the pattern's samples per PWM period, 2 + byte % 120; from 120 up, the pattern's last third is a
//           drop-out tail (the gate low);
//   byte 4: the pattern's duty, byte / 255;
//   byte 5: the pattern's samples before the gate rises (the baseline), byte;
//   then per sample: the current's byte, then with v_coil_V a voltage byte ((byte - 128) / 100 of the supply, a
//   volt when none is given), then with the gate from the data a gate byte (its low bit); at most 6000 samples.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "gap/dataset.h"
#include "gap/hold.h"
#include "model/driver.h"

namespace {

void Check(bool finite, const char* what) {
  if (finite) return;
  std::fprintf(stderr, "the hold's %s is not finite\n", what);
  std::abort();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 6) return 0;
  const std::uint8_t opt = data[0];
  const bool with_v = opt & 1, gate_from_data = opt & 8, nan_sample = opt & 64, inverted = opt & 128;
  static const vb::model::DriverKind kDrivers[] = {
      vb::model::DriverKind::kLowSideFlyback, vb::model::DriverKind::kHBridge,
      vb::model::DriverKind::kInternalElectronics, vb::model::DriverKind::kLowSideFlyback};
  vb::model::DriverParams driver;
  driver.kind = kDrivers[(opt >> 1) & 3];
  static const double kFullScale_A[] = {0.03, 0.3, 3.0, 30.0};
  const double scale_A = kFullScale_A[(opt >> 4) & 3] / 255.0 * (inverted ? -1.0 : 1.0);
  const double supply_V = data[1] / 8.0;
  const double dt = 1e-6 * (1 + data[2]);
  const std::size_t period = 2 + data[3] % 120;
  const double duty = data[4] / 255.0;
  const std::size_t baseline = data[5];
  const bool dropout_tail = data[3] >= 120;
  const std::size_t per_sample = 1 + (with_v ? 1 : 0) + (gate_from_data ? 1 : 0);
  const std::size_t n = std::min<std::size_t>((size - 6) / per_sample, 6000);
  if (n < 2) return 0;

  vb::gap::RunData run;
  run.id = "hold";
  run.supply_V = supply_V;
  run.supply_pressure_Pa = 4e5;
  run.sample_period_s = dt;
  const std::uint8_t* p = data + 6;
  for (std::size_t k = 0; k < n; ++k) {
    run.t_s.push_back(static_cast<double>(k) * dt);
    run.i_A.push_back(*p++ * scale_A);
    if (with_v) run.v_coil_V.push_back((*p++ - 128) / 100.0 * (supply_V > 0.0 ? supply_V : 1.0));
    int gate = 0;
    if (gate_from_data) {
      gate = *p++ & 1;
    } else if (k >= baseline && !(dropout_tail && 3 * k >= 2 * n)) {
      // The pull-in: the first two periods on, then the duty's share of each period.
      const std::size_t j = k - baseline;
      gate = j < 2 * period || static_cast<double>(j % period) < duty * static_cast<double>(period) ? 1 : 0;
    }
    run.gate.push_back(static_cast<std::int8_t>(gate));
  }
  if (nan_sample) run.i_A[n / 2] = NAN;

  (void)vb::gap::IsHoldRun(run);
  auto m = vb::gap::MeasureHold(run, driver);
  if (!m.ok()) {
    if (m.status().message().empty()) std::abort();
  } else {
    Check(std::isfinite(m->R_ohm) && m->R_ohm > 0.0, "R");
    Check(std::isfinite(m->R_sigma_ohm), "R's sigma");
    Check(std::isfinite(m->L_H), "L");
    Check(std::isfinite(m->L_sigma_H), "L's sigma");
    Check(std::isfinite(m->hold_current_A), "current");
    Check(std::isfinite(m->offset_A), "offset");
    Check(std::isfinite(m->duty) && std::isfinite(m->frequency_Hz), "gate");
  }
  auto d = vb::gap::MeasureDropOut(run);
  if (!d.ok()) {
    if (d.status().message().empty()) std::abort();
  } else {
    Check(std::isfinite(d->i_A) && std::isfinite(d->sigma_A) && d->sigma_A > 0.0, "drop-out current");
    Check(std::isfinite(d->t_s) && std::isfinite(d->rise_A), "drop-out's time");
  }
  // The night's values from two copies of the run (the inverse-variance mean and the lowest supply's L).
  std::vector<vb::gap::RunData> holds{run, run};
  holds[1].supply_V = supply_V * 1.5;
  std::vector<std::string> notes;
  for (const auto& v : vb::gap::HoldValues(holds, driver, &notes)) {
    Check(std::isfinite(v.value), v.name.c_str());
    Check(std::isfinite(v.sigma) && v.sigma > 0.0, "value's sigma");
  }
  for (const auto& note : notes)
    if (note.empty()) std::abort();
  return 0;
}
