#include "runs/bench_setup.h"

#include "experiment/runner.h"
#include "hw/hid/hid_bench.h"
#include "hw/hid/hidapi_transport.h"
#include "hw/u3/libusb_transport.h"
#include "hw/u3/u3_bench.h"

namespace vb::runs {

BenchSetup LocalEmulatorSetup() {
  BenchSetup b;
  b.name = "local-emulator";
  b.kind = BenchKind::kEmulated;
  b.bench_class = "local";
  b.interlocks = false;
  b.plant_from_spec = true;
  return b;
}


StatusOr<std::unique_ptr<hw::Bench>> OpenBench(const BenchSetup& setup, const experiment::Experiment& e) {
  const auto& c = setup.config;
  if (setup.kind == BenchKind::kHid) {
    hw::HidDeviceId id;
    if (c.vendor_id() != 0) id.vendor_id = static_cast<std::uint16_t>(c.vendor_id());
    if (c.product_id() != 0) id.product_id = static_cast<std::uint16_t>(c.product_id());
    id.serial = c.serial();
    auto t = hw::OpenHidapiTransport(id);
    if (!t.ok()) return t.status();
    hw::HidBenchOptions opt;
    opt.name = setup.name;
    opt.max_current_A = setup.caps.max_current_A;
    opt.max_supply_V = setup.caps.max_supply_V;
    auto b = hw::HidBench::Open(std::move(t.value()), opt);
    if (!b.ok()) return b.status();
    return std::unique_ptr<hw::Bench>(std::move(b.value()));
  }
  if (setup.kind == BenchKind::kU3) {
    auto t = hw::OpenLibusbU3Transport(0);
    if (!t.ok()) return t.status();
    hw::U3BenchOptions opt;
    opt.name = setup.name;
    if (!c.serial().empty()) opt.serial = static_cast<std::uint32_t>(std::stoul(c.serial()));
    if (c.amps_per_volt() > 0.0) opt.amps_per_volt = c.amps_per_volt();
    opt.max_supply_V = setup.caps.max_supply_V;
    opt.max_current_A = setup.caps.max_current_A;
    opt.max_sample_rate_Hz = setup.caps.max_sample_rate_Hz;
    opt.max_control_rate_Hz = setup.caps.max_control_rate_Hz;
    auto b = hw::U3Bench::Open(std::move(t.value()), opt);
    if (!b.ok()) return b.status();
    return std::unique_ptr<hw::Bench>(std::move(b.value()));
  }
  if (setup.plant_from_spec) return std::unique_ptr<hw::Bench>(std::make_unique<hw::EmulatedBench>(experiment::EmulatedBenchFor(e)));
  hw::EmulatedBenchOptions opts = setup.emulated;
  opts.plant = e.plant;
  opts.disturbance = e.disturbance;
  return std::unique_ptr<hw::Bench>(std::make_unique<hw::EmulatedBench>(opts));
}

}  // namespace vb::runs
