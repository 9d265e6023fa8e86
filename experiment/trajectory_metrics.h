// Metrics from the run's exact trajectory (docs/metrics.md, "Metrics from the run, not from its recording").
//
// A bench that can hand over its trajectory piece by piece (the emulator: hw::Bench::set_trajectory_sink) gets
// its tracking metrics, ripple and means integrated on the pieces themselves instead of on the recorded
// samples, so they do not depend on recording.rate_Hz. Each piece is smooth between two events (gate edges,
// end-stop contacts, control ticks, the reference's steps, which are ticks: experiment/runner.h), so:
//   * integrals (of e^2, |e|, i, x) use 5-point Gauss-Legendre quadrature on the piece, exact for polynomials
//     of degree 9: the dense output of the moving-spool pieces is a polynomial of degree 4 in t, so e^2 on it
//     is integrated exactly; on the closed-form pieces (an exponential over a piece much shorter than L/R) the
//     quadrature error is below 1e-12 relative. |e| is split at its zeros first (located on the piece to
//     1e-15 s), so its kink costs nothing;
//   * extremes (max |e|, max y, min and max i) take the piece's ends and nodes; an interior maximum is refined
//     by golden-section search between its neighbouring nodes (to 4e-9 of their spacing). On the closed-form
//     pieces at a constant reference the exponential is monotone and the extremes are the ends;
//   * the settling instant is the last crossing of the band, located on the piece.
// Lock- and allocation-free: it runs inside the control loop.
#pragma once

#include <limits>

#include "experiment/metrics.h"
#include "experiment/reference.h"
#include "hw/bench.h"

namespace vb::experiment {

class TrajectoryMetrics final : public hw::TrajectorySink {
 public:
  // reference: the run's reference (the controlled variable's), or null / no reference: no tracking metrics.
  // final_ref: the reference at the window's end (the settling band, as MetricsAccumulator).
  // flow_per_m: eq. (12)'s mass flow per metre of opening (experiment/trace.h's Recorder), NaN for none.
  TrajectoryMetrics(ControlledVariable cv, const ReferenceProfile* reference, double start_s, double end_s,
                    double final_ref, double flow_per_m);
  void OnPiece(double t0_s, double t1_s, const hw::TrajectoryPiece& piece) override;

  bool empty() const { return !(covered_s_ > 0.0); }
  double covered_s() const { return covered_s_; }
  // Overwrites the metrics that integrate or extremise over time (rmse, iae, max_abs_error, overshoot,
  // settling_time_s, mean_current_A, mean_position_m/_pct, mean_flow_kg_per_s, ripple_pp_A/_mid_A) and the
  // driver losses that depend on the mean current, keeping the applicability rules of MetricsAccumulator.
  // x_max_m: the upper stop (mean_position_pct).
  void ApplyTo(Metrics* m, double x_max_m, const DriverLossInputs& driver) const;

 private:
  static constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
  double RefAt(double t, double a, double b) const;

  ControlledVariable cv_;
  const ReferenceProfile* ref_;
  double w0_, w1_, hint_ref_, band_, flow_per_m_;
  double covered_s_ = 0.0;
  bool started_ = false;
  double y0_ = kNaN, r_end_ = kNaN;
  double e2_ = 0.0, ea_ = 0.0, emax_ = 0.0, ymax_ = -std::numeric_limits<double>::infinity();
  double settle_t_ = kNaN;  // the last instant |e| > band (NaN: never)
  double i_int_ = 0.0, i_lo_ = std::numeric_limits<double>::infinity(),
         i_hi_ = -std::numeric_limits<double>::infinity();
  double x_int_ = 0.0, xpos_int_ = 0.0;
  bool has_x_ = true;
};

}  // namespace vb::experiment
