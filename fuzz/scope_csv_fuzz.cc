// The scope-capture converter (gap/scope_csv.h, `benchctl convert --channel`) on any file: the input is the
// capture; its first byte picks how it is read (the current from a named or numbered channel, a shunt or a
// probe, the gate from a channel or a trigger time), the rest is the CSV. What it writes must load again
// (gap::LoadDataset), or the converter wrote something its own reader refuses.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include "fuzz/fuzz_files.h"
#include "gap/dataset.h"
#include "gap/scope_csv.h"
#include "model/params.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::vector<std::string> kModels = vb::model::PresetNames();
  if (size == 0) return 0;
  const std::uint8_t mode = data[0];
  const auto scratch = vb::fuzz::ScratchDir();
  const auto out = scratch / "out";
  vb::fuzz::ResetDir(out);
  const auto csv = scratch / "capture.csv";
  vb::fuzz::WriteFile(csv, std::string_view(reinterpret_cast<const char*>(data + 1), size - 1));
  vb::gap::ScopeCsvOptions o;
  o.current_channel = (mode & 1) ? "CH2" : "2";
  if (mode & 2) {
    o.probe_A_per_V = 0.1;
  } else {
    o.shunt_ohm = 1.0;
  }
  if (mode & 4) {
    o.gate_channel = (mode & 8) ? "CH1" : "3";
  } else {
    o.trigger_s = (mode & 8) ? 0.0 : 1e-3;
  }
  if (mode & 16) o.time_column = "X";
  o.supply_V = 12.0;
  o.supply_pressure_Pa = 1e5;
  o.noise_A = (mode & 32) ? 1e-3 : NAN;
  auto run = vb::gap::ConvertScopeCsv(csv.string(), out.string(), o);
  if (!run.ok()) return 0;
  auto ds = vb::gap::LoadDataset(run->directory, kModels);
  if (!ds.ok()) {
    std::fprintf(stderr, "converted capture does not load: %s\n", ds.status().message().c_str());
    std::abort();
  }
  return 0;
}
