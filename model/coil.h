// The coil's electromagnetic physics with effects (docs/model.md, "Equations", "Effects" and "Structure"):
// the flux law and force, the coil's resistance, the current the flux follows (residual magnetism), and the
// terminal quantities the driver and the sensor see (supply resistance, eddy currents). Pure functions of a
// Plant and the state; inline because the integrator's right-hand side calls them at every stage.
#pragma once

#include <algorithm>
#include <cmath>

#include "model/driver.h"
#include "model/plant.h"

namespace vb::model {

// The magnetic law at current i and position x: lambda(i, x) and its co-energy's x-derivative.
struct Magnetics {
  double dlambda_di;  // incremental inductance [H]
  double dlambda_dx;  // [Wb/m]
  double force_N;     // magnetic pull
};

// Linear (seed 000 eq. 7-8, seed 002 eq. 6): lambda = L(x) i, F = 1/2 i^2 dL/dx. magnetic_saturation: a
// saturating core in parallel with the air path it can never lose (the core at mu_r -> 1):
//   lambda = ls f(u) + La i,   u = Lc i / ls,   La = L / mu_r,  Lc = L - La,  ls = N A_e B_sat
// with the knee f Frohlich's f(u) = u / (1 + |u|) (the classic magnetisation-curve fit, a gradual knee),
// tanh(u) (a sharp one) or (2/pi) atan(pi u / 2) (between the two); all give lambda = L i at small currents. Co-energy W' = ls^2/Lc G(u) + La i^2 / 2,
// G' = f (Frohlich: G = |u| - ln(1 + |u|); tanh: G = ln cosh u), so at constant i
//   F = dW'/dx = (dLc/dx) (ls i f(u) / Lc - ls^2 / Lc^2 G(u)) + (dLa/dx) i^2 / 2.
// The air path keeps the incremental inductance >= La: deep saturation stays physical and non-stiff.
//
// Form 3, the core in series with the gap (the reluctance law only): the magnetic circuit of seed 000 eq. 4
// with the core's permeability falling with its flux density. The core's field H and the gap share the
// magnetomotive force, N i = l_c H + phi R_g(x), phi = A_e B(H), with the steel's curve Frohlich's knee plus
// the vacuum's slope, B(H) = B_sat u / (1 + |u|) + mu0 H, u = H / H_k, H_k = B_sat / (mu0 (mu_r - 1)) (so
// B'(0) = mu0 mu_r). R_g(x) = N^2 / L(x) - l_c / (mu0 mu_r A_e) is the gaps' reluctance. Solved for H at
// each (i, x) (monotone: Newton from the unsaturated solution, which lies below the root); then
//   lambda = N phi,  dlambda/di = N^2 A_e B' / (l_c + A_e B' R_g),
//   dlambda/dx = -N A_e^2 B' B R_g' / (l_c + A_e B' R_g),  F = -phi^2 R_g' / 2 = lambda^2 L' / (2 L^2)
// (the energy stored in the gaps at constant flux; the core's does not depend on x). Unlike the parallel
// forms, where the saturated share of the inductance is 1/mu_r at every gap, here a wide gap takes most of the
// magnetomotive force and the core barely saturates, and a closed one saturates it hard: a plunger's
// saturation depends on where it is.
inline Magnetics SeriesCoreMagnetics(const PlantParams& pp, double L, double dLdx, double i, double x) {
  constexpr double kMu0 = 4e-7 * M_PI;
  const double N = pp.N_turns, A = pp.A_e_m2, lc = pp.l_c_m, mu_r = pp.mu_r, B_s = pp.effects.saturation_B_T;
  const double Rg = std::max(N * N / L - lc / (kMu0 * mu_r * A), 0.0);
  const double dRg = -N * N * dLdx / (L * L);
  const double Hk = B_s / (kMu0 * std::max(mu_r - 1.0, 1e-9));
  const double mmf = N * std::abs(i);
  auto B_of = [&](double H, double* dB) {
    const double u = H / Hk;
    *dB = B_s / Hk / ((1.0 + u) * (1.0 + u)) + kMu0;
    return B_s * u / (1.0 + u) + kMu0 * H;
  };
  // The unsaturated solution, B = mu0 mu_r H, is at or below the root (B(H) <= mu0 mu_r H); g is concave and
  // increasing for H >= 0, so Newton's steps from there rise monotonically to it.
  double H = mmf / (lc + kMu0 * mu_r * A * Rg);
  double dB = 0.0, B = 0.0;
  for (int k = 0; k < 60; ++k) {
    B = B_of(H, &dB);
    const double g = lc * H + A * B * Rg - mmf;
    const double step = g / (lc + A * dB * Rg);
    H -= step;
    if (std::abs(step) <= 1e-13 * std::max(H, 1e-30)) break;
  }
  B = B_of(H, &dB);
  const double sign = i < 0.0 ? -1.0 : 1.0;
  const double den = lc + A * dB * Rg;
  Magnetics m;
  m.dlambda_di = N * N * A * dB / den;
  m.dlambda_dx = -sign * N * A * A * dB * B * dRg / den;
  const double phi = A * B;
  m.force_N = -0.5 * phi * phi * dRg;
  (void)x;
  return m;
}

inline Magnetics MagneticsAt(const Plant& plant, double i, double x) {
  double L, dLdx;
  plant.InductanceAndSlope(x, &L, &dLdx);
  Magnetics m;
  const PlantParams& pp = plant.params();
  const double B_sat = pp.effects.saturation_B_T;
  if (B_sat <= 0.0) {  // linear: lambda = L(x) i
    m.dlambda_di = L;
    m.dlambda_dx = dLdx * i;
    m.force_N = 0.5 * i * i * dLdx;
    return m;
  }
  if (pp.effects.saturation_tanh >= 2.5 && pp.law == InductanceLaw::kReluctance)
    return SeriesCoreMagnetics(pp, L, dLdx, i, x);
  const double air = pp.law == InductanceLaw::kReluctance ? 1.0 / std::max(pp.mu_r, 1.0) : 0.01;
  const double La = air * L, Lc = L - La, dLa = air * dLdx, dLc = dLdx - dLa;
  const double ls = pp.N_turns * pp.A_e_m2 * B_sat;
  const double u = Lc * i / ls;
  const double au = std::abs(u);
  double f, df, G;
  if (pp.effects.saturation_tanh >= 1.5) {  // arctan (and form 3 under a law without a core: see above)
    // arctan (a knee between Frohlich's and tanh's): f = (2/pi) atan(pi u / 2), slope 1 at 0;
    // G = (2/pi) (|u| atan(pi |u| / 2) - ln(1 + (pi u / 2)^2) / pi).
    const double a = 0.5 * M_PI * au;
    f = (2.0 / M_PI) * std::atan(0.5 * M_PI * u);
    df = 1.0 / (1.0 + a * a);
    G = (2.0 / M_PI) * (au * std::atan(a) - std::log1p(a * a) / M_PI);
  } else if (pp.effects.saturation_tanh >= 0.5) {
    f = std::tanh(u);
    df = 1.0 - f * f;
    G = au + std::log1p(std::exp(-2.0 * au)) - M_LN2;  // ln cosh u, stable for large |u|
  } else {
    f = u / (1.0 + au);
    df = 1.0 / ((1.0 + au) * (1.0 + au));
    G = au - std::log1p(au);
  }
  m.dlambda_di = Lc * df + La;
  m.dlambda_dx = (dLc * df + dLa) * i;
  m.force_N = dLc * (ls * i * f / Lc - ls * ls / (Lc * Lc) * G) + 0.5 * dLa * i * i;
  return m;
}

// coil_heating: R(T) = R (1 + alpha dT).
inline double ResistanceAt(const Plant& plant, double dT_K) {
  const Effects& fx = plant.params().effects;
  const double R = plant.params().R_ohm;
  return fx.heating ? R * (1.0 + fx.heating_alpha_per_K * dT_K) : R;
}

// The current the flux follows: residual_magnetism's j = alpha i + (1 - alpha) i_m (i_m the play operator's
// output); the magnetising current otherwise.
inline double FluxCurrent(const Effects& fx, double i, double i_m) {
  if (fx.residual_w_A <= 0.0) return i;
  return fx.residual_alpha * i + (1.0 - fx.residual_alpha) * i_m;
}

// The coil's terminal quantities for a magnetising current: what the driver and the sensor see.
struct Terminal {
  double i_A;   // terminal current
  double v_V;   // terminal voltage
  double vL_V;  // voltage across the magnetising inductance (drives dlambda/dt)
};

// v_source_V: the driver's voltage plus any series disturbance (read only when the segment is not blocked).
// Without eddy currents the terminal current is the magnetising current. With a loss resistance R_p across the
// magnetising inductance (one eddy branch) and the supply's R_s in series while the supply drives:
//   v_source - R_s i = R i + v_L,  i = i_mag + v_L / R_p
//   =>  v_L = (v_source - (R + R_s) i_mag) / (1 + (R + R_s)/R_p)
// and with the switch and the diode both off (blocked) the terminal current is 0 and i_mag decays through
// R_p: v_L = -R_p i_mag.
inline Terminal TerminalAt(const Plant& plant, const DriveSegment& seg, double v_source_V, double i_mag,
                           double dT_K) {
  const Effects& fx = plant.params().effects;
  Terminal out;
  if (!fx.any()) {  // the nominal coil: the hot path of every integrated piece
    out.i_A = seg.blocked ? 0.0 : i_mag;
    out.v_V = seg.blocked ? 0.0 : v_source_V;
    out.vL_V = out.v_V - plant.params().R_ohm * out.i_A;
    return out;
  }
  const double R = ResistanceAt(plant, dT_K);
  const double Rs = seg.from_supply ? fx.supply_R_ohm : 0.0;
  if (seg.blocked) {
    out.i_A = 0.0;
    out.vL_V = fx.eddy_R_p_ohm > 0.0 ? -fx.eddy_R_p_ohm * i_mag : 0.0;
    out.v_V = out.vL_V;
    return out;
  }
  if (fx.eddy_R_p_ohm > 0.0) {
    const double Rser = R + Rs;
    out.vL_V = (v_source_V - Rser * i_mag) / (1.0 + Rser / fx.eddy_R_p_ohm);
    out.i_A = i_mag + out.vL_V / fx.eddy_R_p_ohm;
  } else {
    out.i_A = i_mag;
    out.vL_V = v_source_V - (R + Rs) * i_mag;
  }
  out.v_V = v_source_V - Rs * out.i_A;
  return out;
}

}  // namespace vb::model
