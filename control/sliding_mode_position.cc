#include "control/sliding_mode_position.h"
#include "control/param_check.h"

#include <cmath>
#include <cstdlib>
#include <string>

namespace vb::control {
namespace {

double Clamp(double v, double lo, double hi) { return v < lo ? lo : (v > hi ? hi : v); }

}  // namespace

Status SlidingModePosition::Validate(const Params& p) {
  VB_RETURN_IF_ERROR(CheckPositive("", "carrier_Hz", p.carrier_Hz));
  VB_RETURN_IF_ERROR(CheckPositive("", "surface_slope_per_s", p.surface_slope_per_s));
  VB_RETURN_IF_ERROR(CheckPositive("", "reaching_gain_SI", p.reaching_gain_SI));
  if (!(p.reaching_exponent > 0.0 && p.reaching_exponent < 1.0)) {
    return Status::InvalidArgument("reaching_exponent: must be in (0, 1) (eq. 20), got " +
                                   std::to_string(p.reaching_exponent));
  }
  VB_RETURN_IF_ERROR(CheckPositive("", "current_reaching_rate_A_per_s", p.current_reaching_rate_A_per_s));
  VB_RETURN_IF_ERROR(CheckPositive("", "current_boundary_layer_A", p.current_boundary_layer_A));
  VB_RETURN_IF_ERROR(CheckPositive("", "current_limit_A", p.current_limit_A));
  if (!(std::isfinite(p.bridge_diode_drop_V) && p.bridge_diode_drop_V >= 0.0)) {
    return Status::InvalidArgument("bridge_diode_drop_V: must be finite and >= 0, got " +
                                   std::to_string(p.bridge_diode_drop_V));
  }
  return p.model.Validate("model.");
}

StatusOr<SlidingModePosition> SlidingModePosition::Create(const Params& p) {
  VB_RETURN_IF_ERROR(Validate(p));
  return SlidingModePosition(p);
}

SlidingModePosition::Params SlidingModePosition::PaperParams() {
  Params p;
  p.surface_slope_per_s = 5.0;
  p.reaching_gain_SI = 1.5;
  p.reaching_exponent = 0.9;
  p.current_reaching_rate_A_per_s = 9.0;
  return p;
}

SlidingModePosition::SlidingModePosition(const Params& p) : p_(p) {
  if (!Validate(p_).ok()) std::abort();  // invariant: callers validate first (Create does)
}

double SlidingModePosition::PowerRate(double s_mps) const {
  if (s_mps == 0.0) return 0.0;
  const double mag = p_.reaching_gain_SI * std::pow(std::fabs(s_mps), p_.reaching_exponent);
  return s_mps > 0.0 ? mag : -mag;
}

double SlidingModePosition::Sigmoid(double s_A) const { return s_A / (std::fabs(s_A) + p_.current_boundary_layer_A); }

SwitchCommand SlidingModePosition::Step(const Measurement& m, const Reference& r, ControllerState* state) const {
  ControllerState& st = *state;
  if (!r.command_on) {
    st = ControllerState{};
    st.mode = kModeReleased;
    return SwitchCommand::Gate(0);
  }
  if (!std::isfinite(m.position_m) || !std::isfinite(m.velocity_mps)) {
    st = ControllerState{};
    st.mode = kModeNoPosition;
    return SwitchCommand::Gate(0);
  }
  if (!std::isfinite(m.current_A) || !std::isfinite(r.value) || !std::isfinite(r.rate)) {
    return SwitchCommand::Gate(0);  // a transient fault: switch off, state untouched
  }
  const bool first = st.mode != kModeRunning;
  const LungeSolenoidModel& mdl = p_.model;
  const double h = 1.0 / p_.carrier_Hz;
  const double x = m.position_m;
  const double xdot = m.velocity_mps;
  const double c1 = p_.surface_slope_per_s;

  // Position loop (eqs. 18, 20-23).
  const double e = x - r.value;
  const double edot = xdot - r.rate;
  const double xddot_d = (p_.reference_accel_feedforward && !first) ? (r.rate - st.x[kPrevReferenceRate]) / h : 0.0;
  const double s = c1 * e + edot;                                         // eq. 18
  const double u = mdl.mass_kg * (-c1 * edot + xddot_d - PowerRate(s)) +  // eq. 21
                   mdl.spring_N_per_m * x + mdl.damping_N_s_per_m * xdot;
  const double f_unclamped = u + mdl.mass_kg * mdl.gravity_mps2;  // eq. 22
  const double f_mag = Clamp(f_unclamped, 0.0, mdl.ForceN(p_.current_limit_A, x));
  const double i_d = Clamp(mdl.CurrentForForceA(f_mag, x), 0.0, p_.current_limit_A);  // eq. 23

  // Current loop (eqs. 24-29 with the sigmoid).
  const double i = m.current_A;
  const double s_i = i - i_d;
  const double did_dt = first ? 0.0 : (i_d - st.x[kPrevCurrentDemand]) / h;
  const double i_eq = p_.equivalent_control_at_demand ? i_d : i;
  const double v_raw = mdl.InductanceH(x) * (-p_.current_reaching_rate_A_per_s * Sigmoid(s_i) + did_dt) +
                       mdl.coil_resistance_ohm * i_eq + i_eq * xdot * mdl.InductanceSlopeH_per_m(x);  // eq. 29
  const double v_max = m.supply_V > 0.0 ? m.supply_V : 0.0;
  const double v_min = p_.h_bridge ? -(v_max + 2.0 * p_.bridge_diode_drop_V) : 0.0;
  const double v = Clamp(v_raw, v_min, v_max);

  st.mode = kModeRunning;
  st.x[kPrevCurrentDemand] = i_d;
  st.x[kPrevReferenceRate] = r.rate;
  st.x[kForceUnclamped] = f_unclamped;
  st.x[kPositionSurface] = s;
  st.x[kForceDemand] = f_mag;
  st.x[kCurrentSurface] = s_i;
  st.x[kVoltageDemand] = v;
  st.x[kCurrentDemand] = i_d;
  return CoilVoltageCommand(v, m.supply_V, p_.carrier_Hz, p_.h_bridge, p_.bridge_diode_drop_V, i);
}

}  // namespace vb::control
