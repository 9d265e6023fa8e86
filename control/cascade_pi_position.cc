#include "control/cascade_pi_position.h"
#include "control/param_check.h"

#include <cmath>
#include <cstdlib>
#include <string>

namespace vb::control {
namespace {

double Clamp(double v, double lo, double hi) { return v < lo ? lo : (v > hi ? hi : v); }

}  // namespace

Status LungeSolenoidModel::Validate(std::string_view prefix) const {
  VB_RETURN_IF_ERROR(CheckPositive(prefix, "mass_kg", mass_kg));
  VB_RETURN_IF_ERROR(CheckPositive(prefix, "spring_N_per_m", spring_N_per_m));
  VB_RETURN_IF_ERROR(CheckNonNegative(prefix, "damping_N_s_per_m", damping_N_s_per_m));
  VB_RETURN_IF_ERROR(CheckNonNegative(prefix, "gravity_mps2", gravity_mps2));
  VB_RETURN_IF_ERROR(CheckPositive(prefix, "inductance_scale_H", inductance_scale_H));
  VB_RETURN_IF_ERROR(CheckPositive(prefix, "overlap_length_m", overlap_length_m));
  VB_RETURN_IF_ERROR(CheckPositive(prefix, "coil_resistance_ohm", coil_resistance_ohm));
  return Status::Ok();
}

SwitchCommand CoilVoltageCommand(double v_coil_V, double supply_V, double carrier_Hz, bool h_bridge,
                                 double diode_drop_V, double current_A) {
  if (!h_bridge || !(current_A > 0.0) || !(supply_V > 0.0)) return VoltageToPwm(v_coil_V, supply_V, carrier_Hz);
  const double v_off = supply_V + 2.0 * diode_drop_V;  // magnitude of the fast-decay voltage while i > 0
  return SwitchCommand::Pwm(Clamp((v_coil_V + v_off) / (supply_V + v_off), 0.0, 1.0), carrier_Hz);
}

Status CascadePiPosition::Validate(const Params& p) {
  VB_RETURN_IF_ERROR(CheckPositive("", "carrier_Hz", p.carrier_Hz));
  VB_RETURN_IF_ERROR(CheckNonNegative("", "position_kp_N_per_m", p.position_kp_N_per_m));
  VB_RETURN_IF_ERROR(CheckNonNegative("", "position_ki_N_per_m_s", p.position_ki_N_per_m_s));
  VB_RETURN_IF_ERROR(CheckNonNegative("", "current_kp_V_per_A", p.current_kp_V_per_A));
  VB_RETURN_IF_ERROR(CheckNonNegative("", "current_ki_V_per_A_s", p.current_ki_V_per_A_s));
  if (p.position_kp_N_per_m == 0.0 && p.position_ki_N_per_m_s == 0.0) {
    return Status::InvalidArgument(
        "position_kp_N_per_m, position_ki_N_per_m_s: at least one must be > 0 (no position feedback)");
  }
  if (p.current_kp_V_per_A == 0.0 && p.current_ki_V_per_A_s == 0.0 && !p.voltage_feedforward) {
    return Status::InvalidArgument(
        "current_kp_V_per_A, current_ki_V_per_A_s: at least one must be > 0 when voltage_feedforward is off");
  }
  VB_RETURN_IF_ERROR(CheckPositive("", "current_limit_A", p.current_limit_A));
  VB_RETURN_IF_ERROR(CheckNonNegative("", "bridge_diode_drop_V", p.bridge_diode_drop_V));
  return p.model.Validate("model.");
}

StatusOr<CascadePiPosition> CascadePiPosition::Create(const Params& p) {
  VB_RETURN_IF_ERROR(Validate(p));
  return CascadePiPosition(p);
}

CascadePiPosition::CascadePiPosition(const Params& p) : p_(p) {
  if (!Validate(p_).ok()) std::abort();  // invariant: callers validate first (Create does)
}

SwitchCommand CascadePiPosition::Step(const Measurement& m, const Reference& r, ControllerState* state) const {
  ControllerState& st = *state;
  if (!r.command_on) {
    st = ControllerState{};
    st.mode = kModeReleased;
    return SwitchCommand::Gate(0);
  }
  if (!std::isfinite(m.position_m)) {
    st = ControllerState{};
    st.mode = kModeNoPosition;
    return SwitchCommand::Gate(0);
  }
  if (!std::isfinite(m.current_A) || !std::isfinite(r.value)) return SwitchCommand::Gate(0);  // state untouched
  st.mode = kModeRunning;
  const LungeSolenoidModel& mdl = p_.model;
  const double h = 1.0 / p_.carrier_Hz;
  const double x = m.position_m;

  // Outer loop: position -> force demand.
  const double e_x = r.value - x;
  const double f_ff = p_.force_feedforward ? mdl.spring_N_per_m * r.value + mdl.mass_kg * mdl.gravity_mps2 : 0.0;
  const double f_max = mdl.ForceN(p_.current_limit_A, x);
  const double f_p = f_ff + p_.position_kp_N_per_m * e_x;
  double i_f = st.x[kForceIntegral];
  const double i_f_next = i_f + p_.position_ki_N_per_m_s * h * e_x;
  const double f_next = f_p + i_f_next;
  if (!((f_next > f_max && e_x > 0.0) || (f_next < 0.0 && e_x < 0.0))) i_f = i_f_next;
  const double f_d = Clamp(f_p + i_f, 0.0, f_max);

  // Force -> current demand (eq. 23).
  const double i_d = Clamp(mdl.CurrentForForceA(f_d, x), 0.0, p_.current_limit_A);

  // Inner loop: current -> coil voltage.
  const double e_i = i_d - m.current_A;
  const double v_max = m.supply_V > 0.0 ? m.supply_V : 0.0;
  const double v_min = p_.h_bridge ? -(v_max + 2.0 * p_.bridge_diode_drop_V) : 0.0;
  const double v_p = (p_.voltage_feedforward ? mdl.coil_resistance_ohm * i_d : 0.0) + p_.current_kp_V_per_A * e_i;
  double i_v = st.x[kVoltageIntegral];
  const double i_v_next = i_v + p_.current_ki_V_per_A_s * h * e_i;
  const double v_next = v_p + i_v_next;
  if (!((v_next > v_max && e_i > 0.0) || (v_next < v_min && e_i < 0.0))) i_v = i_v_next;
  const double v = Clamp(v_p + i_v, v_min, v_max);

  st.x[kForceIntegral] = i_f;
  st.x[kVoltageIntegral] = i_v;
  st.x[kForceDemand] = f_d;
  st.x[kCurrentDemand] = i_d;
  st.x[kVoltageDemand] = v;
  return CoilVoltageCommand(v, m.supply_V, p_.carrier_Hz, p_.h_bridge, p_.bridge_diode_drop_V, m.current_A);
}

}  // namespace vb::control
