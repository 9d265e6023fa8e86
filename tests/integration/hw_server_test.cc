// Hardware benches in the server: config kinds "hid" and "u3", capability checks at submission (refused with
// the reason, exit 2), ListBenches with the attached USB devices, and a run on a hardware bench whose device is
// not there ending failed with a clear reason (on a machine without a USB bus: that it has none).
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <fstream>

#include "../common/run_command.h"
#include "server_process.h"

namespace vb {
namespace {

using Result = testing::CommandResult;

Result Benchctl(const std::string& args) { return testing::RunCommand(std::string(VB_BENCHCTL) + " " + args); }

std::string WriteSpec(const std::string& dir, const std::string& name, const std::string& json) {
  const std::string path = dir + "/" + name + ".json";
  std::ofstream(path) << json;
  return path;
}

TEST(HwServer, CapabilitiesDecideAtSubmissionAndAMissingDeviceFailsTheRunCleanly) {
  const std::string dir = ::testing::TempDir() + "/vb-hw-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  testing::ServerProcess server(
      dir, "",
      R"([{"name": "emu-a", "kind": "emulated", "model": {"preset": "taghizadeh2009"}},
          {"name": "rig-hid", "kind": "hid", "serial": "NO-SUCH-BENCH", "max_supply_V": 24, "max_current_A": 2},
          {"name": "rig-u3", "kind": "u3", "serial": "320000001", "max_supply_V": 24,
           "safety": {"max_on_time_s": 0.5, "watchdog_s": 0.5}}])");
  const std::string addr = server.Start();
  ASSERT_FALSE(addr.empty()) << server.Log();
  const std::string op = "--server " + addr + " --token " + testing::kOperatorToken;

  Result benches = Benchctl("benches " + op);
  ASSERT_EQ(benches.exit_code, 0) << benches.out;
  EXPECT_NE(benches.out.find("rig-hid"), std::string::npos) << benches.out;
  EXPECT_NE(benches.out.find("rig-u3"), std::string::npos) << benches.out;
  EXPECT_NE(benches.out.find("attached USB devices:"), std::string::npos) << benches.out;
  Result json = Benchctl("benches --json " + op);
  ASSERT_EQ(json.exit_code, 0) << json.out;
  EXPECT_NE(json.out.find("\"device\": \"hid 2e8a:10c0 serial NO-SUCH-BENCH\""), std::string::npos) << json.out;

  const std::string base = R"("conditions":{"supply_V":SUPPLY},"duration_s":0.05,"recording":{"rate_Hz":1000})";
  auto spec = [&](const std::string& kind, const std::string& controller, const std::string& supply) {
    std::string b = base;
    b.replace(b.find("SUPPLY"), 6, supply);
    return R"({"name":"hw-)" + kind + R"(","bench":{"kind":")" + kind + R"("},"reference":{"constant":{"value":0.5}},"controller":)" +
           controller + "," + b + "}";
  };
  const std::string open_loop = R"({"open_loop_pwm":{"segments":[{"start_s":0,"frequency_Hz":375,"duty":0.5}]}})";

  Result volts = Benchctl("run " + WriteSpec(dir, "volts", spec("hid", open_loop, "48")) + " " + op);
  EXPECT_EQ(volts.exit_code, 2) << volts.out;
  EXPECT_NE(volts.out.find("rig-hid: conditions.supply_V: 48 V exceeds the bench's 24 V"), std::string::npos)
      << volts.out;
  Result fast = Benchctl("run " + WriteSpec(dir, "fast", spec("u3", R"({"pi_current":{}})", "24")) + " " + op);
  EXPECT_EQ(fast.exit_code, 2) << fast.out;
  EXPECT_NE(fast.out.find("faster than the bench's host loop of 1000 Hz"), std::string::npos) << fast.out;
  // The same fast loop is fine on the emulated bench: refusal is about the bench, not the spec.
  Result emu = Benchctl("run " + WriteSpec(dir, "emu", spec("emulated", R"({"pi_current":{}})", "24")) + " --wait " + op);
  EXPECT_EQ(emu.exit_code, 0) << emu.out;

  // Accepted, then the device is not there: the run fails with the reason (exit 1), nothing hangs.
  Result missing = Benchctl("run " + WriteSpec(dir, "missing", spec("hid", open_loop, "24")) + " --wait " + op);
  EXPECT_EQ(missing.exit_code, 1) << missing.out;
  Result shown = Benchctl("queue --status failed --json " + op);
  EXPECT_NE(shown.out.find("bench rig-hid: hid 2e8a:10c0 serial NO-SUCH-BENCH"), std::string::npos) << shown.out;
  // The bench is faulted now, with that reason; the others are not.
  Result faulted = Benchctl("benches --json " + op);
  ASSERT_EQ(faulted.exit_code, 0) << faulted.out;
  const auto j = nlohmann::json::parse(faulted.out.substr(faulted.out.find('{')));
  for (const auto& b : j["benches"]) {
    const std::string fault = b.value("fault", "");
    if (b["name"] == "rig-hid") {
      EXPECT_NE(fault.find("bench rig-hid: hid 2e8a:10c0 serial NO-SUCH-BENCH"), std::string::npos) << faulted.out;
    } else {
      EXPECT_EQ(fault, "") << b.dump();
    }
  }
}

TEST(HwServer, BadHardwareConfigNamesTheField) {
  const std::string dir = ::testing::TempDir() + "/vb-hw-bad-" + std::to_string(::getpid());
  std::filesystem::remove_all(dir);
  testing::ServerProcess server(dir, "", R"([{"name": "rig-u3", "kind": "u3", "serial": "abc"}])");
  EXPECT_TRUE(server.Start().empty());
  EXPECT_NE(server.Log().find("benches[0].serial: a U3 serial number is decimal, got 'abc'"), std::string::npos)
      << server.Log();
}

}  // namespace
}  // namespace vb
