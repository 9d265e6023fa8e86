#include "server/health_check.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "common/bench_kind.h"

namespace vb::server {

namespace v1 = valvebench::v1;

Status ValidateHealthCheck(const v1::BenchConfig& b, const hw::Capabilities& caps, const std::string& field) {
  if (!b.has_health()) return Status::Ok();
  const auto& h = b.health();
  const std::string f = field + ".health";
  if (h.supply_v_size() == 0) return Status::InvalidArgument(f + ".supply_V: give at least one supply");
  for (int i = 0; i < h.supply_v_size(); ++i)
    if (!(h.supply_v(i) > 0.0) || h.supply_v(i) > caps.max_supply_V)
      return Status::InvalidArgument(fmt::format("{}.supply_V[{}]: {} V is outside (0, {}] (the bench's max_supply_V)",
                                                 f, i, h.supply_v(i), caps.max_supply_V));
  if (h.supply_pressure_pa_size() == 0)
    return Status::InvalidArgument(f + ".supply_pressure_Pa: give at least one pressure (0 for none)");
  for (int i = 0; i < h.supply_pressure_pa_size(); ++i)
    if (!(h.supply_pressure_pa(i) >= 0.0) || !std::isfinite(h.supply_pressure_pa(i)))
      return Status::InvalidArgument(fmt::format("{}.supply_pressure_Pa[{}]: must be a gauge pressure >= 0, got {}", f,
                                                 i, h.supply_pressure_pa(i)));
  if (h.duration_s() != 0.0 && !(h.duration_s() > 2 * kHealthPreTrigger_s && h.duration_s() <= 10.0))
    return Status::InvalidArgument(fmt::format("{}.duration_s: must be in (0.0002, 10] s, got {}", f, h.duration_s()));
  if (h.record_rate_hz() != 0.0 && !(h.record_rate_hz() >= 1e3 && h.record_rate_hz() <= caps.max_sample_rate_Hz))
    return Status::InvalidArgument(fmt::format("{}.record_rate_Hz: must be in [1000, {}] Hz (the bench's limit), got {}",
                                               f, caps.max_sample_rate_Hz, h.record_rate_hz()));
  const double duty = h.has_hold_duty() ? h.hold_duty() : kHealthDefaultHoldDuty;
  if (duty == 0.0) return Status::Ok();  // no hold run
  if (!(duty > 0.0 && duty < 1.0))
    return Status::InvalidArgument(fmt::format("{}.hold_duty: must be in (0, 1) (0: no hold run), got {}", f, duty));
  const double rate_Hz = h.record_rate_hz() > 0.0 ? h.record_rate_hz() : kHealthDefaultRate_Hz;
  const double f_Hz = h.hold_frequency_hz() > 0.0 ? h.hold_frequency_hz() : kHealthDefaultHoldFrequency_Hz;
  if (h.hold_frequency_hz() < 0.0 || !std::isfinite(h.hold_frequency_hz()) || f_Hz > rate_Hz / 10.0 ||
      (caps.max_carrier_Hz > 0.0 && (f_Hz < caps.min_carrier_Hz || f_Hz > caps.max_carrier_Hz)))
    return Status::InvalidArgument(fmt::format(
        "{}.hold_frequency_Hz: {} Hz must be within the bench's carrier range [{}, {}] Hz and leave 10 samples a "
        "period at {} Hz", f, f_Hz, caps.min_carrier_Hz, caps.max_carrier_Hz, rate_Hz));
  const double hold_s = h.hold_s() != 0.0 ? h.hold_s() : kHealthDefaultHold_s;
  if (!(hold_s * f_Hz >= 8.0) || hold_s > 10.0)
    return Status::InvalidArgument(fmt::format(
        "{}.hold_s: {} s holds {:.3g} periods at {} Hz; give at least 8 (the second half is measured, 3 whole "
        "periods at least) and at most 10 s", f, hold_s, hold_s * f_Hz, f_Hz));
  if (h.has_dropout_s() && !(h.dropout_s() == 0.0 || (h.dropout_s() >= 4.0 / f_Hz && h.dropout_s() <= 10.0)))
    return Status::InvalidArgument(fmt::format(
        "{}.dropout_s: {} s; give 0 (no drop-out) or at least 4 PWM periods ({:.3g} s at {} Hz: shorter is the "
        "PWM's own off-time) and at most 10 s",
        f, h.dropout_s(), 4.0 / f_Hz, f_Hz));
  return Status::Ok();
}

Status DriftFromConfig(const v1::BenchConfig& b, const std::string& field, runs::BenchSetup* setup) {
  const bool emulated = setup->kind == BenchKind::kEmulated;
  if (!emulated && (b.drift_size() > 0 || b.current_noise_a() != 0.0))
    return Status::InvalidArgument(field + ".drift/current_noise_A: only an emulated bench's valve is told how to "
                                           "change (a hardware valve drifts on its own)");
  if (!(b.current_noise_a() >= 0.0) || !std::isfinite(b.current_noise_a()))
    return Status::InvalidArgument(fmt::format("{}.current_noise_A: must be >= 0 A, got {}", field, b.current_noise_a()));
  setup->current_noise_A = b.current_noise_a();
  for (int i = 0; i < b.drift_size(); ++i) {
    const auto& d = b.drift(i);
    const std::string f = fmt::format("{}.drift[{}]", field, i);
    const bool effect = d.parameter().find('.') != std::string::npos;
    auto own = effect ? model::GetEffectParam(setup->emulated.plant.effects, d.parameter())
                      : model::GetParam(setup->emulated.plant, d.parameter());
    if (!own.ok())
      return Status::InvalidArgument(f + ".parameter: '" + d.parameter() +
                                     "' is not a model parameter (the names spec files use: R, N, k, delta, b, m, mu_r, "
                                     "...) nor an effect's (coulomb_friction.F_c, eddy_currents.R_p, ...): " +
                                     own.status().message());
    if (!std::isfinite(d.base()) || d.base() < 0.0)
      return Status::InvalidArgument(fmt::format("{}.base: must be >= 0 (0: the model's own value), got {}", f, d.base()));
    if (d.base() == 0.0 && *own == 0.0)
      return Status::InvalidArgument(f + ".base: " + d.parameter() +
                                     " is 0 in the bench's model, so a relative drift keeps it 0: give the value it "
                                     "starts from (base)");
    if (!std::isfinite(d.step()) || !std::isfinite(d.per_night()) || d.step() <= -1.0)
      return Status::InvalidArgument(f + ".step/per_night: must be finite, and step > -1 (a factor above 0)");
    if (d.step() == 0.0 && d.per_night() == 0.0)
      return Status::InvalidArgument(f + ": give a step or a per_night change (both are 0)");
    if (d.from_night() < 1) return Status::InvalidArgument(f + ".from_night: must be >= 1 (the lab's first night is 1)");
    setup->drift.push_back({d.parameter(), d.step(), d.per_night(), d.from_night(), d.base()});
  }
  return Status::Ok();
}

std::vector<experiment::ExperimentSpec> HealthCheckSpecs(const runs::BenchSetup& bench, const std::string& date,
                                                          int night_number) {
  std::vector<experiment::ExperimentSpec> specs;
  if (!bench.config.has_health()) return specs;
  const auto& h = bench.config.health();
  const double duration_s = h.duration_s() > 0.0 ? h.duration_s() : kHealthDefaultDuration_s;
  const double rate_Hz = h.record_rate_hz() > 0.0 ? h.record_rate_hz() : kHealthDefaultRate_Hz;
  const double duty = h.has_hold_duty() ? h.hold_duty() : kHealthDefaultHoldDuty;
  const double hold_Hz = h.hold_frequency_hz() > 0.0 ? h.hold_frequency_hz() : kHealthDefaultHoldFrequency_Hz;
  const double hold_s = h.hold_s() > 0.0 ? h.hold_s() : kHealthDefaultHold_s;
  const double dropout_s = h.has_dropout_s() ? h.dropout_s() : kHealthDefaultDropOut_s;
  const auto one = [&](double v, double p, bool hold) {
    experiment::ExperimentSpec s;
    s.set_name(fmt::format("health-{}{:g}V-{:g}Pa", hold ? "hold-" : "", v, p));
    s.set_description(hold ? fmt::format("nightly health check of {}: switch-on from rest at {:g} V and {:g} Pa, then "
                                         "a hold at duty {:g} and {:g} Hz for {:g} s{}",
                                         bench.name, v, p, duty, hold_Hz, hold_s,
                                         dropout_s > 0.0 ? fmt::format(", then {:g} s of drop-out", dropout_s) : "")
                           : fmt::format("nightly health check of {}: switch-on from rest at {:g} V and {:g} Pa",
                                         bench.name, v, p));
    for (const std::string& t : {std::string("health"), "health:" + bench.name, std::string("night"), "night:" + date,
                                 runs::NightNumberTag(night_number)})
      s.add_tags(t);
    s.mutable_bench()->set_kind(std::string(BenchKindName(bench.kind)));
    s.mutable_bench()->set_name(bench.name);
    if (bench.kind == BenchKind::kEmulated) {
      *s.mutable_bench()->mutable_model() = bench.model;
      *s.mutable_bench()->mutable_driver() = bench.config.driver();
    }
    s.mutable_conditions()->set_supply_v(v);
    s.mutable_conditions()->set_supply_pressure_pa(p);
    auto* pwm = s.mutable_controller()->mutable_open_loop_pwm();
    auto* off = pwm->add_segments();
    off->set_start_s(0.0), off->set_frequency_hz(0.0), off->set_duty(0.0);
    // The hold's switch-on starts after a longer baseline and lasts as the switch-ons do after their rise.
    const double rise_s = hold ? kHealthHoldBaseline_s : kHealthPreTrigger_s;
    const double hold_from_s = rise_s + duration_s - kHealthPreTrigger_s;
    auto* on = pwm->add_segments();
    on->set_start_s(rise_s), on->set_frequency_hz(0.0), on->set_duty(1.0);
    if (hold) {
      auto* held = pwm->add_segments();
      held->set_start_s(hold_from_s), held->set_frequency_hz(hold_Hz), held->set_duty(duty);
      if (dropout_s > 0.0) {
        auto* released = pwm->add_segments();
        released->set_start_s(hold_from_s + hold_s), released->set_frequency_hz(0.0), released->set_duty(0.0);
      }
    }
    s.set_duration_s(hold ? hold_from_s + hold_s + dropout_s : duration_s);
    s.mutable_recording()->set_rate_hz(rate_Hz);
    s.set_priority(kHealthPriority);
    specs.push_back(std::move(s));
  };
  for (double v : h.supply_v())
    for (double p : h.supply_pressure_pa()) one(v, p, false);
  // One hold: at the first (the bench's declared) supply and the highest pressure, where the pressure's force on
  // the held plunger is largest (R and L at the stop do not depend on it; a plunger that drops out does).
  if (duty > 0.0)
    one(h.supply_v(0), *std::max_element(h.supply_pressure_pa().begin(), h.supply_pressure_pa().end()), true);
  return specs;
}

}  // namespace vb::server
