// Open-loop PWM: a schedule of segments, each a (carrier frequency, duty) or a constant gate level, from its
// start time until the next segment starts. The PWM itself is realised by the bench's timer; this law only
// tells it when to change (a segment start restarts the carrier, so the new duty starts exactly then).
#pragma once

#include <string_view>
#include <vector>

#include "common/status.h"
#include "control/controller.h"

namespace vb::control {

struct PwmSegment {
  double start_s = 0.0;
  double frequency_Hz = 0.0;  // 0: constant gate level `duty` (0 or 1)
  double duty = 0.0;          // [0, 1]
};

class OpenLoopPwm final : public Controller {
 public:
  // segments sorted by start_s, the first at 0 (see Validate).
  // name: the law as specs and tables know it ("dither_pwm" when seed 003's planner chose the one segment).
  explicit OpenLoopPwm(std::vector<PwmSegment> segments, std::string_view name = "open_loop_pwm")
      : segments_(std::move(segments)), name_(name) {}
  static Status Validate(const std::vector<PwmSegment>& segments);

  std::string_view name() const override { return name_; }
  // The law only acts at segment starts; the runner also ticks at every breakpoint (segment starts).
  double period_s() const override { return 1e9; }
  ControllerState InitialState() const override {
    ControllerState s;
    s.mode = -1;  // index of the segment in force; -1 = none yet
    return s;
  }
  SwitchCommand Step(const Measurement& m, const Reference& r, ControllerState* state) const override;
  const std::vector<PwmSegment>& segments() const { return segments_; }

 private:
  std::vector<PwmSegment> segments_;
  std::string_view name_;  // a string literal
};

}  // namespace vb::control
