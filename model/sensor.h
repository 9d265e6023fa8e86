// The current sensor's measurement chain (docs/model.md, "Effects": sensor_lag, sensor_offset, sensor_gain).
//
// What the bench's current sensor reports for the coil's terminal current. It works on samples and is not part
// of the plant: controllers and recordings see its reading, the integration never does. Its state (the lag's
// output, the latency's history ring) is owned here and changes only through Sample(); reading it is const.
//   lag (first order, tau_s dy/dt = i - y), exact for a current linear between samples (first-order hold):
//     y_k = a y_(k-1) + (1 - a) i_(k-1) + (i_k - i_(k-1)) (1 - tau (1 - a) / h),   a = exp(-h / tau)
//   latency: the lagged reading delay_s ago, interpolated between the samples around it (0 before the run);
//   static chain: reading = gain * y + offset.
#pragma once

#include <cstddef>
#include <vector>

#include "model/effects.h"

namespace vb::model {

class CurrentSensor {
 public:
  explicit CurrentSensor(const Effects& effects);

  // Sizes the latency ring for a sample period and empties it. Allocates: call outside the control loop.
  void SetSamplePeriod(double period_s);
  // No sample seen yet (the lag starts at the first sample's current; the ring reads 0).
  void Reset();
  // The reading for the terminal current i_A sampled at t_s; advances the lag and the latency ring.
  // Allocation-free.
  double Sample(double t_s, double i_A);

  // A lag or a latency: the reading depends on earlier samples.
  bool dynamic() const { return tau_s_ > 0.0 || delay_s_ > 0.0; }
  // dynamic() and at least one sample seen: LastReading_A() is what the sensor shows between samples.
  bool has_reading() const { return dynamic() && prev_t_s_ >= 0.0; }
  double LastReading_A() const { return Static(last_A_); }
  // The static part of the chain alone (offset, gain): what a sensor without lag reports for i_A.
  double Static(double i_A) const { return gain_ * i_A + offset_A_; }

 private:
  double tau_s_, delay_s_, gain_, offset_A_;
  double sample_period_s_ = 0.0;
  double y_A_ = 0.0, prev_i_A_ = 0.0, prev_t_s_ = -1.0;  // the lag: its output and the previous sample
  std::vector<double> hist_;                             // lagged outputs at the last samples (latency), ring
  std::size_t head_ = 0, count_ = 0;
  double last_A_ = 0.0;                                  // the last reading before the static chain
};

}  // namespace vb::model
