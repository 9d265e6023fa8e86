#include "control/predictive_current.h"
#include "control/param_check.h"

#include <cmath>
#include <cstdio>
#include <string>

namespace vb::control {
namespace {

constexpr double kMu0 = 4.0e-7 * 3.14159265358979323846;  // [H/m]

}  // namespace

Status PredictiveCurrent::Validate(const Params& p) {
  VB_RETURN_IF_ERROR(CheckPositive("predictive.", "horizon_s", p.horizon_s));
  VB_RETURN_IF_ERROR(CheckPositive("predictive.", "w_I_per_A2", p.w_I_per_A2));
  VB_RETURN_IF_ERROR(CheckNonNegative("predictive.", "w_v_per_V2", p.w_v_per_V2));
  VB_RETURN_IF_ERROR(CheckNonNegative("predictive.", "R_ohm", p.R_ohm));
  VB_RETURN_IF_ERROR(CheckPositive("predictive.", "L_H", p.L_H));
  VB_RETURN_IF_ERROR(CheckPositive("predictive.", "carrier_Hz", p.carrier_Hz));
  if (p.use_measured_position) {
    VB_RETURN_IF_ERROR(CheckPositive("predictive.", "turns", p.turns));
    VB_RETURN_IF_ERROR(CheckPositive("predictive.", "core_area_m2", p.core_area_m2));
    VB_RETURN_IF_ERROR(CheckPositive("predictive.", "core_length_m", p.core_length_m));
    VB_RETURN_IF_ERROR(CheckPositive("predictive.", "mu_r", p.mu_r));
    VB_RETURN_IF_ERROR(CheckPositive("predictive.", "total_gap_m", p.total_gap_m));
  }
  return Status::Ok();
}

StatusOr<PredictiveCurrent> PredictiveCurrent::Create(const Params& p) {
  Status s = Validate(p);
  if (!s.ok()) return s;
  return PredictiveCurrent(p);
}

double PredictiveCurrent::K() const { return p_.turns * p_.turns * p_.core_area_m2 * p_.mu_r * kMu0; }

double PredictiveCurrent::InductanceAt(double x_m) const {
  const double x = x_m < 0.0 ? 0.0 : (x_m > p_.total_gap_m ? p_.total_gap_m : x_m);
  return K() / (p_.core_length_m + 2.0 * p_.mu_r * (p_.total_gap_m - x));
}

double PredictiveCurrent::InductanceSlopeAt(double x_m) const {
  const double L = InductanceAt(x_m);
  return 2.0 * p_.mu_r * L * L / K();
}

PredictiveCurrent::Terms PredictiveCurrent::Compute(const Measurement& m, const Reference& r) const {
  Terms t{};
  const double i = m.current_A;
  const bool have_x = p_.use_measured_position && std::isfinite(m.position_m);
  t.L_H = have_x ? InductanceAt(m.position_m) : p_.L_H;
  t.back_emf_V = (have_x && std::isfinite(m.velocity_mps)) ? InductanceSlopeAt(m.position_m) * m.velocity_mps * i
                                                            : 0.0;
  const double h = p_.horizon_s;
  const double L = t.L_H;
  t.k = h * h / (h * h + (p_.w_v_per_V2 / p_.w_I_per_A2) * L * L);
  const double target = r.value + h * r.rate;  // i*(t+h)
  t.v_opt_V = t.k * (L * (target - i) / h + p_.R_ohm * i + t.back_emf_V);
  return t;
}

SwitchCommand PredictiveCurrent::Step(const Measurement& m, const Reference& r, ControllerState* state) const {
  if (!r.command_on) {
    *state = InitialState();
    return SwitchCommand::Gate(0);
  }
  if (!std::isfinite(m.current_A) || !std::isfinite(r.value) || !std::isfinite(r.rate)) {
    return SwitchCommand::Gate(0);
  }
  const double supply = (std::isfinite(m.supply_V) && m.supply_V > 0.0) ? m.supply_V : 0.0;
  const Terms t = Compute(m, r);
  double v = t.v_opt_V;
  bool saturated = false;
  if (!(v >= 0.0)) {  // also catches NaN
    v = 0.0;
    saturated = true;
  } else if (v > supply) {
    v = supply;
    saturated = true;
  }
  state->x[0] = t.v_opt_V;
  state->x[1] = t.L_H;
  state->x[2] = t.back_emf_V;
  state->mode = saturated ? 1 : 0;
  return VoltageToPwm(v, supply, p_.carrier_Hz);
}

}  // namespace vb::control
