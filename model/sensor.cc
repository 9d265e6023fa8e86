#include "model/sensor.h"

#include <algorithm>
#include <cmath>

namespace vb::model {

CurrentSensor::CurrentSensor(const Effects& effects)
    : tau_s_(effects.sensor_tau_s),
      delay_s_(effects.sensor_delay_s),
      gain_(effects.sensor_gain),
      offset_A_(effects.sensor_offset_A),
      hist_(1, 0.0) {}

void CurrentSensor::SetSamplePeriod(double period_s) {
  sample_period_s_ = period_s > 0.0 ? period_s : 0.0;
  hist_.assign(sample_period_s_ > 0.0 && delay_s_ > 0.0
                   ? static_cast<std::size_t>(std::ceil(delay_s_ / sample_period_s_)) + 3
                   : 1,
               0.0);
  head_ = count_ = 0;
}

void CurrentSensor::Reset() {
  y_A_ = prev_i_A_ = 0.0;
  prev_t_s_ = -1.0;
  head_ = count_ = 0;
  last_A_ = 0.0;
}

double CurrentSensor::Sample(double t_s, double i_A) {
  if (!dynamic()) return Static(i_A);
  if (prev_t_s_ < 0.0 || tau_s_ <= 0.0) {
    y_A_ = i_A;
  } else {
    const double h = t_s - prev_t_s_;
    if (h > 0.0) {
      const double a = std::exp(-h / tau_s_);
      y_A_ = a * y_A_ + (1.0 - a) * prev_i_A_ + (i_A - prev_i_A_) * (1.0 - tau_s_ * (1.0 - a) / h);
    }
  }
  prev_i_A_ = i_A;
  prev_t_s_ = t_s;
  double out = y_A_;
  if (delay_s_ > 0.0 && sample_period_s_ > 0.0) {
    const std::size_t cap = hist_.size();
    hist_[head_] = y_A_;
    head_ = (head_ + 1) % cap;
    count_ = std::min(count_ + 1, cap);
    const double back = delay_s_ / sample_period_s_;
    const auto k0 = static_cast<std::size_t>(std::floor(back));
    const double frac = back - static_cast<double>(k0);
    auto at = [&](std::size_t ago) {  // the reading `ago` samples back; before the first sample: 0
      if (ago >= count_) return 0.0;
      return hist_[(head_ + cap - 1 - ago) % cap];
    };
    out = (1.0 - frac) * at(k0) + frac * at(k0 + 1);
  }
  last_A_ = out;
  return Static(out);
}

}  // namespace vb::model
