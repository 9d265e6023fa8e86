// Plant parameters: a validated, data-driven struct. Presets come from the papers; any field can be
// overridden by name (the names are the papers' symbols, values in SI units), and Validate() reports the
// field and the problem. Nothing here is a constant buried in code: the presets are data tables.
#pragma once

#include <limits>
#include <string>
#include <string_view>
#include <vector>

#include "common/status.h"
#include "model/effects.h"

namespace vb::model {

// How the coil inductance depends on the spool position. Every law gives L(x) and dL/dx; the force is the
// co-energy derivative F_m = 1/2 i^2 dL/dx, and the coil obeys v = R i + L(x) di/dt + i dL/dx xdot.
enum class InductanceLaw {
  // Seed 000 (Taghizadeh 2009) eq. (4): L(x) = K / (l_c + 2 mu_r (x_t - x)), K = N^2 A_e mu_r mu0.
  // With it, 1/2 i^2 dL/dx equals eq. (8) F_m = L^2 i^2 / (N^2 A_e mu0), and the coil law equals eq. (7).
  kReluctance,
  // Seed 002 (Lunge 2013) eq. (5): L(x) = L' x / (x + a), L' = pi d mu0 a N^2 / g; force eq. (6).
  kLimitedTravel,
  // Seed 003 (Kang): a plain RL coil, L constant, no moving part.
  kConstant,
};

struct PlantParams {
  std::string preset;  // the preset these values started from
  InductanceLaw law = InductanceLaw::kReluctance;
  bool has_moving_part = true;

  // Electrical
  double R_ohm = 13.0;          // coil resistance
  double N_turns = 1250.0;      // coil turns
  // kReluctance (seed 000 eq. 2-4)
  double A_e_m2 = 0.8e-4;       // effective cross-section of the flux path
  double l_c_m = 0.115;         // length of the magnetic circuit in the core
  double mu_r = 120.0;          // relative permeability of the core
  double x_t_m = 0.4e-3;        // total air gap (travelling + holding) with the spool at x = 0
  // kLimitedTravel (seed 002 eq. 5)
  double d_m = 0.008;           // guide tube diameter
  double g_m = 0.0012;          // guide tube thickness (the air gap)
  double a_m = 0.006;           // length of the iron strips the flux passes
  // kConstant (seed 003)
  double L_H = 0.33;            // inductance

  // Mechanical (seed 000 eq. 9-11; seed 002 eq. 7)
  double m_kg = 0.027;          // moving mass (spool / plunger)
  double k_N_per_m = 1.0e4;     // return spring stiffness
  double delta_m = 1.1e-3;      // spring pre-tension (pre-compression) at x = 0
  double b_N_s_per_m = 0.2;     // viscous damping
  double g_r_m_per_s2 = 0.0;    // gravity along the travel, opposing the magnetic pull (seed 002 eq. 7)
  double x_min_m = 0.0;         // lower end stop (valve closed)
  double x_max_m = 0.33e-3;     // upper end stop (valve fully open)
  // Pressure force, seed 000 eq. (10): F_prs = (A1 - A2) P_sup (A3 = A4, so P_out has no effect).
  double A1_m2 = 26.57e-6;
  double A2_m2 = 35.25e-6;

  // Flow, seed 000 eq. (12): dm/dt = C_d C_A xbar P_sup/sqrt(T) * (choked or subsonic factor). The paper gives
  // no values for C_d, C_A, T: they scale the flow but not its shape (the static map in % of max).
  double C_d = 0.8;                // discharge coefficient
  double C_A_m = 2.4e-3;           // orifice area per unit spool travel, A = C_A xbar [m^2/m]: 0.8 mm^2 open
  double T_supply_K = 293.15;      // supply temperature
  double P_out_Pa = 101325.0;      // absolute downstream pressure (exhaust to atmosphere)
  double P_atm_Pa = 101325.0;      // supply_pressure_Pa is gauge; absolute = gauge + P_atm

  // A coil whose plunger a fixture holds at a fixed stroke (a bench that measures L against stroke): the
  // inductance at each stroke as measured or identified, strokes increasing, linear in between. Empty: the
  // inductance law gives L(stroke). Used by AtState.
  std::vector<double> inductance_stroke_m, inductance_L_H;

  // Named additions to the nominal model (model/effects.h); none by default.
  Effects effects;

  // Derived: K = N^2 A_e mu_r mu0 (kReluctance), L' = pi d mu0 a N^2 / g (kLimitedTravel).
  double K_reluctance_H_m() const;
  double L_prime_H() const;
};

// The default model: seed 000's pneumatic valve (Taghizadeh 2009), what a spec, a dataset or an import that
// names no model means. One constant, so the default is said once.
inline constexpr char kDefaultPreset[] = "taghizadeh2009";

// The preset names the papers give us.
std::vector<std::string> PresetNames();
StatusOr<PlantParams> Preset(std::string_view name);

// One overridable parameter: its name (the paper's symbol), unit, meaning and physical bounds.
struct ParamInfo {
  std::string_view name;
  std::string_view unit;
  std::string_view meaning;
  double PlantParams::*field;
  double min;   // inclusive physical bounds; Validate() rejects values outside
  double max;
};
const std::vector<ParamInfo>& ParamTable();
const ParamInfo* FindParam(std::string_view name);
// The SI unit of a parameter by any name a fit reports: a plant parameter ("R"), an effect's
// ("supply_resistance.R_s"), or a fit's reparametrisation "effect.X_excess" (a difference of two X, e.g.
// coulomb_friction.F_s_excess = F_s - F_c: X's unit). Empty when the name is unknown.
std::string ParamUnit(std::string_view name);

// Sets a parameter by name; InvalidArgument naming the parameter if unknown or out of bounds.
Status SetParam(PlantParams* p, std::string_view name, double value);
StatusOr<double> GetParam(const PlantParams& p, std::string_view name);

// Checks every field against its bounds and the cross-field constraints (x_min < x_max < x_t, ...).
Status Validate(const PlantParams& p);

// The state of the device in one run, where a run records it (NaN: not recorded).
struct HeldState {
  double stroke_m = std::numeric_limits<double>::quiet_NaN();  // the plunger held at this stroke (no motion)
  double coil_C = std::numeric_limits<double>::quiet_NaN();    // the winding's temperature
};
// The plant as it is in that state. A held plunger makes a constant-inductance coil with no moving part,
// L = the inductance table at the stroke (linear interpolation; a stroke outside the table is an error) or,
// without a table, the inductance law at x = stroke. A winding temperature scales R when the
// resistance_temperature effect is on: R (1 + alpha (T - T_ref)). Errors name the field (stroke_m, coil_C).
StatusOr<PlantParams> AtState(const PlantParams& p, const HeldState& s);

}  // namespace vb::model
