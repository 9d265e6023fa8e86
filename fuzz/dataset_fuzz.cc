// The dataset importer (gap::LoadDataset) on whatever a lab hands us: valve-runs/1 and valve-runs/2
// manifests with their CSV files and model files. Input: parts separated by lines "%%" (fuzz_files.h),
// written as manifest.json, a.csv, b.csv, c.csv, model.json into a scratch directory "ds", and read the same
// from memory (gap::LoadDatasetFromFiles, the web's upload): neither may crash, and where both load, they load
// the same runs (a difference aborts).
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <map>
#include <string>

#include "fuzz/fuzz_files.h"
#include "gap/dataset.h"
#include "model/params.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const char* const kNames[] = {"manifest.json", "a.csv", "b.csv", "c.csv", "model.json"};
  static const std::vector<std::string> kModels = vb::model::PresetNames();
  const auto dir = vb::fuzz::ScratchDir() / "ds";
  vb::fuzz::ResetDir(dir);
  const auto parts = vb::fuzz::SplitParts(data, size);
  std::map<std::string, std::string> files;
  for (std::size_t k = 0; k < parts.size() && k < std::size(kNames); ++k) {
    vb::fuzz::WriteFile(dir / kNames[k], parts[k]);
    files[kNames[k]] = std::string(parts[k]);
  }
  auto ds = vb::gap::LoadDataset(dir.string(), kModels);
  if (ds.ok())
    for (const auto& run : ds->runs) (void)vb::gap::DeclaredStandardErrors(*ds, run);
  auto mem = vb::gap::LoadDatasetFromFiles("ds", files, kModels);
  if (ds.ok() && mem.ok()) {
    if (mem->runs.size() != ds->runs.size()) std::abort();
    for (std::size_t k = 0; k < ds->runs.size(); ++k)
      if (mem->runs[k].id != ds->runs[k].id || mem->runs[k].i_A.size() != ds->runs[k].i_A.size()) std::abort();
  }
  return 0;
}
