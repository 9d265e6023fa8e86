// A target that crashes on one token (fuzz/replay_selftest.dict) that no seed holds: the replay's self-test
// (tests/CMakeLists.txt, Fuzz.ReplayFindsACrashItsSeedsDoNotHold, expected to fail). It shows that the replay's
// mutations reach an input its seeds do not contain and that a crash there fails the test.
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view in(reinterpret_cast<const char*>(data), size);
  if (in.find("valvebench-replay-selftest") != std::string_view::npos) std::abort();
  return 0;
}
