// The readings CSV converter (gap/readings_csv.h, `benchctl convert`) on any file: the input is the CSV; the
// datasets it writes must load again (gap::LoadDataset), or the converter wrote something its own reader
// refuses.
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>

#include "fuzz/fuzz_files.h"
#include "gap/dataset.h"
#include "gap/readings_csv.h"
#include "model/params.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::vector<std::string> kModels = vb::model::PresetNames();
  const auto scratch = vb::fuzz::ScratchDir();
  const auto out = scratch / "out";
  vb::fuzz::ResetDir(out);
  const auto csv = scratch / "readings.csv";
  vb::fuzz::WriteFile(csv, std::string_view(reinterpret_cast<const char*>(data), size));
  auto sessions = vb::gap::ConvertReadingsCsv(csv.string(), out.string());
  if (!sessions.ok()) return 0;
  for (const auto& s : *sessions) {
    auto ds = vb::gap::LoadDataset(s.directory, kModels);
    if (!ds.ok()) {
      std::fprintf(stderr, "converted dataset does not load: %s\n", ds.status().message().c_str());
      std::abort();
    }
  }
  return 0;
}
