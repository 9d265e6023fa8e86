// The experiment spec as a user (or a client of the server) sends it: protobuf JSON -> parse -> expand
// variants, sweeps and repeats -> validate and build each run. Nothing may crash, hang or allocate without
// bound, whatever the bytes; a bad spec must come back as a Status.
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "experiment/spec.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view json(reinterpret_cast<const char*>(data), size);
  auto spec = vb::experiment::ParseSpecJson(json);
  if (!spec.ok()) return 0;
  (void)vb::experiment::SpecToJson(*spec);
  // A small run limit: the expansion itself is what is under test, not 100k copies of a spec.
  auto runs = vb::experiment::ExpandSweep(*spec, 16);
  if (!runs.ok()) {
    (void)vb::experiment::BuildExperiment(*spec);  // validation of an unexpanded spec must refuse, not crash
    return 0;
  }
  for (const auto& run : *runs) (void)vb::experiment::BuildExperiment(run);
  return 0;
}
