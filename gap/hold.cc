#include "gap/hold.h"

#include <fmt/format.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <utility>

namespace vb::gap {

namespace {

constexpr int kMinRises = 4;    // the pull-in and at least three PWM rises
constexpr int kMinPeriods = 3;  // whole periods in the second half: a scatter to take a sigma from
// Samples before the gate rises that make a baseline: fewer leave the offset (the health check records 500, so
// that the offset's own error, noise / sqrt(500), is a few hundredths of a percent of a 0.1 A hold).
constexpr std::size_t kMinBaselineSamples = 20;
// A drop-out tail: the gate low after the PWM for at least this many of its periods (the health check's 50 ms is
// 50 at 1 kHz). Shorter stretches are the PWM's own off-times, or a run cut at its end.
constexpr double kMinDropOutPeriods = 4.0;
// The largest share of the voltage's integral the settling correction may carry (MeasureHold). The correction's
// error is that share times L's relative error. L's sigma is propagated into R's; what it does not hold is L's
// bias: the ripple's L is the coil's at the PWM frequency, where eddy currents lower it, while the settling is
// slow, and a ripple of a few ADC steps misreads it (a 0.2 s coil measured 8 ms after its pull-in, its ripple
// half a step, read 238 ohm for 10). At a share of 0.5, an L 10 % off moves R by 5 %. The trade: a slow coil
// whose L the ripple does read right is refused too (the tests' valve at a tenth of its R, 40 ms of hold: share
// above 0.5, and it would have read 1.2956 ohm for 1.3); the refusal asks for a longer hold. The health check's
// 0.1 s gives a coil of L/R 50 ms a share of about 0.23.
constexpr double kMaxSettlingShare = 0.5;

std::vector<std::size_t> Rises(const RunData& r) {
  std::vector<std::size_t> rises;
  for (std::size_t k = 1; k < r.gate.size(); ++k)
    if (r.gate[k] != 0 && r.gate[k - 1] == 0) rises.push_back(k);
  return rises;
}

// Where the PWM ends: the gate's last fall when the gate stays low after it for at least kMinDropOutPeriods of
// the PWM's periods (a drop-out tail), else the run's end.
std::size_t PwmEnd(const RunData& r, const std::vector<std::size_t>& rises) {
  const std::size_t n = r.gate.size();
  if (rises.size() < 3) return n;
  const double period = static_cast<double>(rises.back() - rises[1]) / static_cast<double>(rises.size() - 2);
  std::size_t f = n;
  while (f > 0 && r.gate[f - 1] == 0) --f;
  if (f == 0 || f <= rises.back()) return n;
  return static_cast<double>(n - f) >= kMinDropOutPeriods * period ? f : n;
}

// The scope's baseline offset: the mean of the samples before the gate first rises (0 with fewer than
// kMinBaselineSamples), and its sigma. NaN samples make it NaN.
std::pair<double, double> Baseline(const RunData& r, std::size_t first_rise) {
  if (first_rise < kMinBaselineSamples) return {0.0, 0.0};
  double sum = 0.0, ss = 0.0;
  for (std::size_t k = 0; k < first_rise; ++k) sum += r.i_A[k];
  const double mean = sum / static_cast<double>(first_rise);
  for (std::size_t k = 0; k < first_rise; ++k) ss += (r.i_A[k] - mean) * (r.i_A[k] - mean);
  return {mean, std::sqrt(ss / static_cast<double>(first_rise - 1) / static_cast<double>(first_rise))};
}

double Mean(const std::vector<double>& v) {
  double s = 0.0;
  for (double x : v) s += x;
  return s / static_cast<double>(v.size());
}

// The sample standard deviation of the mean of v.
double SigmaOfMean(const std::vector<double>& v) {
  const double m = Mean(v);
  double ss = 0.0;
  for (double x : v) ss += (x - m) * (x - m);
  return std::sqrt(ss / static_cast<double>(v.size() - 1) / static_cast<double>(v.size()));
}

}  // namespace

bool IsHoldRun(const RunData& r) {
  if (r.kind != RunKind::kWaveform || r.gate.empty() || r.gate.front() != 0) return false;
  return static_cast<int>(Rises(r).size()) >= kMinRises;
}

std::vector<RunData> TakeHoldRuns(Dataset* ds) {
  std::vector<RunData> holds;
  std::vector<RunData> rest;
  for (auto& r : ds->runs) (IsHoldRun(r) ? holds : rest).push_back(std::move(r));
  ds->runs = std::move(rest);
  return holds;
}

StatusOr<HoldMeasurement> MeasureHold(const RunData& r, const model::DriverParams& driver) {
  const std::string where = fmt::format("hold run {}", r.id);
  if (!IsHoldRun(r))
    return Status::InvalidArgument(fmt::format("{}: not a hold (the gate must rise once, then switch)", where));
  const std::size_t n = r.i_A.size();
  const double dt = r.sample_period_s;
  if (r.gate.size() != n || !(dt > 0.0))
    return Status::InvalidArgument(fmt::format("{}: gate and i_A differ in length", where));
  const auto rises = Rises(r);
  // The second half, from the first PWM rise to the PWM's end: the first half lets the current settle.
  const std::size_t mid = (rises[1] + PwmEnd(r, rises) - 1) / 2;
  std::vector<std::size_t> edges;
  for (std::size_t j = 1; j < rises.size(); ++j)
    if (rises[j] >= mid) edges.push_back(rises[j]);
  const int periods = static_cast<int>(edges.size()) - 1;
  if (periods < kMinPeriods)
    return Status::InvalidArgument(fmt::format(
        "{}: {} whole PWM period(s) in the hold's second half; at least {} are needed (a longer hold or a higher "
        "PWM frequency)",
        where, std::max(periods, 0), kMinPeriods));
  HoldMeasurement m;
  m.periods = periods;
  m.voltage_measured = r.v_coil_V.size() == n;
  const std::size_t a = edges.front(), b = edges.back();
  for (std::size_t k = a; k <= b; ++k)
    if (!std::isfinite(r.i_A[k])) return Status::InvalidArgument(fmt::format("{}: i_A[{}] is not a number", where, k));
  // A clipped capture (the scope's range, a saturated amplifier) holds the current at one value while the gate
  // switches; the mean over a period is then not the coil's, and R comes out as wrong as the clip is deep (a
  // 24 V, 20 ohm hold clipped at 0.3 A read 30.7 ohm with a sigma of 0.1 %). Noise never repeats one value for
  // long, a clip does: a run of equal samples at the window's highest (or lowest) value that spans a gate edge
  // and lasts more than a quarter of a period is refused. The same rule refuses a noise-free ripple of under
  // about two steps of the ADC, whose mean the steps bias as much and whose L cannot be read.
  {
    const double period_samples = static_cast<double>(b - a) / periods;
    double hi = -HUGE_VAL, lo = HUGE_VAL;
    for (std::size_t k = a; k <= b; ++k) hi = std::max(hi, r.i_A[k]), lo = std::min(lo, r.i_A[k]);
    for (const double level : {hi, lo}) {
      std::size_t k = a;
      while (k <= b) {
        if (r.i_A[k] != level) {
          ++k;
          continue;
        }
        std::size_t e = k;
        bool both_gates = false;
        while (e + 1 <= b && r.i_A[e + 1] == level) both_gates = both_gates || (r.gate[e + 1] != r.gate[k]), ++e;
        if (both_gates && static_cast<double>(e - k + 1) > period_samples / 4.0)
          return Status::InvalidArgument(fmt::format(
              "{}: the current stays at {:.5g} A for {} samples ({:.2g} of a PWM period) while the gate switches: "
              "clipped by the scope's range (or a ripple below its step); record the hold within range",
              where, level, e - k + 1, static_cast<double>(e - k + 1) / period_samples));
        k = e + 1;
      }
    }
  }
  // The baseline: a scope's offset shifts the mean current and so R (on an independent plant's draw, -0.78 mA
  // on a 75 mA hold read R 1.05 % high).
  std::vector<double> i(r.i_A.begin(), r.i_A.end());
  const auto [offset_A, offset_sigma_A] = Baseline(r, rises[0]);
  if (!std::isfinite(offset_A)) return Status::InvalidArgument(fmt::format("{}: a baseline sample is not a number", where));
  m.offset_A = offset_A;
  for (double& x : i) x -= m.offset_A;
  std::vector<double> v(n);
  if (m.voltage_measured) {
    for (std::size_t k = a; k <= b; ++k) {
      if (!std::isfinite(r.v_coil_V[k]))
        return Status::InvalidArgument(fmt::format("{}: v_coil_V[{}] is not a number", where, k));
      v[k] = r.v_coil_V[k];
    }
  } else {
    if (driver.kind != model::DriverKind::kLowSideFlyback)
      return Status::InvalidArgument(fmt::format(
          "{}: the coil voltage is not recorded (no v_coil_V) and the driver ({}) does not say it from the gate; "
          "record v_coil_V to measure the hold",
          where, model::DriverKindName(driver.kind)));
    if (!(r.supply_V > 0.0)) return Status::InvalidArgument(fmt::format("{}: supply_V is not given", where));
    // The flyback diode conducts only while the current flows: a hold whose current stops in a period is not
    // a resistance and an inductance in series with a known voltage.
    double lowest = HUGE_VAL, highest = -HUGE_VAL;
    for (std::size_t k = a; k <= b; ++k) lowest = std::min(lowest, i[k]), highest = std::max(highest, i[k]);
    if (!(lowest > 0.05 * highest))
      return Status::InvalidArgument(fmt::format(
          "{}: the current falls to {:.4g} A of its {:.4g} A peak within a period (it stops, or nearly: "
          "discontinuous conduction), so the diode's voltage is not known; record v_coil_V or raise the duty",
          where, lowest, highest));
    for (std::size_t k = a; k <= b; ++k) v[k] = r.gate[k] != 0 ? r.supply_V : -driver.diode_drop_V;
  }

  // Per period [e0, e1): the gate holds each sample's value until the next (valve-runs/2), so the voltage's
  // integral is a left sum; the current is smooth, a trapezoid.
  std::vector<double> volt_s(periods), amp_s(periods), mean_A(periods);
  double on = 0.0;
  for (int p = 0; p < periods; ++p) {
    const std::size_t e0 = edges[p], e1 = edges[p + 1];
    double sv = 0.0, si = 0.0;
    for (std::size_t k = e0; k < e1; ++k) {
      sv += v[k];
      si += 0.5 * (i[k] + i[k + 1]);
      on += r.gate[k] != 0;
    }
    volt_s[p] = sv * dt, amp_s[p] = si * dt;
    mean_A[p] = amp_s[p] / (static_cast<double>(e1 - e0) * dt);
  }
  const double window_s = static_cast<double>(b - a) * dt;
  m.duty = on / static_cast<double>(b - a);
  m.frequency_Hz = periods / window_s;
  double amp_total = 0.0;
  for (double x : amp_s) amp_total += x;
  m.hold_current_A = amp_total / window_s;
  if (!(m.hold_current_A > 0.0))
    return Status::InvalidArgument(
        fmt::format("{}: the hold's mean current is {:.4g} A (an open coil, or the "
                    "polarity inverted)",
                    where, m.hold_current_A));

  // A first R with the flux taken as periodic, then L from the periods' flux, then R again with what the hold
  // still settles by: over a period the flux changes by L times the change of the current at its rising edges,
  // and with the ripple's shape the same from one period to the next, the current at an edge moves as the mean
  // of the periods either side of it does: (mean[p + 1] - mean[p - 1]) / 2 (one-sided at the window's ends).
  std::vector<double> settle_A(periods, 0.0);
  for (int p = 0; p < periods; ++p) {
    const int lo = std::max(p - 1, 0), hi = std::min(p + 1, periods - 1);
    settle_A[p] = (mean_A[hi] - mean_A[lo]) / static_cast<double>(hi - lo);
  }
  double R = 0.0;
  {
    double sv = 0.0;
    for (double x : volt_s) sv += x;
    R = sv / amp_total;
  }
  // L: psi(t) = integral(v - R i) within each period, regressed on i with an intercept and a term in t (what R's
  // error and the settling add to psi is nearly linear in t over one period). Noise in i attenuates the slope by
  // var(noise) / var(i's part the regression uses); it is corrected with the noise of the current's second
  // differences (gap/dataset.h SecondDifferenceSigma).
  const double noise_A = [&] {
    std::vector<double> w(i.begin() + static_cast<std::ptrdiff_t>(a), i.begin() + static_cast<std::ptrdiff_t>(b) + 1);
    return SecondDifferenceSigma(w);
  }();
  std::vector<double> L_p(periods);
  for (int p = 0; p < periods; ++p) {
    const std::size_t e0 = edges[p], e1 = edges[p + 1], len = e1 - e0 + 1;
    Eigen::MatrixXd X(len, 3);
    Eigen::VectorXd y(len);
    double psi = 0.0;
    for (std::size_t k = e0; k <= e1; ++k) {
      if (k > e0) psi += (v[k - 1] - R * 0.5 * (i[k - 1] + i[k])) * dt;
      const std::size_t row = k - e0;
      X(row, 0) = 1.0, X(row, 1) = i[k], X(row, 2) = static_cast<double>(row) * dt;
      y(row) = psi;
    }
    const Eigen::Vector3d beta = X.colPivHouseholderQr().solve(y);
    // The variance of i left after the intercept and t: what the slope is taken from.
    Eigen::MatrixXd Z(len, 2);
    Z.col(0) = X.col(0), Z.col(1) = X.col(2);
    const Eigen::VectorXd fit = Z * Z.colPivHouseholderQr().solve(X.col(1));
    const double var_i = (X.col(1) - fit).squaredNorm() / static_cast<double>(len);
    const double attenuation = var_i > 0.0 ? std::max(1.0 - noise_A * noise_A / var_i, 0.5) : 1.0;
    L_p[p] = beta(1) / attenuation;
  }
  m.L_H = Mean(L_p);
  m.L_sigma_H = SigmaOfMean(L_p);
  // R's sigma from six blocks of periods: within a block the settling terms telescope to its two ends (the
  // periods' means either side), as they do over the window, where a single period carries its own two-sided
  // difference. Measured on 40 draws of the tests' hold (gap_hold_test, 2 mA of noise): the periods' scatter
  // states 2.0x the values' true spread for a hold of 0.1 s (50 periods measured) and 1.6x for 0.04 s (19);
  // six blocks state 1.16x and 1.36x. Conservative, and the tracker takes the nights' scatter where it is larger.
  const int per_block = std::max(1, periods / 6);
  const int blocks = periods / per_block;
  std::vector<double> R_b(blocks);
  double sv = 0.0;
  for (int blk = 0; blk < blocks; ++blk) {
    double bv = 0.0, bi = 0.0;
    const int end = blk == blocks - 1 ? periods : (blk + 1) * per_block;  // the last block takes the remainder
    for (int p = blk * per_block; p < end; ++p) bv += volt_s[p] - m.L_H * settle_A[p], bi += amp_s[p];
    R_b[blk] = bv / bi;
    sv += bv;
  }
  m.R_ohm = sv / amp_total;
  // What the settling correction carries: L times the current's change over the window, against the voltage's
  // integral. Its error is L's error times that share, so L's sigma enters R's; and beyond half the hold is more
  // correction than measurement, a share L's regression cannot bear (a 0.2 s coil measured 8 ms after its
  // pull-in read 238 ohm for 10, with a sigma of 6 %): refused.
  double settle_total_A = 0.0, volt_total = 0.0;
  for (int p = 0; p < periods; ++p) settle_total_A += settle_A[p], volt_total += volt_s[p];
  const double settling_share = std::abs(m.L_H * settle_total_A) / std::abs(volt_total);
  if (!(settling_share <= kMaxSettlingShare))
    return Status::InvalidArgument(fmt::format(
        "{}: the current is still settling in the hold's second half (its mean moves by {:.3g} A, {:.0f} % of "
        "the coil voltage's integral); a longer hold (several L/R) or a lower inductance's coil",
        where, std::abs(mean_A.back() - mean_A.front()), 100.0 * settling_share));
  // The offset's error shifts the mean current: R's relative error is its share of the hold current.
  m.R_sigma_ohm = std::hypot(std::hypot(SigmaOfMean(R_b), m.R_ohm * offset_sigma_A / m.hold_current_A),
                             m.L_sigma_H * settle_total_A / amp_total);
  if (!std::isfinite(m.R_ohm) || !std::isfinite(m.L_H) || !(m.R_ohm > 0.0))
    return Status::InvalidArgument(
        fmt::format("{}: the hold gives R = {:.4g} ohm and L = {:.4g} H, not a coil's", where, m.R_ohm, m.L_H));
  return m;
}

StatusOr<DropOutMeasurement> MeasureDropOut(const RunData& r) {
  const std::string where = fmt::format("hold run {}", r.id);
  if (!IsHoldRun(r) || r.i_A.size() != r.gate.size() || !(r.sample_period_s > 0.0))
    return Status::InvalidArgument(fmt::format("{}: not a hold (the gate must rise once, then switch)", where));
  const auto rises = Rises(r);
  const std::size_t n = r.i_A.size(), f = PwmEnd(r, rises);
  if (f == n)
    return Status::InvalidArgument(fmt::format(
        "{}: no drop-out tail (the gate low for at least {:g} PWM periods after the hold)", where, kMinDropOutPeriods));
  const auto [offset_A, offset_sigma_A] = Baseline(r, rises[0]);
  (void)offset_sigma_A;
  if (!std::isfinite(offset_A))
    return Status::InvalidArgument(fmt::format("{}: a baseline sample is not a number", where));
  std::vector<double> tail(r.i_A.begin() + static_cast<std::ptrdiff_t>(f), r.i_A.end());
  for (std::size_t k = 0; k < tail.size(); ++k) {
    if (!std::isfinite(tail[k]))
      return Status::InvalidArgument(fmt::format("{}: i_A[{}] is not a number", where, f + k));
    tail[k] -= offset_A;
  }
  // A centred moving mean over w samples (w a 400th of the tail: the release dip lasts the plunger's flight,
  // hundreds of samples at the health check's rate) and the noise left on it.
  const std::size_t len = tail.size(), w = std::max<std::size_t>(1, len / 400), half = w / 2;
  std::vector<double> smooth(len);
  for (std::size_t k = 0; k < len; ++k) {
    const std::size_t lo = k >= half ? k - half : 0, hi = std::min(len - 1, k + half);
    double sum = 0.0;
    for (std::size_t j = lo; j <= hi; ++j) sum += tail[j];
    smooth[k] = sum / static_cast<double>(hi - lo + 1);
  }
  const double sigma_A = SecondDifferenceSigma(tail) / std::sqrt(static_cast<double>(w));
  // The dip: the lowest current so far, once the current has risen 4 sigma above it (a chance of 3e-5 a sample
  // for noise on a flat bottom; on a decay, where each sample lies below the last, less). Not near zero, where
  // the current's end is flat and noise alone makes minima (ten sigma above zero and 2 % of the current at the
  // gate's fall), and not within the gate edge's first 50 us or two smoothing widths (a switching spike).
  const std::size_t start =
      std::max<std::size_t>(2 * w, static_cast<std::size_t>(std::ceil(50e-6 / r.sample_period_s)));
  if (start + 2 >= len)
    return Status::InvalidArgument(fmt::format("{}: the drop-out tail is too short to measure", where));
  const double at_fall_A = smooth[std::min(start, len - 1)];
  const double floor_A = std::max(10.0 * sigma_A, 0.02 * at_fall_A);
  std::size_t k_min = start;
  for (std::size_t k = start; k < len; ++k) {
    if (smooth[k] < smooth[k_min]) k_min = k;
    if (smooth[k_min] <= floor_A) break;
    if (smooth[k] > smooth[k_min] + 4.0 * sigma_A) {
      DropOutMeasurement d;
      double peak = smooth[k_min];
      for (std::size_t j = k_min; j < len; ++j) peak = std::max(peak, smooth[j]);
      d.rise_A = peak - smooth[k_min];
      // The bottom from every sample near it, not the smoothed series' lowest point (which noise biases low and
      // scatters by the smoothing's sigma): a parabola by least squares over the samples within a fifth of the
      // rise (and at least 3 sigma) of the lowest, its vertex the drop-out current. Its sigma from the fit's
      // covariance and the samples' noise; the lowest point where the fit is not a valley within its samples.
      const double within = std::max(3.0 * sigma_A, 0.2 * d.rise_A);
      std::size_t lo = k_min, hi = k_min;
      while (lo > start && smooth[lo - 1] <= smooth[k_min] + within) --lo;
      while (hi + 1 < len && smooth[hi + 1] <= smooth[k_min] + within) ++hi;
      d.i_A = smooth[k_min];
      d.sigma_A = sigma_A;
      d.t_s = static_cast<double>(k_min) * r.sample_period_s;
      if (hi - lo + 1 >= 5) {
        const std::size_t m = hi - lo + 1;
        const double scale = static_cast<double>(m) / 2.0;  // the abscissa in units of half the region
        Eigen::MatrixXd X(m, 3);
        Eigen::VectorXd y(m);
        for (std::size_t j = 0; j < m; ++j) {
          const double u = (static_cast<double>(lo + j) - static_cast<double>(k_min)) / scale;
          X(j, 0) = 1.0, X(j, 1) = u, X(j, 2) = u * u;
          y(j) = tail[lo + j];
        }
        const Eigen::Vector3d beta = X.colPivHouseholderQr().solve(y);
        const double a = beta(2), b = beta(1), c = beta(0);
        const double u0 = a > 0.0 ? -b / (2.0 * a) : NAN;
        const double lo_u = (static_cast<double>(lo) - static_cast<double>(k_min)) / scale,
                     hi_u = (static_cast<double>(hi) - static_cast<double>(k_min)) / scale;
        if (std::isfinite(u0) && u0 >= lo_u && u0 <= hi_u) {
          const double noise2 = (y - X * beta).squaredNorm() / static_cast<double>(m - 3);
          const Eigen::Matrix3d cov = noise2 * (X.transpose() * X).inverse();
          const Eigen::Vector3d g(1.0, -b / (2.0 * a), b * b / (4.0 * a * a));
          d.i_A = c - b * b / (4.0 * a);
          d.sigma_A = std::sqrt(std::max(g.dot(cov * g), 0.0));
          d.t_s = (static_cast<double>(k_min) + u0 * scale) * r.sample_period_s;
        }
      }
      if (!(d.sigma_A > 0.0)) d.sigma_A = sigma_A;
      return d;
    }
  }
  return Status::InvalidArgument(fmt::format(
      "{}: no release dip in the drop-out tail ({:.3g} s): the current fell from {:.4g} A to {:.4g} A without the "
      "plunger letting go (stuck at its stop, a tail too short for the coil's decay, or a decay too fast)",
      where, static_cast<double>(len) * r.sample_period_s, at_fall_A, smooth[k_min]));
}

std::vector<DeterminedValue> HoldValues(const std::vector<RunData>& holds, const model::DriverParams& driver,
                                        std::vector<std::string>* notes) {
  std::vector<DeterminedValue> out;
  double w_sum = 0.0, wr_sum = 0.0;
  const RunData* lowest = nullptr;
  HoldMeasurement at_lowest;
  bool measured_v = true;
  for (const auto& r : holds) {
    auto m = MeasureHold(r, driver);
    if (!m.ok()) {
      if (notes != nullptr) notes->push_back(m.status().message());
      continue;
    }
    measured_v = measured_v && m->voltage_measured;
    const double w = m->R_sigma_ohm > 0.0 ? 1.0 / (m->R_sigma_ohm * m->R_sigma_ohm) : 0.0;
    w_sum += w, wr_sum += w * m->R_ohm;
    if (lowest == nullptr || r.supply_V < lowest->supply_V) lowest = &r, at_lowest = *m;
  }
  // R and L from the runs measured (none: the drop-out may still be, it needs no voltage).
  if (lowest != nullptr && w_sum > 0.0) {
    DeterminedValue R;
    R.name = std::string("R_hold");
    R.unit = std::string("ohm");
    R.meaning = measured_v ? "the winding's resistance from the hold (mean coil voltage over mean current, plunger held)"
                           : "the resistance from the hold (the driver's voltage over the mean current, plunger held): "
                             "the winding and what lies between it and the supply while the gate is on";
    R.value = wr_sum / w_sum;
    R.sigma = R.sigma_white = 1.0 / std::sqrt(w_sum);
    out.push_back(R);
    DeterminedValue L;
    L.name = std::string("L_hold");
    L.unit = std::string("H");
    L.meaning = fmt::format(
        "the coil's inductance at the held stop and {:.3g} A (the flux's slope over the hold's "
        "ripple at {:.0f} Hz)",
        at_lowest.hold_current_A, at_lowest.frequency_Hz);
    L.value = at_lowest.L_H;
    L.sigma = L.sigma_white = at_lowest.L_sigma_H;
    if (std::isfinite(L.value) && L.value > 0.0 && std::isfinite(L.sigma) && L.sigma > 0.0) out.push_back(L);
  }
  // The drop-out, of every run with a tail (a run without one has not asked for it: no note).
  double wd_sum = 0.0, wdi_sum = 0.0;
  for (const auto& r : holds) {
    const auto rises = Rises(r);
    if (!IsHoldRun(r) || PwmEnd(r, rises) == r.gate.size()) continue;
    auto d = MeasureDropOut(r);
    if (!d.ok()) {
      if (notes != nullptr) notes->push_back(d.status().message());
      continue;
    }
    if (!(d->sigma_A > 0.0)) continue;
    const double w = 1.0 / (d->sigma_A * d->sigma_A);
    wd_sum += w, wdi_sum += w * d->i_A;
  }
  if (wd_sum > 0.0) {
    DeterminedValue D;
    D.name = std::string("i_dropout");
    D.unit = std::string("A");
    D.meaning = "the current at which the plunger leaves its stop as the held coil de-energises (the release dip): "
                "the spring's force at the stop against the pull per ampere squared";
    D.value = wdi_sum / wd_sum;
    D.sigma = D.sigma_white = 1.0 / std::sqrt(wd_sum);
    out.push_back(D);
  }
  return out;
}

}  // namespace vb::gap
