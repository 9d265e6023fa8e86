#include "experiment/reference.h"

#include <algorithm>
#include <cmath>

namespace vb::experiment {

using valvebench::v1::ReferenceSpec;

StatusOr<ReferenceProfile> ReferenceProfile::FromSpec(const ReferenceSpec& ref,
                                                      const valvebench::v1::ValveCommand& command) {
  ReferenceProfile p;
  if (command.frequency_hz() < 0.0 || !std::isfinite(command.frequency_hz()))
    return Status::InvalidArgument("valve_command.frequency_Hz: must be >= 0");
  if (command.frequency_hz() > 0.0) {
    if (!(command.duty() >= 0.0 && command.duty() <= 1.0))
      return Status::InvalidArgument("valve_command.duty: must be in [0, 1]");
    p.cmd_period_s_ = 1.0 / command.frequency_hz();
    p.cmd_duty_ = command.duty();
  }
  switch (ref.shape_case()) {
    case ReferenceSpec::SHAPE_NOT_SET: p.kind_ = Kind::kNone; break;
    case ReferenceSpec::kConstant:
      p.kind_ = Kind::kConstant;
      p.a_ = ref.constant().value();
      break;
    case ReferenceSpec::kSteps: {
      p.kind_ = Kind::kSteps;
      double last = -1.0;
      for (int k = 0; k < ref.steps().steps_size(); ++k) {
        const auto& s = ref.steps().steps(k);
        if (!(s.start_s() > last) || s.start_s() < 0.0)
          return Status::InvalidArgument("reference.steps.steps[" + std::to_string(k) +
                                         "].start_s: steps must start at >= 0 in increasing order");
        last = s.start_s();
        p.step_t_s_.push_back(s.start_s());
        p.step_value_.push_back(s.value());
      }
      if (p.step_t_s_.empty()) return Status::InvalidArgument("reference.steps.steps: at least one step is needed");
      break;
    }
    case ReferenceSpec::kRamp:
      p.kind_ = Kind::kRamp;
      p.a_ = ref.ramp().start_value();
      p.b_ = ref.ramp().end_value();
      p.c_ = ref.ramp().start_s();
      p.d_ = ref.ramp().end_s();
      if (!(p.d_ > p.c_)) return Status::InvalidArgument("reference.ramp.end_s: must be greater than start_s");
      break;
    case ReferenceSpec::kSine:
      p.kind_ = Kind::kSine;
      p.a_ = ref.sine().offset();
      p.b_ = ref.sine().amplitude();
      p.c_ = ref.sine().frequency_hz();
      p.d_ = ref.sine().phase_rad();
      if (!(p.c_ > 0.0)) return Status::InvalidArgument("reference.sine.frequency_Hz: must be > 0");
      break;
    case ReferenceSpec::kOnOffProfile:
      p.kind_ = Kind::kOnOff;
      p.a_ = ref.on_off_profile().switching_value();
      p.b_ = ref.on_off_profile().switching_time_s();
      p.c_ = ref.on_off_profile().holding_value();
      if (p.b_ < 0.0) return Status::InvalidArgument("reference.on_off_profile.switching_time_s: must be >= 0");
      break;
  }
  return p;
}

bool ReferenceProfile::CommandOn(double t_s, double* t_since_on_s) const {
  if (cmd_period_s_ <= 0.0) {
    *t_since_on_s = t_s;
    return true;
  }
  const double n = std::floor(t_s / cmd_period_s_ + 1e-12);
  const double phase = std::max(0.0, t_s - n * cmd_period_s_);
  *t_since_on_s = phase;
  return phase < cmd_duty_ * cmd_period_s_ - 1e-12;
}

control::Reference ReferenceProfile::At(double t_s) const {
  control::Reference r;
  r.command_on = CommandOn(t_s, &r.t_since_on_s);
  switch (kind_) {
    case Kind::kNone: break;
    case Kind::kConstant: r.value = a_; break;
    case Kind::kSteps: {
      auto it = std::upper_bound(step_t_s_.begin(), step_t_s_.end(), t_s + 1e-12);
      r.value = it == step_t_s_.begin() ? 0.0 : step_value_[static_cast<size_t>(it - step_t_s_.begin()) - 1];
      break;
    }
    case Kind::kRamp:
      if (t_s <= c_) {
        r.value = a_;
      } else if (t_s >= d_) {
        r.value = b_;
      } else {
        r.rate = (b_ - a_) / (d_ - c_);
        r.value = a_ + r.rate * (t_s - c_);
      }
      break;
    case Kind::kSine: {
      const double w = 2.0 * M_PI * c_;
      r.value = a_ + b_ * std::sin(w * t_s + d_);
      r.rate = b_ * w * std::cos(w * t_s + d_);
      break;
    }
    case Kind::kOnOff: r.value = !r.command_on ? 0.0 : (r.t_since_on_s < b_ ? a_ : c_); break;
  }
  return r;
}

std::vector<double> ReferenceProfile::Breakpoints(double duration_s) const {
  std::vector<double> out;
  if (kind_ == Kind::kSteps)
    for (double t : step_t_s_) out.push_back(t);
  if (kind_ == Kind::kRamp) {
    out.push_back(c_);
    out.push_back(d_);
  }
  if (cmd_period_s_ > 0.0) {
    for (long n = 0;; ++n) {
      const double on = static_cast<double>(n) * cmd_period_s_;
      if (on >= duration_s) break;
      out.push_back(on);
      if (cmd_duty_ > 0.0 && cmd_duty_ < 1.0) out.push_back(on + cmd_duty_ * cmd_period_s_);
      if (kind_ == Kind::kOnOff && b_ > 0.0 && b_ < cmd_duty_ * cmd_period_s_) out.push_back(on + b_);
    }
  } else if (kind_ == Kind::kOnOff && b_ > 0.0) {
    out.push_back(b_);
  }
  std::erase_if(out, [&](double t) { return t < 0.0 || t >= duration_s; });
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace vb::experiment
