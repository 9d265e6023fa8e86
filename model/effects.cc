#include "model/effects.h"

#include <cmath>
#include <sstream>

namespace vb::model {

const std::vector<EffectInfo>& EffectCatalog() {
  static const std::vector<EffectInfo> catalog = {
      {"supply_resistance", "source impedance: the coil voltage sags by R_s i while the switch is on", true,
       {{"R_s", "ohm", &Effects::supply_R_ohm, 0.0, 100.0}}},
      {"supply_voltage", "the supply delivers a voltage other than declared (gain x the declared)", true,
       {{"gain", "1", &Effects::supply_gain, 0.2, 2.0}}},
      {"driver_delay", "the driver switches the coil a delay after its gate command", true,
       {{"delay_s", "s", &Effects::driver_delay_s, 0.0, 0.01}}},
      {"coil_heating", "R rises with coil temperature from I^2 R losses (one thermal node)", true,
       {{"alpha", "1/K", &Effects::heating_alpha_per_K, 0.0, 0.02},
        {"R_th", "K/W", &Effects::heating_R_th_K_per_W, 1e-3, 1e3},
        {"C_th", "J/K", &Effects::heating_C_th_J_per_K, 1e-4, 1e4},
        {"dT0", "K", &Effects::heating_dT0_K, 0.0, 300.0}}},
      {"eddy_currents", "eddy currents in the core: flux and force lag the coil current (one branch)", true,
       {{"R_p", "ohm", &Effects::eddy_R_p_ohm, 1.0, 1e7}}},
      {"sensor_lag", "current-sensor bandwidth and latency", true,
       {{"tau_s", "s", &Effects::sensor_tau_s, 0.0, 0.1}, {"delay_s", "s", &Effects::sensor_delay_s, 0.0, 0.1}}},
      {"magnetic_saturation", "core flux saturates at high magnetomotive force", true,
       {{"B_sat", "T", &Effects::saturation_B_T, 0.05, 1000.0},
        {"tanh", "1", &Effects::saturation_tanh, 0.0, 3.0}}},
      {"residual_magnetism", "remanent flux holds the spool after de-energising", true,
       {{"w", "A", &Effects::residual_w_A, 1e-4, 10.0},
        {"alpha", "1", &Effects::residual_alpha, 0.01, 1.0},
        {"im0", "A", &Effects::residual_im0_A, -10.0, 10.0}}},
      {"coulomb_friction", "dry friction / stiction on the spool", true,
       {{"F_c", "N", &Effects::friction_F_c_N, 0.0, 100.0}, {"F_s", "N", &Effects::friction_F_s_N, 0.0, 100.0}}},
      {"end_stop_bounce", "elastic impact at the end stops", true,
       {{"e", "1", &Effects::bounce_e, 0.0, 0.99}, {"v_stick", "m/s", &Effects::bounce_v_stick_mps, 1e-6, 1.0}}},
      {"sensor_offset", "the current-sense chain reads a constant offset", true,
       {{"offset_A", "A", &Effects::sensor_offset_A, -10.0, 10.0}}},
      {"sensor_gain", "the current-sense chain's gain is off its nominal value", true,
       {{"gain", "1", &Effects::sensor_gain, 0.2, 5.0}}},
      {"resistance_temperature", "the winding resistance follows the run's temperature, R (1 + alpha (T - T_ref))",
       true,
       {{"alpha", "1/K", &Effects::temperature_alpha_per_K, 0.0, 0.05},
        {"T_ref", "C", &Effects::temperature_ref_C, -60.0, 300.0}}},
  };
  return catalog;
}

std::vector<std::string> EffectNames() {
  std::vector<std::string> out = {"none"};
  for (const auto& e : EffectCatalog()) out.emplace_back(e.name);
  out.emplace_back("param:NAME");
  return out;
}

Status AddEffect(Effects* effects, std::string_view name, const std::vector<std::pair<std::string, double>>& params) {
  const EffectInfo* info = nullptr;
  for (const auto& e : EffectCatalog())
    if (e.name == name) info = &e;
  if (info == nullptr) {
    std::string known;
    for (const auto& n : EffectNames()) known += (known.empty() ? "" : ", ") + n;
    return Status::InvalidArgument("name: unknown effect '" + std::string(name) + "' (known: " + known + ")");
  }
  if (!info->simulated)
    return Status::InvalidArgument("name: effect '" + std::string(name) + "' is catalogued but not simulated yet");
  Effects e = *effects;
  if (name == "coil_heating") e.heating = true;
  if (name == "eddy_currents" && e.eddy_R_p_ohm == 0.0) e.eddy_R_p_ohm = 400.0;
  if (name == "supply_resistance" && e.supply_R_ohm == 0.0) e.supply_R_ohm = 0.5;
  if (name == "supply_voltage" && e.supply_gain == 1.0) e.supply_gain = 0.9;
  if (name == "driver_delay" && e.driver_delay_s == 0.0) e.driver_delay_s = 50e-6;
  if (name == "sensor_lag" && e.sensor_tau_s == 0.0 && e.sensor_delay_s == 0.0) e.sensor_tau_s = 50e-6;
  if (name == "magnetic_saturation" && e.saturation_B_T == 0.0) e.saturation_B_T = 2.0;
  if (name == "end_stop_bounce" && e.bounce_e == 0.0) e.bounce_e = 0.5;
  if (name == "residual_magnetism" && e.residual_w_A == 0.0) e.residual_w_A = 0.08;
  if (name == "resistance_temperature") e.temperature = true;
  if (name == "coulomb_friction" && e.friction_F_c_N == 0.0 && e.friction_F_s_N == 0.0) {
    e.friction_F_c_N = 1.0;
    e.friction_F_s_N = 1.5;
  }
  for (const auto& [pname, value] : params) {
    const EffectParamInfo* p = nullptr;
    for (const auto& candidate : info->params)
      if (candidate.name == pname) p = &candidate;
    if (p == nullptr) {
      std::string known;
      for (const auto& c : info->params) known += (known.empty() ? "" : ", ") + std::string(c.name);
      return Status::InvalidArgument("params[" + pname + "]: unknown parameter of " + std::string(name) +
                                     " (known: " + known + ")");
    }
    if (!std::isfinite(value) || value < p->min || value > p->max) {
      std::ostringstream os;
      os << "params[" << pname << "]: " << value << " " << p->unit << " is outside [" << p->min << ", " << p->max
         << "]";
      return Status::InvalidArgument(os.str());
    }
    e.*(p->field) = value;
  }
  if (name == "coulomb_friction" && e.friction_F_s_N < e.friction_F_c_N)
    return Status::InvalidArgument("params[F_s]: the static friction must be at least the kinetic F_c");

  *effects = e;
  return Status::Ok();
}

namespace {

StatusOr<const EffectParamInfo*> FindEffectParam(std::string_view dotted) {
  // Messages through a stream: GCC 12's -Wrestrict misfires on "'" + std::string + "..." here.
  std::ostringstream os;
  os << "'" << dotted << "': ";
  const std::size_t dot = dotted.find('.');
  if (dot == std::string_view::npos) {
    os << "not an effect parameter (effect.parameter)";
    return Status::InvalidArgument(os.str());
  }
  const std::string_view effect = dotted.substr(0, dot), field = dotted.substr(dot + 1);
  for (const auto& e : EffectCatalog()) {
    if (e.name != effect) continue;
    for (const auto& q : e.params)
      if (q.name == field) return &q;
    os << "unknown parameter of " << effect << " (known: ";
    for (std::size_t k = 0; k < e.params.size(); ++k) os << (k ? ", " : "") << e.params[k].name;
    os << ")";
    return Status::InvalidArgument(os.str());
  }
  os << "unknown effect '" << effect << "'";
  return Status::InvalidArgument(os.str());
}

}  // namespace

StatusOr<double> GetEffectParam(const Effects& e, std::string_view dotted) {
  auto p = FindEffectParam(dotted);
  if (!p.ok()) return p.status();
  return e.*((*p)->field);
}

Status SetEffectParam(Effects* e, std::string_view dotted, double value) {
  auto p = FindEffectParam(dotted);
  if (!p.ok()) return p.status();
  if (!std::isfinite(value) || value < (*p)->min || value > (*p)->max) {
    std::ostringstream os;
    os << dotted << " = " << value << " " << (*p)->unit << " is outside [" << (*p)->min << ", " << (*p)->max << "]";
    return Status::InvalidArgument(os.str());
  }
  e->*((*p)->field) = value;
  if (dotted == "coulomb_friction.F_c" && e->friction_F_s_N < value) e->friction_F_s_N = value;
  return Status::Ok();
}

}  // namespace vb::model
