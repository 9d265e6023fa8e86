#include "model/flow.h"

#include <algorithm>
#include <cmath>

namespace vb::model {

double MassFlow_kg_per_s(const PlantParams& p, double xbar_m, double supply_pressure_gauge_Pa) {
  const double p_sup = supply_pressure_gauge_Pa + p.P_atm_Pa;
  if (xbar_m <= 0.0 || p_sup <= p.P_out_Pa || p_sup <= 0.0) return 0.0;
  constexpr double kGamma = 1.4;
  constexpr double kRgas = 287.05;
  const double area_term = p.C_d * p.C_A_m * xbar_m * p_sup / std::sqrt(p.T_supply_K);
  const double ratio = p.P_out_Pa / p_sup;
  if (ratio <= 0.528) return 0.0405 * area_term;  // choked
  const double f = 2.0 * kGamma / (kRgas * (kGamma - 1.0)) *
                   (std::pow(ratio, 2.0 / kGamma) - std::pow(ratio, (kGamma + 1.0) / kGamma));
  return area_term * std::sqrt(std::max(f, 0.0));
}

void MovingAverage::Reset(double* buffer, int window) {
  buf_ = buffer;
  window_ = window > 0 ? window : 1;
  n_ = 0;
  head_ = 0;
  sum_ = 0.0;
}

double MovingAverage::Push(double value) {
  if (buf_ == nullptr) return value;
  if (n_ < window_) {
    buf_[n_++] = value;
    sum_ += value;
  } else {
    sum_ += value - buf_[head_];
    buf_[head_] = value;
    if (++head_ == window_) head_ = 0;
  }
  return sum_ / n_;
}

}  // namespace vb::model
