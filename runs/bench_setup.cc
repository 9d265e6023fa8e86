#include "runs/bench_setup.h"

#include <atomic>
#include <random>
#include <string>

#include "experiment/runner.h"
#include "hw/hid/hid_bench.h"
#include "hw/hid/hidapi_transport.h"
#include "hw/u3/libusb_transport.h"
#include "hw/u3/u3_bench.h"

namespace vb::runs {

namespace {
constexpr char kNightNumberPrefix[] = "night-number:";
}  // namespace

double DriftFactor(const ValveDrift& d, int night) {
  if (night < d.from_night || night < 1) return 1.0;
  return 1.0 + d.step + d.per_night * static_cast<double>(night - d.from_night);
}

Status ApplyDrift(const std::vector<ValveDrift>& drift, int night, model::PlantParams* plant) {
  for (const auto& d : drift) {
    if (night < d.from_night || night < 1) continue;  // the model's own value until the drift starts
    // A plant parameter ("R") or an effect's ("coulomb_friction.F_c": the plant's effects).
    const bool effect = d.parameter.find('.') != std::string::npos;
    auto v = effect ? model::GetEffectParam(plant->effects, d.parameter) : model::GetParam(*plant, d.parameter);
    if (!v.ok()) return v.status().WithContext("drift");
    const double value = (d.base != 0.0 ? d.base : *v) * DriftFactor(d, night);
    auto st = effect ? model::SetEffectParam(&plant->effects, d.parameter, value) : model::SetParam(plant, d.parameter, value);
    if (!st.ok()) return st.WithContext("drift on night " + std::to_string(night));
  }
  return Status::Ok();
}

int NightNumberOf(const valvebench::v1::ExperimentSpec& spec) {
  const std::string prefix = kNightNumberPrefix;
  for (const auto& t : spec.tags())
    if (t.rfind(prefix, 0) == 0) {
      try {
        return std::max(0, std::stoi(t.substr(prefix.size())));
      } catch (const std::exception&) {
        return 0;
      }
    }
  return 0;
}

std::string NightNumberTag(int night) { return kNightNumberPrefix + std::to_string(night); }

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
  if (!setup.drift.empty()) {
    int night = NightNumberOf(e.spec);
    if (night > 0) {
      int seen = setup.night_seen->load();
      while (night > seen && !setup.night_seen->compare_exchange_weak(seen, night)) {
      }
    } else {
      night = setup.night_seen->load();
    }
    if (auto st = ApplyDrift(setup.drift, night, &opts.plant); !st.ok()) return st.WithContext("bench " + setup.name);
  }
  if (setup.current_noise_A > 0.0) {
    opts.current_noise_A = setup.current_noise_A;
    opts.noise_seed = std::random_device{}();
  }
  return std::unique_ptr<hw::Bench>(std::make_unique<hw::EmulatedBench>(opts));
}

}  // namespace vb::runs
