// Orifice flow through the valve, seed 000 eq. (12), driven by the moving average of the spool position
// (section 5): the flow of a PWM-driven valve follows xbar(t), the mean of x over one PWM period.
#pragma once

#include "model/params.h"

namespace vb::model {

// Mass flow [kg/s] through the orifice of area C_A * xbar_m at supply pressure P_sup (gauge, converted to
// absolute with P_atm) into P_out (absolute). Choked when P_out/P_sup <= 0.528, subsonic otherwise.
// The gas is air: gamma = 1.4, R = 287.05 J/(kg K); 0.0405 is the choked-flow constant of eq. (12)
// (= sqrt(gamma/R (2/(gamma+1))^((gamma+1)/(gamma-1))) = 0.04042 for these values).
double MassFlow_kg_per_s(const PlantParams& p, double xbar_m, double supply_pressure_gauge_Pa);

// Streaming moving average over a fixed window of uniformly spaced samples (one PWM period), with a
// caller-provided buffer so that the real-time path never allocates.
class MovingAverage {
 public:
  MovingAverage() = default;
  // buffer must hold `window` doubles and outlive this object.
  void Reset(double* buffer, int window);
  double Push(double value);  // returns the mean of the last min(n, window) values
 private:
  double* buf_ = nullptr;
  int window_ = 0, n_ = 0, head_ = 0;
  double sum_ = 0.0;
};

}  // namespace vb::model
