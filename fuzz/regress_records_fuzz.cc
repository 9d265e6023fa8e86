// A regression result and a baseline as a client sends them to SaveRegression (result_json) or in a baseline
// file (benchctl regress --baseline FILE): bytes -> JSON -> regress::ResultFromJson / BaselineFromJson, the way
// service/records_service.cc and benchctl parse them. Nothing may crash, hang or allocate without bound; a bad
// document must come back as a Status (or the JSON exception the service turns into one).
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "regress/compare.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  const vb::regress::Json j = vb::regress::Json::parse(text, nullptr, /*allow_exceptions=*/false);
  if (j.is_discarded()) return 0;
  try {
    auto r = vb::regress::ResultFromJson(j);
    if (r.ok()) {
      (void)r->verdict();
      (void)vb::regress::ResultToJson(*r).dump();
    }
  } catch (const vb::regress::Json::exception&) {
    // the service answers these as InvalidArgument "not a regression result"
  }
  try {
    auto b = vb::regress::BaselineFromJson(j);
    if (b.ok()) (void)vb::regress::BaselineToJson(*b).dump();
  } catch (const vb::regress::Json::exception&) {
  }
  return 0;
}
