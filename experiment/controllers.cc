#include "experiment/controllers.h"

#include <string_view>
#include <utility>

#include "control/cascade_pi_position.h"
#include "control/dither_planner.h"
#include "control/peak_and_hold.h"
#include "control/sliding_mode_position.h"
#include "control/fuzzy_current.h"
#include "control/hysteresis_current.h"
#include "control/pi_current.h"
#include "control/predictive_current.h"
#include "control/open_loop_pwm.h"

namespace vb::experiment {

using valvebench::v1::ControllerSpec;

namespace {

// The nominal plant a position law is designed on: data from the bench's model (never the model itself).
StatusOr<control::LungeSolenoidModel> LungeNominal(const model::PlantParams& plant, const char* law) {
  if (plant.law != model::InductanceLaw::kLimitedTravel)
    return Status::InvalidArgument(std::string("controller.") + law +
                                   ": position laws are designed for a limited-travel solenoid (preset lunge2013), "
                                   "not " + plant.preset);
  control::LungeSolenoidModel m;
  m.mass_kg = plant.m_kg;
  m.spring_N_per_m = plant.k_N_per_m;
  m.damping_N_s_per_m = plant.b_N_s_per_m;
  m.gravity_mps2 = plant.g_r_m_per_s2;
  m.inductance_scale_H = plant.L_prime_H();
  m.overlap_length_m = plant.a_m;
  m.coil_resistance_ohm = plant.R_ohm;
  return m;
}

using FieldNames = std::initializer_list<std::string_view>;
using FieldMap = std::initializer_list<std::pair<std::string_view, std::string_view>>;

// A law validates its own parameters ("pi.carrier_Hz: must be > 0"); the user wrote the spec. Puts the message
// at the spec's field path ("controller.pi_current.carrier_Hz: must be > 0"). The laws' parameter names are the
// spec's (`fields`); only where the spec's name carries no unit does the C++ name differ (`renamed`: the
// position laws' gains and the predictive weights, whose spec names predate the unit rule and stay for
// existing spec files). A message about anything else stays at the law.
Status InSpec(const Status& st, std::string_view law, std::string_view law_prefix, FieldNames fields,
              FieldMap renamed = {}) {
  if (st.ok()) return st;
  std::string msg = st.message();
  if (!law_prefix.empty() && msg.rfind(law_prefix, 0) == 0) msg = msg.substr(law_prefix.size());
  const size_t colon = msg.find(':');
  const std::string param = msg.substr(0, colon);
  const std::string rest = colon == std::string::npos ? "" : msg.substr(colon);
  const std::string at = "controller." + std::string(law) + ".";
  for (const auto& name : fields)
    if (param == name) return Status::InvalidArgument(at + param + rest);
  for (const auto& [cpp, spec] : renamed)
    if (param == cpp) return Status::InvalidArgument(at + std::string(spec) + rest);
  return Status::InvalidArgument("controller." + std::string(law) + ": " + msg);
}

}  // namespace

StatusOr<BuiltController> BuildController(const valvebench::v1::ExperimentSpec& spec,
                                          const model::PlantParams& plant, const model::DriverParams& driver,
                                          double supply_V) {
  BuiltController out;
  const ControllerSpec& cs = spec.controller();
  switch (cs.law_case()) {
    case ControllerSpec::kOpenLoopPwm: {
      std::vector<control::PwmSegment> segs;
      for (const auto& s : cs.open_loop_pwm().segments())
        segs.push_back(control::PwmSegment{s.start_s(), s.frequency_hz(), s.duty()});
      auto st = control::OpenLoopPwm::Validate(segs);
      if (!st.ok()) return st.InField("controller.open_loop_pwm");
      for (const auto& s : segs) {
        out.breakpoints_s.push_back(s.start_s);
        if (out.pwm_period_s == 0.0 && s.frequency_Hz > 0.0) out.pwm_period_s = 1.0 / s.frequency_Hz;
      }
      out.controller = std::make_unique<control::OpenLoopPwm>(std::move(segs));
      out.controlled = ControlledVariable::kNone;
      return out;
    }
    case ControllerSpec::kDitherPwm: {
      // Seed 003: plan (f, D) once, before the run, then hold it with the bench's PWM timer.
      const auto& d = cs.dither_pwm();
      control::RlCoil coil;
      coil.supply_V = supply_V;
      coil.R_ohm = d.coil_r_ohm() > 0.0 ? d.coil_r_ohm() : plant.R_ohm;
      if (d.coil_l_h() > 0.0) {
        coil.L_H = d.coil_l_h();
      } else if (plant.law == model::InductanceLaw::kConstant) {
        coil.L_H = plant.L_H;
      } else {
        return Status::InvalidArgument(
            "controller.dither_pwm.coil_L_H: required for a coil whose inductance depends on the spool position");
      }
      control::DitherPlannerOptions opt;
      if (d.min_frequency_hz() > 0.0) opt.min_frequency_Hz = d.min_frequency_hz();
      if (d.max_frequency_hz() > 0.0) opt.max_frequency_Hz = d.max_frequency_hz();
      if (d.min_duty() > 0.0) opt.min_duty = d.min_duty();
      if (d.max_duty() > 0.0) opt.max_duty = d.max_duty();
      const control::DitherRequest req{d.average_current_a(), d.dither_amplitude_a()};
      StatusOr<control::DitherPlan> plan = Status::Internal("unset");
      if (d.method().empty() || d.method() == "exact") {
        plan = control::PlanDitherExact(coil, req, opt);
      } else if (d.method() == "approximate") {
        auto model = control::FitApproxDitherModel(coil, opt);
        if (!model.ok()) return model.status().InField("controller.dither_pwm");
        plan = control::PlanDitherApprox(*model, req);
      } else {
        return Status::InvalidArgument("controller.dither_pwm.method: '" + d.method() +
                                       "' is not one of exact, approximate");
      }
      if (!plan.ok())
        return InSpec(plan.status(), "dither_pwm", "dither.",
                      {"dither_amplitude_A", "average_current_A", "min_frequency_Hz", "max_frequency_Hz", "min_duty",
                       "max_duty"});
      std::vector<control::PwmSegment> segs = {{0.0, plan->frequency_Hz, plan->duty}};
      out.breakpoints_s.push_back(0.0);
      out.pwm_period_s = 1.0 / plan->frequency_Hz;
      out.controller = std::make_unique<control::OpenLoopPwm>(std::move(segs), "dither_pwm");
      out.controlled = ControlledVariable::kNone;
      return out;
    }
    case ControllerSpec::kHysteresisCurrent: {
      const auto& h = cs.hysteresis_current();
      control::HysteresisCurrentParams p;
      if (h.band_a() != 0.0) p.band_A = h.band_a();
      if (h.sample_period_s() != 0.0) p.sample_period_s = h.sample_period_s();
      VB_RETURN_IF_ERROR(InSpec(control::HysteresisCurrent::Validate(p), "hysteresis_current", "hysteresis.",
                                {"band_A", "sample_period_s"}));
      out.controller = std::make_unique<control::HysteresisCurrent>(p);
      out.controlled = ControlledVariable::kCurrent;
      return out;
    }
    case ControllerSpec::kPiCurrent: {
      const auto& c = cs.pi_current();
      control::PiCurrentParams p;
      if (c.kp_v_per_a() != 0.0) p.kp_V_per_A = c.kp_v_per_a();
      if (c.ki_v_per_a_s() != 0.0) p.ki_V_per_A_s = c.ki_v_per_a_s();
      if (c.carrier_hz() != 0.0) p.carrier_Hz = c.carrier_hz();
      if (c.has_feedforward_r_ohm()) p.feedforward_R_ohm = c.feedforward_r_ohm();
      VB_RETURN_IF_ERROR(InSpec(control::PiCurrent::Validate(p), "pi_current", "pi.",
                                {"kp_V_per_A", "ki_V_per_A_s", "carrier_Hz", "feedforward_R_ohm"}));
      out.controller = std::make_unique<control::PiCurrent>(p);
      out.controlled = ControlledVariable::kCurrent;
      return out;
    }
    case ControllerSpec::kPredictiveCurrent: {
      const auto& c = cs.predictive_current();
      control::PredictiveCurrentParams p;
      if (c.horizon_s() != 0.0) p.horizon_s = c.horizon_s();
      if (c.w_current() != 0.0) p.w_I_per_A2 = c.w_current();
      if (c.has_w_voltage()) p.w_v_per_V2 = c.w_voltage();
      if (c.r_ohm() != 0.0) p.R_ohm = c.r_ohm();
      if (c.l_h() != 0.0) p.L_H = c.l_h();
      if (c.carrier_hz() != 0.0) p.carrier_Hz = c.carrier_hz();
      VB_RETURN_IF_ERROR(InSpec(control::PredictiveCurrent::Validate(p), "predictive_current", "predictive.",
                                {"horizon_s", "R_ohm", "L_H", "carrier_Hz"},
                                {{"w_I_per_A2", "w_current"}, {"w_v_per_V2", "w_voltage"}}));
      out.controller = std::make_unique<control::PredictiveCurrent>(p);
      out.controlled = ControlledVariable::kCurrent;
      return out;
    }
    case ControllerSpec::kFuzzyCurrent: {
      const auto& c = cs.fuzzy_current();
      control::FuzzyCurrentParams p;
      if (c.error_scale_a() != 0.0) p.error_scale_A = c.error_scale_a();
      if (c.rate_scale_a_per_s() != 0.0) p.rate_scale_A_per_s = c.rate_scale_a_per_s();
      if (c.output_scale_v() != 0.0) p.output_scale_V = c.output_scale_v();
      if (c.carrier_hz() != 0.0) p.carrier_Hz = c.carrier_hz();
      if (c.has_feedforward_r_ohm()) p.feedforward_R_ohm = c.feedforward_r_ohm();
      VB_RETURN_IF_ERROR(InSpec(control::FuzzyCurrent::Validate(p), "fuzzy_current", "fuzzy.",
                                {"error_scale_A", "rate_scale_A_per_s", "output_scale_V", "carrier_Hz",
                                 "feedforward_R_ohm"}));
      out.controller = std::make_unique<control::FuzzyCurrent>(p);
      out.controlled = ControlledVariable::kCurrent;
      return out;
    }
    case ControllerSpec::kCascadePiPosition: {
      const auto& c = cs.cascade_pi_position();
      auto nominal = LungeNominal(plant, "cascade_pi_position");
      if (!nominal.ok()) return nominal.status();
      control::CascadePiPosition::Params p;
      p.model = *nominal;
      p.current_limit_A = supply_V / plant.R_ohm;
      p.h_bridge = driver.kind == model::DriverKind::kHBridge;
      p.bridge_diode_drop_V = driver.diode_drop_V;
      if (c.kp_position() != 0.0) p.position_kp_N_per_m = c.kp_position();
      if (c.ki_position() != 0.0) p.position_ki_N_per_m_s = c.ki_position();
      if (c.kp_current() != 0.0) p.current_kp_V_per_A = c.kp_current();
      if (c.ki_current() != 0.0) p.current_ki_V_per_A_s = c.ki_current();
      if (c.carrier_hz() != 0.0) p.carrier_Hz = c.carrier_hz();
      VB_RETURN_IF_ERROR(InSpec(control::CascadePiPosition::Validate(p), "cascade_pi_position", "",
                                {"carrier_Hz"},
                                {{"position_kp_N_per_m", "kp_position"}, {"position_ki_N_per_m_s", "ki_position"},
                                 {"current_kp_V_per_A", "kp_current"}, {"current_ki_V_per_A_s", "ki_current"}}));
      out.controller = std::make_unique<control::CascadePiPosition>(p);
      out.controlled = ControlledVariable::kPosition;
      return out;
    }
    case ControllerSpec::kSlidingModePosition: {
      const auto& c = cs.sliding_mode_position();
      auto nominal = LungeNominal(plant, "sliding_mode_position");
      if (!nominal.ok()) return nominal.status();
      control::SlidingModePosition::Params p;
      p.model = *nominal;
      p.current_limit_A = supply_V / plant.R_ohm;
      p.h_bridge = driver.kind == model::DriverKind::kHBridge;
      p.bridge_diode_drop_V = driver.diode_drop_V;
      if (c.c_position() != 0.0) p.surface_slope_per_s = c.c_position();
      if (c.k_position() != 0.0) p.reaching_gain_SI = c.k_position();
      if (c.alpha() != 0.0) p.reaching_exponent = c.alpha();
      if (c.k_current() != 0.0) p.current_reaching_rate_A_per_s = c.k_current();
      if (c.sigmoid_delta() != 0.0) p.current_boundary_layer_A = c.sigmoid_delta();
      if (c.carrier_hz() != 0.0) p.carrier_Hz = c.carrier_hz();
      VB_RETURN_IF_ERROR(InSpec(control::SlidingModePosition::Validate(p), "sliding_mode_position", "",
                                {"carrier_Hz"},
                                {{"surface_slope_per_s", "c_position"}, {"reaching_gain_SI", "k_position"},
                                 {"reaching_exponent", "alpha"}, {"current_reaching_rate_A_per_s", "k_current"},
                                 {"current_boundary_layer_A", "sigmoid_delta"}}));
      out.controller = std::make_unique<control::SlidingModePosition>(p);
      out.controlled = ControlledVariable::kPosition;
      return out;
    }
    case ControllerSpec::kPeakAndHold: {
      const auto& c = cs.peak_and_hold();
      control::PeakAndHold::Params p;
      if (c.switching_current_a() != 0.0) p.switching_current_A = c.switching_current_a();
      if (c.holding_current_a() != 0.0) p.holding_current_A = c.holding_current_a();
      if (c.band_a() != 0.0) p.band_A = c.band_a();
      if (c.peak_time_max_s() != 0.0) p.peak_time_max_s = c.peak_time_max_s();
      p.reverse_on_release = c.reverse_on_release();
      if (p.reverse_on_release && driver.kind != model::DriverKind::kHBridge)
        return Status::InvalidArgument(
            "controller.peak_and_hold.reverse_on_release: needs an H-bridge driver (bench.driver.kind = h_bridge)");
      VB_RETURN_IF_ERROR(InSpec(control::PeakAndHold::Validate(p), "peak_and_hold", "",
                                {"switching_current_A", "holding_current_A", "band_A", "peak_time_max_s"}));
      out.controller = std::make_unique<control::PeakAndHold>(p);
      out.controlled = spec.reference().shape_case() == valvebench::v1::ReferenceSpec::SHAPE_NOT_SET
                           ? ControlledVariable::kNone
                           : ControlledVariable::kCurrent;
      return out;
    }
    case ControllerSpec::LAW_NOT_SET:
      return Status::InvalidArgument("controller: no law given (e.g. {\"open_loop_pwm\": {...}})");
  }
  return Status::Internal("controller: unhandled law");
}

}  // namespace vb::experiment
