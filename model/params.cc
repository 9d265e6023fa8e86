#include "model/params.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include "model/plant.h"

namespace vb::model {
namespace {

constexpr double kMu0 = 4.0e-7 * M_PI;  // vacuum permeability [H/m], as the nominal contract fixes it
constexpr double kInf = std::numeric_limits<double>::infinity();

// Seed 000, Tables 1-2 (identified values) and the nominal contract of issue 2.
PlantParams Taghizadeh2009() {
  PlantParams p;
  p.preset = kDefaultPreset;
  p.law = InductanceLaw::kReluctance;
  p.has_moving_part = true;
  p.R_ohm = 13.0;         // Table 2 identified (15 measured cold)
  p.N_turns = 1250.0;     // Table 1
  p.A_e_m2 = 0.8e-4;      // Table 2 identified 0.8 cm^2
  p.l_c_m = 0.115;        // Table 2 identified 11.5 cm
  p.mu_r = 120.0;         // Table 2 identified
  p.x_t_m = 0.4e-3;       // Table 2 identified 0.4 mm
  p.m_kg = 0.027;         // Table 1: 27 g
  p.k_N_per_m = 1.0e4;    // Table 1
  p.delta_m = 1.1e-3;     // Table 2
  p.b_N_s_per_m = 0.2;    // Table 2 identified
  p.g_r_m_per_s2 = 0.0;   // not in the model
  p.x_min_m = 0.0;
  p.x_max_m = 0.33e-3;    // Table 2 identified 0.33 mm
  p.A1_m2 = 26.57e-6;     // Table 1
  p.A2_m2 = 35.25e-6;     // Table 1
  return p;
}

// Seed 002, Table I. Decisions (docs/model.md): b = 1.25 N s/m, not the printed 4.25, because the paper's own
// SMC design matrix (A22 = -b/M = -357, with A21 = -K/M and b2 = 1/M matching Table I exactly) was built
// with it; the travel is limited by stops at 0.2 mm (L(0) = 0 makes eq. 10 singular) and 3 mm.
PlantParams Lunge2013() {
  PlantParams p;
  p.preset = "lunge2013";
  p.law = InductanceLaw::kLimitedTravel;
  p.has_moving_part = true;
  p.R_ohm = 5540.0;
  p.N_turns = 3750.0;
  p.d_m = 0.008;
  p.g_m = 0.0012;
  p.a_m = 0.006;
  p.m_kg = 0.0035;
  p.k_N_per_m = 90.5;
  p.delta_m = 0.0;        // eq. (7) has no pre-tension
  p.b_N_s_per_m = 1.25;   // see above
  p.g_r_m_per_s2 = 9.8;
  p.x_min_m = 0.2e-3;
  p.x_max_m = 3.0e-3;
  p.A1_m2 = 0.0;          // no pressure force in seed 002
  p.A2_m2 = 0.0;
  p.C_A_m = 0.0;
  return p;
}

// Seed 003 section III: HydraForce TS98-T34 coil, 28.5 ohm and 330 mH at 24 V and 20 degC.
PlantParams Ts98Coil() {
  PlantParams p;
  p.preset = "ts98_coil";
  p.law = InductanceLaw::kConstant;
  p.has_moving_part = false;
  p.R_ohm = 28.5;
  p.L_H = 0.33;
  p.x_min_m = 0.0;
  p.x_max_m = 0.0;
  p.A1_m2 = 0.0;
  p.A2_m2 = 0.0;
  p.C_A_m = 0.0;
  return p;
}

}  // namespace

double PlantParams::K_reluctance_H_m() const { return N_turns * N_turns * A_e_m2 * mu_r * kMu0; }
double PlantParams::L_prime_H() const { return M_PI * d_m * kMu0 * a_m * N_turns * N_turns / g_m; }

std::vector<std::string> PresetNames() { return {kDefaultPreset, "lunge2013", "ts98_coil"}; }

StatusOr<PlantParams> Preset(std::string_view name) {
  if (name == kDefaultPreset) return Taghizadeh2009();
  if (name == "lunge2013") return Lunge2013();
  if (name == "ts98_coil") return Ts98Coil();
  std::string known;
  for (const auto& n : PresetNames()) known += (known.empty() ? "" : ", ") + n;
  return Status::InvalidArgument("unknown model preset '" + std::string(name) + "' (known: " + known + ")");
}

const std::vector<ParamInfo>& ParamTable() {
  static const std::vector<ParamInfo> table = {
      {"R", "ohm", "coil resistance", &PlantParams::R_ohm, 1e-3, 1e6},
      {"N", "turns", "coil turns", &PlantParams::N_turns, 1.0, 1e6},
      {"A_e", "m^2", "effective flux-path cross-section", &PlantParams::A_e_m2, 1e-9, 1e-1},
      {"l_c", "m", "magnetic path length in the core", &PlantParams::l_c_m, 1e-5, 10.0},
      {"mu_r", "1", "relative permeability of the core", &PlantParams::mu_r, 1.0, 1e6},
      {"x_t", "m", "total air gap at x = 0", &PlantParams::x_t_m, 1e-7, 0.1},
      {"d", "m", "guide tube diameter (lunge2013)", &PlantParams::d_m, 1e-5, 1.0},
      {"g", "m", "guide tube thickness / gap (lunge2013)", &PlantParams::g_m, 1e-6, 0.1},
      {"a", "m", "iron strip length (lunge2013)", &PlantParams::a_m, 1e-6, 1.0},
      {"L", "H", "constant inductance (ts98_coil)", &PlantParams::L_H, 1e-6, 100.0},
      {"m", "kg", "moving mass", &PlantParams::m_kg, 1e-6, 10.0},
      {"k", "N/m", "return spring stiffness", &PlantParams::k_N_per_m, 0.0, 1e8},
      {"delta", "m", "spring pre-tension at x = 0", &PlantParams::delta_m, -0.1, 0.1},
      {"b", "N s/m", "viscous damping", &PlantParams::b_N_s_per_m, 0.0, 1e4},
      {"g_r", "m/s^2", "gravity along the travel", &PlantParams::g_r_m_per_s2, 0.0, 100.0},
      {"x_min", "m", "lower end stop", &PlantParams::x_min_m, 0.0, 1.0},
      {"x_max", "m", "upper end stop", &PlantParams::x_max_m, 0.0, 1.0},
      {"A1", "m^2", "spool land area under P_sup (pushing open)", &PlantParams::A1_m2, 0.0, 1.0},
      {"A2", "m^2", "spool land area under P_sup (pushing closed)", &PlantParams::A2_m2, 0.0, 1.0},
      {"C_d", "1", "discharge coefficient", &PlantParams::C_d, 0.0, 1.0},
      {"C_A", "m^2/m", "orifice area per unit spool travel", &PlantParams::C_A_m, 0.0, 1e3},
      {"T_supply", "K", "supply air temperature", &PlantParams::T_supply_K, 1.0, 2000.0},
      {"P_out", "Pa", "absolute downstream pressure", &PlantParams::P_out_Pa, 0.0, 1e8},
      {"P_atm", "Pa", "atmospheric pressure (gauge -> absolute)", &PlantParams::P_atm_Pa, 0.0, 1e7},
  };
  return table;
}

std::string ParamUnit(std::string_view name) {
  if (const ParamInfo* p = FindParam(name)) return std::string(p->unit);
  const std::size_t dot = name.find('.');
  if (dot == std::string_view::npos) return "";
  const std::string_view effect = name.substr(0, dot);
  std::string_view field = name.substr(dot + 1);
  constexpr std::string_view kExcess = "_excess";
  if (field.size() > kExcess.size() && field.substr(field.size() - kExcess.size()) == kExcess)
    field.remove_suffix(kExcess.size());
  for (const auto& e : EffectCatalog())
    if (e.name == effect)
      for (const auto& q : e.params)
        if (q.name == field) return std::string(q.unit);
  return "";
}

const ParamInfo* FindParam(std::string_view name) {
  for (const auto& info : ParamTable())
    if (info.name == name) return &info;
  return nullptr;
}

static Status UnknownParam(std::string_view name) {
  std::string known;
  for (const auto& info : ParamTable()) known += (known.empty() ? "" : ", ") + std::string(info.name);
  return Status::InvalidArgument("unknown parameter '" + std::string(name) + "' (known: " + known + ")");
}

Status SetParam(PlantParams* p, std::string_view name, double value) {
  const ParamInfo* info = FindParam(name);
  if (info == nullptr) return UnknownParam(name);
  if (!std::isfinite(value) || value < info->min || value > info->max) {
    std::ostringstream os;
    os << "parameter " << name << " = " << value << " " << info->unit << " is outside [" << info->min << ", "
       << info->max << "]";
    return Status::InvalidArgument(os.str());
  }
  p->*(info->field) = value;
  return Status::Ok();
}

StatusOr<double> GetParam(const PlantParams& p, std::string_view name) {
  const ParamInfo* info = FindParam(name);
  if (info == nullptr) return UnknownParam(name);
  return p.*(info->field);
}

Status Validate(const PlantParams& p) {
  for (const auto& info : ParamTable()) {
    double v = p.*(info.field);
    if (!std::isfinite(v) || v < info.min || v > info.max) {
      std::ostringstream os;
      os << "parameter " << info.name << " = " << v << " " << info.unit << " is outside [" << info.min << ", "
         << info.max << "]";
      return Status::InvalidArgument(os.str());
    }
  }
  if (p.inductance_stroke_m.size() != p.inductance_L_H.size())
    return Status::InvalidArgument("inductance_table: stroke_m and L_H must have the same length");
  for (std::size_t k = 0; k < p.inductance_L_H.size(); ++k) {
    const double s = p.inductance_stroke_m[k], L = p.inductance_L_H[k];
    if (!std::isfinite(s) || (k > 0 && !(s > p.inductance_stroke_m[k - 1])))
      return Status::InvalidArgument("inductance_table.stroke_m[" + std::to_string(k) +
                                     "]: strokes must be finite and increasing");
    if (!std::isfinite(L) || !(L > 0.0) || L > 100.0)
      return Status::InvalidArgument("inductance_table.L_H[" + std::to_string(k) + "]: must be in (0, 100] H");
  }
  if (!p.has_moving_part) return Status::Ok();
  if (!(p.x_max_m > p.x_min_m))
    return Status::InvalidArgument("parameter x_max must be greater than x_min");
  switch (p.law) {
    case InductanceLaw::kReluctance:
      // The gap l_g = 2 (x_t - x) must stay positive over the travel (eq. 2).
      if (!(p.x_t_m > p.x_max_m))
        return Status::InvalidArgument("parameter x_t must be greater than x_max (the air gap must stay open)");
      break;
    case InductanceLaw::kLimitedTravel:
      if (!(p.x_min_m > 0.0))
        return Status::InvalidArgument("parameter x_min must be > 0 for lunge2013: L(0) = 0 makes eq. (10) singular");
      break;
    case InductanceLaw::kConstant:
      return Status::InvalidArgument("a constant-inductance coil has no moving part");
  }
  if (!(p.m_kg > 0.0)) return Status::InvalidArgument("parameter m must be > 0");
  return Status::Ok();
}

StatusOr<PlantParams> AtState(const PlantParams& p, const HeldState& s) {
  PlantParams out = p;
  if (std::isfinite(s.stroke_m)) {
    double L = 0.0;
    const auto& xs = p.inductance_stroke_m;
    if (!xs.empty()) {
      const double lo = xs.front(), hi = xs.back(), tol = 1e-9 + 1e-6 * std::abs(hi - lo);
      if (s.stroke_m < lo - tol || s.stroke_m > hi + tol) {
        std::ostringstream os;
        os << "stroke_m: " << s.stroke_m << " m is outside the model's inductance table [" << lo << ", " << hi << "] m";
        return Status::InvalidArgument(os.str());
      }
      const auto it = std::upper_bound(xs.begin(), xs.end(), s.stroke_m);
      const std::size_t k = it == xs.begin() ? 0 : std::min<std::size_t>(it - xs.begin(), xs.size()) - 1;
      if (k + 1 >= xs.size()) {
        L = p.inductance_L_H[k];
      } else {
        const double f = std::clamp((s.stroke_m - xs[k]) / (xs[k + 1] - xs[k]), 0.0, 1.0);
        L = p.inductance_L_H[k] + f * (p.inductance_L_H[k + 1] - p.inductance_L_H[k]);
      }
    } else if (p.law == InductanceLaw::kConstant) {
      L = p.L_H;  // a plain coil: the stroke changes nothing
    } else {
      if (p.has_moving_part && (s.stroke_m < p.x_min_m || s.stroke_m > p.x_max_m)) {
        std::ostringstream os;
        os << "stroke_m: " << s.stroke_m << " m is outside the travel [" << p.x_min_m << ", " << p.x_max_m << "] m";
        return Status::InvalidArgument(os.str());
      }
      L = Plant(p).L_H(s.stroke_m);
    }
    out.law = InductanceLaw::kConstant;
    out.has_moving_part = false;
    out.L_H = L;
    out.x_min_m = out.x_max_m = 0.0;
    out.A1_m2 = out.A2_m2 = out.C_A_m = 0.0;
    out.inductance_stroke_m.clear();
    out.inductance_L_H.clear();
  }
  if (p.effects.temperature && std::isfinite(s.coil_C)) {
    const double f = 1.0 + p.effects.temperature_alpha_per_K * (s.coil_C - p.effects.temperature_ref_C);
    if (!(f > 0.0)) {
      std::ostringstream os;
      os << "coil_C: " << s.coil_C << " C makes the winding resistance non-positive";
      return Status::InvalidArgument(os.str());
    }
    out.R_ohm = p.R_ohm * f;
  }
  return out;
}

}  // namespace vb::model
