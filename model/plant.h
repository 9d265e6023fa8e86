// The valve plant: electromagnetic, mechanical and pressure-force physics, pure and I/O-free.
//
// States: coil current i [A], spool position x [m] in [x_min, x_max], spool velocity v [m/s].
//   Coil (seed 000 eq. 5-7; seed 002 eq. 2, 10):   L(x) di/dt = v_coil - R i - i (dL/dx) v
//   Force (co-energy, seed 000 eq. 8; seed 002 eq. 3-6):  F_m = 1/2 i^2 dL/dx
//   Motion (seed 000 eq. 9-11; seed 002 eq. 7):  m dv/dt = F_m + (A1 - A2) P_sup - k (x + delta) - b v - m g_r
// For the reluctance law of seed 000, 1/2 i^2 dL/dx = L^2 i^2 / (N^2 A_e mu0) exactly (eq. 8), and the
// back-EMF term i (dL/dx) v / L = 2 mu_r L v i / K (eq. 7): one formulation serves every preset.
#pragma once

#include "model/params.h"

namespace vb::model {

class Plant {
 public:
  explicit Plant(const PlantParams& params);

  const PlantParams& params() const { return p_; }
  bool has_moving_part() const { return p_.has_moving_part; }

  // Inductance and its slope at position x.
  double L_H(double x_m) const {
    switch (p_.law) {
      case InductanceLaw::kReluctance: return K_ / (p_.l_c_m + two_mu_r_ * (p_.x_t_m - x_m));   // eq. (4)
      case InductanceLaw::kLimitedTravel: return L_prime_ * x_m / (x_m + p_.a_m);            // seed 002 eq. (5)
      case InductanceLaw::kConstant: return p_.L_H;
    }
    return p_.L_H;
  }
  double dLdx_H_per_m(double x_m) const {
    switch (p_.law) {
      case InductanceLaw::kReluctance: {
        const double L = L_H(x_m);
        return two_mu_r_ * L * L / K_;                                                      // eq. (6)
      }
      case InductanceLaw::kLimitedTravel: {
        const double s = x_m + p_.a_m;
        return L_prime_ * p_.a_m / (s * s);
      }
      case InductanceLaw::kConstant: return 0.0;
    }
    return 0.0;
  }

  // L(x) and dL/dx in one evaluation (the reluctance law's slope needs L itself).
  void InductanceAndSlope(double x_m, double* L_H_out, double* dLdx_out) const {
    switch (p_.law) {
      case InductanceLaw::kReluctance: {
        const double L = K_ / (p_.l_c_m + two_mu_r_ * (p_.x_t_m - x_m));
        *L_H_out = L;
        *dLdx_out = two_mu_r_ * L * L / K_;
        return;
      }
      default:
        *L_H_out = L_H(x_m);
        *dLdx_out = dLdx_H_per_m(x_m);
    }
  }

  // Magnetic pull (seed 000 eq. 8; seed 002 eq. 6).
  double MagneticForce_N(double i_A, double x_m) const { return 0.5 * i_A * i_A * dLdx_H_per_m(x_m); }

  // Everything but the magnetic and damping forces: pressure (eq. 10), spring (eq. 9), gravity (seed 002).
  double PassiveForce_N(double x_m, double supply_pressure_Pa) const {
    return area_diff_m2_ * supply_pressure_Pa - p_.k_N_per_m * (x_m + p_.delta_m) - p_.m_kg * p_.g_r_m_per_s2;
  }

  // Net force on a spool at rest at x (what decides whether it stays at a stop).
  double NetForceAtRest_N(double i_A, double x_m, double supply_pressure_Pa) const {
    return MagneticForce_N(i_A, x_m) + PassiveForce_N(x_m, supply_pressure_Pa);
  }

  // di/dt (eq. 7) for the coil alone.
  double CurrentRate_A_per_s(double i_A, double x_m, double v_mps, double v_coil_V) const {
    const double L = L_H(x_m);
    return (v_coil_V - p_.R_ohm * i_A - i_A * dLdx_H_per_m(x_m) * v_mps) / L;
  }

  // dv/dt (eq. 11) of a free spool.
  double Acceleration_mps2(double i_A, double x_m, double v_mps, double supply_pressure_Pa) const {
    return (MagneticForce_N(i_A, x_m) + PassiveForce_N(x_m, supply_pressure_Pa) - p_.b_N_s_per_m * v_mps) *
           inv_m_;
  }

  // The current at which a spool at rest at x has zero net force, i.e. |i| above it lifts the spool off the
  // lower stop and |i| below it lets it leave the upper stop. Returns a negative value when no current
  // balances the passive force (the passive force alone already points up, or dL/dx = 0).
  double BalanceCurrent_A(double x_m, double supply_pressure_Pa) const;

 private:
  PlantParams p_;
  double K_ = 0.0;          // N^2 A_e mu_r mu0 [H m]
  double two_mu_r_ = 0.0;
  double L_prime_ = 0.0;    // seed 002 L' [H]
  double area_diff_m2_ = 0.0;
  double inv_m_ = 0.0;
};

}  // namespace vb::model
