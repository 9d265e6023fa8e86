#include "experiment/controllers.h"

#include "control/open_loop_pwm.h"

namespace vb::experiment {

using valvebench::v1::ControllerSpec;

StatusOr<BuiltController> BuildController(const valvebench::v1::ExperimentSpec& spec,
                                          const model::PlantParams& plant, const model::DriverParams& driver,
                                          double supply_V) {
  (void)plant;
  (void)driver;
  (void)supply_V;
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
    case ControllerSpec::LAW_NOT_SET:
      return Status::InvalidArgument("controller: no law given (e.g. {\"open_loop_pwm\": {...}})");
    default:
      return Status::InvalidArgument("controller: law '" +
                                     std::string(cs.GetDescriptor()->FindFieldByNumber(cs.law_case())->name()) +
                                     "' is not available yet");
  }
}

}  // namespace vb::experiment
