// An independent plant for the moving-valve identification (issue 35, point 1): a valve written here, not with
// model/ (no code shared with the plant the identification fits), with forms the catalog does not have:
//  - the core: a tabulated B-H curve of a low-carbon steel (1010-like, piecewise linear, mu0 beyond the table)
//    in series with the two working air gaps: N i = H(B) l_c + 2 B g(x) / mu0, g = g_res + stroke - x, with the
//    flux linkage lambda = N B A as the state (so i is explicit in lambda and x);
//  - eddy currents as a two-rung ladder: a loss resistance R_e1 across the winding's EMF and a second rung
//    R_e2 in series with L_e2 (a deeper layer that answers more slowly);
//  - the pull F = B^2 A / mu0 (two gaps, each B^2 A / (2 mu0), at constant flux);
//  - the spring k (x + x0) with preload F0 = k x0, viscous damping b and Stribeck friction
//    F_f = sign(v) (F_c + (F_s - F_c) exp(-(v / v_s)^2)), sticking while |net force| <= F_s at rest;
//  - a flow-dependent pressure force A_net P (1 - c_flow x / stroke): the force falls as the valve opens;
//  - end stops at 0 and the stroke (inelastic);
//  - the scope: white noise per sweep, averaging, a resolution step, and optionally a baseline offset and a
//    switching spike at the edge.
// Integrated with classical RK4 at 1/20 of the sample period (the states are smooth between the stops; a stop
// is applied after each step).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

