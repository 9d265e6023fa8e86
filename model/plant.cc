#include "model/plant.h"

#include <cmath>

namespace vb::model {

Plant::Plant(const PlantParams& params) : p_(params) {
  K_ = p_.K_reluctance_H_m();
  two_mu_r_ = 2.0 * p_.mu_r;
  L_prime_ = p_.L_prime_H();
  area_diff_m2_ = p_.A1_m2 - p_.A2_m2;
  inv_m_ = p_.m_kg > 0.0 ? 1.0 / p_.m_kg : 0.0;
}

double Plant::BalanceCurrent_A(double x_m, double supply_pressure_Pa) const {
  const double passive = PassiveForce_N(x_m, supply_pressure_Pa);
  const double slope = dLdx_H_per_m(x_m);
  if (passive >= 0.0 || slope <= 0.0) return -1.0;
  return std::sqrt(-2.0 * passive / slope);
}

}  // namespace vb::model
