#include "control/pi_current.h"
#include "control/param_check.h"

#include <cmath>
#include <cstdio>
#include <string>

namespace vb::control {
namespace {

Status Check(bool ok, const char* field, const char* problem, double v) {
  if (ok) return Status::Ok();
  return Status::InvalidArgument(std::string("pi.") + field + ": " + problem + ", got " + FormatNumber(v));
}

}  // namespace

Status PiCurrent::Validate(const Params& p) {
  VB_RETURN_IF_ERROR(Check(std::isfinite(p.kp_V_per_A) && p.kp_V_per_A >= 0.0, "kp_V_per_A", "must be >= 0",
                           p.kp_V_per_A));
  VB_RETURN_IF_ERROR(Check(std::isfinite(p.ki_V_per_A_s) && p.ki_V_per_A_s >= 0.0, "ki_V_per_A_s", "must be >= 0",
                           p.ki_V_per_A_s));
  VB_RETURN_IF_ERROR(Check(p.kp_V_per_A > 0.0 || p.ki_V_per_A_s > 0.0, "kp_V_per_A",
                           "kp and ki must not both be 0", p.kp_V_per_A));
  VB_RETURN_IF_ERROR(Check(std::isfinite(p.feedforward_R_ohm) && p.feedforward_R_ohm >= 0.0, "feedforward_R_ohm",
                           "must be >= 0", p.feedforward_R_ohm));
  VB_RETURN_IF_ERROR(Check(std::isfinite(p.carrier_Hz) && p.carrier_Hz > 0.0, "carrier_Hz", "must be > 0",
                           p.carrier_Hz));
  return Status::Ok();
}

StatusOr<PiCurrent> PiCurrent::Create(const Params& p) {
  Status s = Validate(p);
  if (!s.ok()) return s;
  return PiCurrent(p);
}

PiCurrent::Params PiCurrent::FromPoles(double L_H, double R_ohm, double pole1_rad_s, double pole2_rad_s) {
  Params p;
  p.kp_V_per_A = L_H * (pole1_rad_s + pole2_rad_s) - R_ohm;
  p.ki_V_per_A_s = L_H * pole1_rad_s * pole2_rad_s;
  return p;
}

SwitchCommand PiCurrent::Step(const Measurement& m, const Reference& r, ControllerState* state) const {
  if (!r.command_on) {
    *state = InitialState();
    return SwitchCommand::Gate(0);
  }
  if (!std::isfinite(m.current_A) || !std::isfinite(r.value)) return SwitchCommand::Gate(0);

  const double supply = (std::isfinite(m.supply_V) && m.supply_V > 0.0) ? m.supply_V : 0.0;
  const double T = 1.0 / p_.carrier_Hz;
  const double e = r.value - m.current_A;
  double& integ = state->x[kIntegrator];

  const double v_unsat = p_.kp_V_per_A * e + integ + p_.feedforward_R_ohm * r.value;
  double v = v_unsat;
  bool saturated = false;
  if (v > supply) {
    v = supply;
    saturated = true;
  } else if (v < 0.0) {
    v = 0.0;
    saturated = true;
  }
  // Conditional integration: integrate unless saturated with the error pushing further into the limit.
  const bool winding_up = (v_unsat > supply && e > 0.0) || (v_unsat < 0.0 && e < 0.0);
  if (!winding_up) integ += p_.ki_V_per_A_s * T * e;

  state->x[kLastVoltage] = v;
  state->x[kLastDemand] = v_unsat;
  state->mode = saturated ? 1 : 0;
  return VoltageToPwm(v, supply, p_.carrier_Hz);
}

}  // namespace vb::control