namespace vb::perf {

struct IndependentValve {
  double supply_V = 24.0;
  double R_ohm = 40.0;
  double N = 1500.0;
  double A_m2 = 30e-6;        // pole area
  double l_core_m = 0.05;     // core path
  double g_res_m = 0.05e-3;   // residual gap when pulled in
  double stroke_m = 0.8e-3;
  double m_kg = 0.01;
  double k_N_per_m = 2000.0;
  double F0_N = 3.0;          // preload at rest
  double A_net_m2 = 5e-6;     // pressure area against the pull
  double c_flow = 0.3;        // the pressure force falls by this fraction when fully open
  double b_N_s_per_m = 1.0;
  double Fc_N = 0.05, Fs_N = 0.1, v_s_m_per_s = 0.01;  // Stribeck
  double Re1_ohm = 2000.0, Re2_ohm = 500.0, Le2_H = 0.02;
  // The scope.
  double dt_s = 1e-5;
  double noise_A = 2e-3;
  int averaged = 4;
  double lsb_A = 1.0 / 480.0;
  double offset_A = 0.0, spike_A = 0.0;
  // The supply and the driver as they are, against what a session declares (perf_changes): the supply delivers
  // supply_gain x the declared voltage, and the driver switches delay_s after the gate (rounded to samples).
  double supply_gain = 1.0;
  double delay_s = 0.0;
  // For ablation studies (perf_identify --ablate core): a linear core of this relative permeability instead of
  // the steel's table (0 = the table).
  double linear_core_mu_r = 0.0;
};

// H (A/m) of the steel at B (T): 1010-like steel, piecewise linear; beyond the table the slope is mu0.
inline double SteelH(double B) {
  static const std::array<double, 12> b = {0.0, 0.4, 0.8, 1.1, 1.3, 1.45, 1.55, 1.65, 1.75, 1.85, 2.0, 2.2};
  static const std::array<double, 12> h = {0.0, 120.0, 200.0, 300.0, 450.0, 700.0, 1100.0, 2000.0, 4000.0, 8000.0,
                                           25000.0, 150000.0};
  const double a = std::abs(B);
  double H;
  if (a >= b.back()) {
    H = h.back() + (a - b.back()) / (4e-7 * M_PI);
  } else {
    std::size_t j = 1;
    while (b[j] < a) ++j;
    H = h[j - 1] + (h[j] - h[j - 1]) * (a - b[j - 1]) / (b[j] - b[j - 1]);
  }
  return B < 0 ? -H : H;
}

// The current (noise-free) sampled every v.dt_s under a gate per sample: 1 puts the supply on the coil; 0 the
// flyback diode's -0.7 V while the winding conducts (the last sample's current above 0), else nothing. The
// driver switches delay_s after the gate. A switch-on (SimulateSwitchOn), or a PWM hold after one.
inline std::vector<double> SimulateGate(const IndependentValve& v, double supply_V, double P_Pa,
                                        const std::vector<std::int8_t>& gate) {
  const std::size_t n = gate.size();
  constexpr double mu0 = 4e-7 * M_PI;
  // State: lambda, i2 (second rung), x (from the rest position toward the open stop), xv.
  std::array<double, 4> s{0.0, 0.0, 0.0, 0.0};
  auto current_mag = [&](double lambda, double x) {
    const double B = lambda / (v.N * v.A_m2);
    const double g = v.g_res_m + v.stroke_m - x;
    const double H = v.linear_core_mu_r > 0.0 ? B / (mu0 * v.linear_core_mu_r) : SteelH(B);
    return (H * v.l_core_m + 2.0 * B * g / mu0) / v.N;
  };
  auto vL_of = [&](const std::array<double, 4>& y, double V) {
    const double im = current_mag(y[0], y[2]);
    return (V - v.R_ohm * (im + y[1])) / (1.0 + v.R_ohm / v.Re1_ohm);
  };
  bool stuck = true;  // at rest on the lower stop, held by the preload and static friction
  auto deriv = [&](const std::array<double, 4>& y, double V) {
    std::array<double, 4> d{};
    const double vL = vL_of(y, V);
    d[0] = vL;
    d[1] = (vL - v.Re2_ohm * y[1]) / v.Le2_H;
    const double B = y[0] / (v.N * v.A_m2);
    const double F_mag = B * B * v.A_m2 / mu0;
    const double F_p = v.A_net_m2 * P_Pa * (1.0 - v.c_flow * y[2] / v.stroke_m);
    double net = F_mag - v.F0_N - v.k_N_per_m * y[2] - F_p - v.b_N_s_per_m * y[3];
    const double vel = y[3];
    if (stuck) {
      d[2] = 0.0;
      d[3] = 0.0;
      return d;
    }
    const double sgn = vel > 0 ? 1.0 : vel < 0 ? -1.0 : (net > 0 ? 1.0 : -1.0);
    net -= sgn * (v.Fc_N + (v.Fs_N - v.Fc_N) * std::exp(-(vel / v.v_s_m_per_s) * (vel / v.v_s_m_per_s)));
    d[2] = vel;
    d[3] = net / v.m_kg;
    return d;
  };
  std::vector<double> out(n, 0.0);
  supply_V *= v.supply_gain;
  const auto delay = static_cast<std::size_t>(std::llround(v.delay_s / v.dt_s));
  const int sub = 20;
  const double h = v.dt_s / sub;
  bool started = false;  // from rest until the driver first switches on: nothing to integrate
  for (std::size_t k = 0; k < n; ++k) {
    const bool high = k >= delay && gate[k - delay] != 0;
    started = started || high;
    const double V = high ? supply_V : (k > 0 && out[k - 1] > 0.0 ? -0.7 : 0.0);
    if (started) {
      for (int j = 0; j < sub; ++j) {
        // Sticking: at rest (on a stop, or not yet moved) while the net force is within static friction.
        const double B = s[0] / (v.N * v.A_m2);
        const double F_mag = B * B * v.A_m2 / mu0;
        const double F_p = v.A_net_m2 * P_Pa * (1.0 - v.c_flow * s[2] / v.stroke_m);
        const double net = F_mag - v.F0_N - v.k_N_per_m * s[2] - F_p;
        if (std::abs(s[3]) < 1e-9) {
          const bool at_low = s[2] <= 0.0, at_high = s[2] >= v.stroke_m;
          stuck = (at_low && net <= v.Fs_N) || (at_high && net >= -v.Fs_N) || std::abs(net) <= v.Fs_N;
        } else {
          stuck = false;
        }
        const auto k1 = deriv(s, V);
        std::array<double, 4> y;
        for (int q = 0; q < 4; ++q) y[q] = s[q] + 0.5 * h * k1[q];
        const auto k2 = deriv(y, V);
        for (int q = 0; q < 4; ++q) y[q] = s[q] + 0.5 * h * k2[q];
        const auto k3 = deriv(y, V);
        for (int q = 0; q < 4; ++q) y[q] = s[q] + h * k3[q];
        const auto k4 = deriv(y, V);
        for (int q = 0; q < 4; ++q) s[q] += h / 6.0 * (k1[q] + 2 * k2[q] + 2 * k3[q] + k4[q]);
        if (s[2] <= 0.0 && s[3] < 0.0) s[2] = 0.0, s[3] = 0.0;
        if (s[2] >= v.stroke_m && s[3] > 0.0) s[2] = v.stroke_m, s[3] = 0.0;
        if (s[2] < 0.0) s[2] = 0.0;
        if (s[2] > v.stroke_m) s[2] = v.stroke_m;
      }
    }
    const double vL = vL_of(s, V);
    out[k] = current_mag(s[0], s[2]) + vL / v.Re1_ohm + s[1];
  }
  return out;
}

// The switch-on current (noise-free) sampled every v.dt_s: n samples, the gate rising at sample `on`.
inline std::vector<double> SimulateSwitchOn(const IndependentValve& v, double supply_V, double P_Pa, std::size_t n,
                                            std::size_t on) {
  std::vector<std::int8_t> gate(n, 0);
  for (std::size_t k = on; k < n; ++k) gate[k] = 1;
  return SimulateGate(v, supply_V, P_Pa, gate);
}

// One valve of the population, drawn from `rng`: 12, 24 or 48 V; a final current of 0.15 to 1.2 A; a stroke of
// 0.4 to 1.5 mm; a pole area, a core, a mass, a spring and a pressure area several times apart; the turns from
// an open-gap L/R of 0.4 to 3 ms, the residual gap so that the closed core reaches 1.0 to 2.2 T at the final
// current (into the steel's knee or beyond); the preload and the pressure area set so that the pull at the final current through the open gap clears the
// 4-bar load by a factor of 1.3 to 3 (it pulls in at 1-4 bar, and at 6 bar and 0.75x supply it may not).
inline IndependentValve DrawValve(std::mt19937& rng) {
  constexpr double mu0 = 4e-7 * M_PI;
  auto U = [&](double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng); };
  auto LU = [&](double a, double b) { return std::exp(U(std::log(a), std::log(b))); };
  IndependentValve v;
  const double supplies[] = {12.0, 24.0, 48.0};
  v.supply_V = supplies[std::uniform_int_distribution<int>(0, 2)(rng)];
  const double i_final = LU(0.15, 1.2);
  v.R_ohm = v.supply_V / i_final;
  v.stroke_m = LU(0.4e-3, 1.5e-3);
  v.A_m2 = LU(10e-6, 60e-6);
  v.l_core_m = LU(0.03, 0.1);
  // The turns from the open-gap time constant L_open / R of 0.4 to 3 ms (some do not settle in the 10 ms window
  // once the gap closes and L rises), L_open = mu0 N^2 A / (2 (g_res + stroke)); the residual gap from the
  // closed core's flux density at the final current, 1.0 to 2.2 T unsaturated (mu0 N i / (2 g_res)), so the
  // steel's knee bends the closed-gap inductance at the final current; one fixed-point pass settles both.
  const double L_open = v.R_ohm * LU(0.4e-3, 3e-3);
  const double B_closed = U(1.0, 2.2);
  v.g_res_m = 0.05e-3;
  for (int pass = 0; pass < 3; ++pass) {
    v.N = std::sqrt(2.0 * L_open * (v.g_res_m + v.stroke_m) / (mu0 * v.A_m2));
    v.g_res_m = std::clamp(mu0 * v.N * i_final / (2.0 * B_closed), 0.01e-3, 0.3e-3);
  }
  // The pull at the final current through the open gap (linear, no core drop): B = mu0 N i / (2 (g_res + stroke)).
  const double B_open = mu0 * v.N * i_final / (2.0 * (v.g_res_m + v.stroke_m));
  const double F_open = B_open * B_open * v.A_m2 / mu0;
  const double load_4bar = F_open / U(1.3, 3.0);
  const double share_p = U(0.15, 0.6);  // of the 4-bar load, the pressure's share
  v.A_net_m2 = share_p * load_4bar / 4e5;
  v.F0_N = (1.0 - share_p) * load_4bar;
  v.k_N_per_m = v.F0_N / v.stroke_m * LU(0.1, 1.0);
  v.c_flow = U(0.0, 0.5);
  // The mass from a flight time of 0.3 to 2 ms under half the open-gap pull (x = a t^2 / 2).
  const double t_flight = LU(0.3e-3, 2e-3);
  v.m_kg = std::clamp(0.5 * F_open * t_flight * t_flight / (2.0 * v.stroke_m), 1e-3, 30e-3);  // 1-30 g
  v.b_N_s_per_m = LU(0.02, 0.5) * 2.0 * std::sqrt(v.k_N_per_m * v.m_kg);  // 2-50 % of critical damping
  v.Fs_N = U(0.0, 0.05) * v.F0_N;
  v.Fc_N = U(0.5, 1.0) * v.Fs_N;
  v.v_s_m_per_s = LU(0.002, 0.05);
  // Eddy ladder: the first rung 10-100x R, the second rung R_e2 2-20x R with an L/R of 0.1-1 ms.
  v.Re1_ohm = v.R_ohm * LU(10.0, 100.0);
  v.Re2_ohm = v.R_ohm * LU(2.0, 20.0);
  v.Le2_H = v.Re2_ohm * LU(1e-4, 1e-3);
  // The scope: 50, 100 or 200 kHz; 1-8 sweeps; 1/240 to 1/1000 A; noise of one sweep 0.5-4 mA; a third of the
  // captures with an offset and a switching spike.
  const double rates[] = {50e3, 100e3, 200e3};
  v.dt_s = 1.0 / rates[std::uniform_int_distribution<int>(0, 2)(rng)];
  const int avg[] = {1, 2, 4, 8};
  v.averaged = avg[std::uniform_int_distribution<int>(0, 3)(rng)];
  v.lsb_A = 1.0 / LU(240.0, 1000.0);
  v.noise_A = LU(0.5e-3, 4e-3);
  if (U(0.0, 1.0) < 1.0 / 3.0) {
    v.offset_A = U(-0.005, 0.005);
    v.spike_A = (U(0.0, 1.0) < 0.5 ? -1.0 : 1.0) * U(0.01, 0.05);
  }
  return v;
}

// A captured trace of the valve: the noise-free current through the scope chain.
inline std::vector<double> Capture(const IndependentValve& v, const std::vector<double>& truth, std::size_t on,
                                   std::mt19937& rng) {
  std::normal_distribution<double> noise(0.0, v.noise_A);
  std::vector<double> out(truth.size());
  for (std::size_t k = 0; k < truth.size(); ++k) {
    double sum = 0.0;
    for (int s = 0; s < v.averaged; ++s) sum += truth[k] + noise(rng);
    double i = sum / v.averaged + v.offset_A;
    if (k >= on && k < on + 3) i += v.spike_A * std::pow(0.5, static_cast<double>(k - on));
    out[k] = v.lsb_A > 0.0 ? std::round(i / v.lsb_A) * v.lsb_A : i;
  }
  return out;
}

}  // namespace vb::perf
