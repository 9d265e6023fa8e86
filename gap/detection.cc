#include "gap/detection.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <thread>

#include "gap/diagnose.h"
#include "gap/predict.h"

namespace vb::gap {

namespace {

std::vector<double> Flatten(const Predicted& p) {
  std::vector<double> out;
  for (const auto& run : p.i_A) out.insert(out.end(), run.begin(), run.end());
  return out;
}

std::string UnitOf(const std::string& name) {
  const auto dot = name.find('.');
  if (dot == std::string::npos) return "";
  for (const auto& e : model::EffectCatalog()) {
    if (e.name != name.substr(0, dot)) continue;
    for (const auto& p : e.params)
      if (p.name == name.substr(dot + 1)) return std::string(p.unit);
  }
  return "";
}

}  // namespace

StatusOr<std::vector<DetectionLimit>> DetectionLimits(const Dataset& ds, const model::PlantParams& nominal,
                                                      const std::vector<Candidate>& candidates, double floor_A,
                                                      const AttributionOptions& options) {
  PredictOptions popt;
  popt.solver = options.solver;
  auto base = Predict(ds, nominal, popt);
  if (!base.ok()) return base.status().WithContext("detection limits: nominal");
  const std::vector<double> y0 = Flatten(*base);
  // What R alone would absorb: the direction of a 0.1 % change of R.
  model::PlantParams r_up = nominal;
  r_up.R_ohm *= 1.001;
  auto pr = Predict(ds, r_up, popt);
  if (!pr.ok()) return pr.status().WithContext("detection limits: R");
  std::vector<double> dR = Flatten(*pr);
  double dR2 = 0.0;
  for (std::size_t k = 0; k < dR.size(); ++k) {
    dR[k] -= y0[k];
    dR2 += dR[k] * dR[k];
  }
  const double threshold = std::sqrt(kSignificance * kSignificance - 1.0) * floor_A;

  std::vector<const Candidate*> todo;
  for (const auto& c : candidates)
    if (std::any_of(c.params.begin(), c.params.end(), [](const FreeParam& f) { return std::isfinite(f.absent); }))
      todo.push_back(&c);
  std::vector<DetectionLimit> out(todo.size());

  auto residual = [&](const Candidate& c, double s, std::map<std::string, double>* at) -> double {
    std::vector<double> values;
    for (const auto& f : c.params) {
      double v = f.name == "R" ? nominal.R_ohm : f.initial;
      if (std::isfinite(f.absent)) {
        const double ua = std::clamp(Normalised(f, f.absent), 0.0, 1.0);
        const double far = ua < 0.5 ? 1.0 : 0.0;
        v = ValueAt(f, ua + s * (far - ua));
        (*at)[f.name] = v;
      }
      values.push_back(v);
    }
    auto plant = ApplyCandidate(nominal, c, values);
    if (!plant.ok()) return NAN;
    auto p = Predict(ds, *plant, popt);
    if (!p.ok()) return NAN;
    const std::vector<double> y = Flatten(*p);
    const bool r_free = std::any_of(c.params.begin(), c.params.end(), [](const FreeParam& f) { return f.name == "R"; });
    double dot = 0.0;
    for (std::size_t k = 0; k < y.size(); ++k) dot += (y[k] - y0[k]) * dR[k];
    const double a = r_free && dR2 > 0.0 ? dot / dR2 : 0.0;
    double e2 = 0.0;
    for (std::size_t k = 0; k < y.size(); ++k) {
      const double e = (y[k] - y0[k]) - a * dR[k];
      e2 += e * e;
    }
    return y.empty() ? 0.0 : std::sqrt(e2 / static_cast<double>(y.size()));
  };

  std::atomic<std::size_t> next{0};
  auto worker = [&]() {
    for (std::size_t i = next++; i < todo.size(); i = next++) {
      const Candidate& c = *todo[i];
      DetectionLimit& lim = out[i];
      lim.effect = c.name;
      std::map<std::string, double> at;
      const double r_far = residual(c, 1.0, &at);
      if (!(r_far >= threshold)) {  // also NaN: the range's end could not be simulated
        lim.detectable = false;
        lim.params = at;
        lim.residual_at_limit_A = std::isfinite(r_far) ? r_far : 0.0;
      } else if (std::map<std::string, double> weakest; residual(c, 0.0, &weakest) >= threshold) {
        lim.detectable = true;
        lim.below_range = true;
        lim.params = weakest;
        lim.residual_at_limit_A = residual(c, 0.0, &weakest);
      } else {
        double lo = 0.0, hi = 1.0, r_hi = r_far;
        for (int it = 0; it < 14; ++it) {
          const double mid = 0.5 * (lo + hi);
          std::map<std::string, double> m;
          const double r = residual(c, mid, &m);
          if (r >= threshold) {
            hi = mid;
            r_hi = r;
          } else {
            lo = mid;
          }
        }
        at.clear();
        residual(c, hi, &at);
        lim.detectable = true;
        lim.params = at;
        lim.residual_at_limit_A = r_hi;
      }
      for (const auto& [name, v] : lim.params) lim.units[name] = UnitOf(name);
    }
  };
  std::vector<std::thread> pool;
  const int threads = std::clamp(options.threads, 1, static_cast<int>(std::max<std::size_t>(todo.size(), 1)));
  for (int t = 0; t < threads; ++t) pool.emplace_back(worker);
  for (auto& t : pool) t.join();
  return out;
}

}  // namespace vb::gap
