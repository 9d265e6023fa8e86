// Event location inside one integration step (docs/model.md, "Integration: exact in time" and "Structure").
//
// An event function g(t) is > 0 before its event and <= 0 on or past it (a stop reached, the current at zero,
// a force that lifts the spool). Given g at both ends of a step [a, b], LocateEvent says whether the event
// happens in the step and where:
//   * g(b) > 0: no event in the step (kNone);
//   * g(a) > 0 >= g(b): a crossing, solved by Boost.Math's TOMS 748 bracketing solver (Alefeld, Potra, Shi,
//     ACM TOMS 21 (1995), algorithm 748) to time_tol_s; the answer is the bracket's upper end, the earliest
//     instant found with g <= 0, so the state there is on or just past the surface, never before it;
//   * g(a) <= 0 (the step starts on the surface: just lifted, released, rebounded): probe instants close to a,
//     then across the step, for one where g has become > 0, and solve from there; if g never becomes > 0 but
//     g(b) is clearly negative (< -on_surface_g), the event is at a itself (kAtStart, a vanishing rebound);
//     otherwise nothing crossed (the state sat on the surface, e.g. a spool at rest with zero net force).
//
// g is evaluated only inside [a, b]. A g that is NaN counts as "on or past the event" (not > 0), as the
// simulator always treated it; the watchdog (model/simulator.h) then stops the run on the state itself.
// Allocation-free, no exceptions (the solver's error policy is "ignore"): callable on the real-time path.
#pragma once

#include <cmath>
#include <cstdint>
#include <utility>

#include <boost/math/policies/policy.hpp>
#include <boost/math/tools/toms748_solve.hpp>

namespace vb::model {

struct EventLocatorOptions {
  double time_tol_s = 1e-14;           // the bracket around a crossing is narrowed to this width
  std::uintmax_t max_evaluations = 200;  // g evaluations allowed for one bracketed solve
  // A step that starts on the surface and ends below -on_surface_g without ever being measurably off the
  // surface is an event at the start. The surface functions are O(1) (positions in units of travel, currents
  // in A, forces in N), so 1e-9 is far below any real pass (a missed micro-rebound is ~1e-5 of the travel) and
  // far above round-off.
  double on_surface_g = 1e-9;
};

enum class EventFound : std::uint8_t {
  kNone,      // no event in the step
  kAtStart,   // the event is at the step's start
  kCrossing,  // g crosses from > 0 to <= 0 inside the step
};

struct EventHit {
  EventFound found = EventFound::kNone;
  double t_s = 0.0;                // the event's instant (kAtStart, kCrossing)
  std::uintmax_t evaluations = 0;  // g evaluations spent by LocateEvent (probes and solve)
  bool converged = true;           // kCrossing: the bracket narrowed to time_tol_s within max_evaluations
};

namespace event_locator_detail {

// Where a step that starts on the surface is probed: close to the start first (a short rebound can be over
// long before the step's end), then across the step.
inline constexpr double kProbe[] = {1e-9,     1e-7,     1e-5,      1e-3,      1.0 / 64,  1.0 / 16,  2.0 / 16,
                                    3.0 / 16, 4.0 / 16, 6.0 / 16, 8.0 / 16, 10.0 / 16, 12.0 / 16, 14.0 / 16};

using NoThrowPolicy = boost::math::policies::policy<
    boost::math::policies::domain_error<boost::math::policies::ignore_error>,
    boost::math::policies::evaluation_error<boost::math::policies::ignore_error>>;

}  // namespace event_locator_detail

// The bracketed solve alone: g(lo) = g_lo > 0 >= g(hi) = g_hi, lo < hi. Returns the upper end of the final
// bracket (g <= 0 there), which is hi itself when the bracket is already within time_tol_s.
template <typename G>
EventHit SolveEventBracket(G&& g, double lo, double g_lo, double hi, double g_hi, const EventLocatorOptions& opt) {
  EventHit hit;
  hit.found = EventFound::kCrossing;
  hit.t_s = hi;
  if (!(hi - lo > opt.time_tol_s)) return hit;
  // NaN is "not > 0": the solver needs a number with that sign.
  auto f = [&](double t) {
    const double v = g(t);
    return v > 0.0 || v <= 0.0 ? v : -1.0;
  };
  const double f_hi = g_hi <= 0.0 ? g_hi : -1.0;
  auto tol = [&opt](double a, double b) { return b - a <= opt.time_tol_s; };
  std::uintmax_t budget = opt.max_evaluations;
  const std::pair<double, double> r = boost::math::tools::toms748_solve(
      f, lo, hi, g_lo, f_hi, tol, budget, event_locator_detail::NoThrowPolicy());
  hit.evaluations = budget;
  hit.converged = r.second - r.first <= opt.time_tol_s;
  // TOMS 748 keeps g(first) > 0 and g(second) <= 0 (an exact zero closes the bracket on it).
  if (std::isfinite(r.second) && r.second > lo && r.second <= hi) hit.t_s = r.second;
  return hit;
}

// The event in the step [a, b] with g(a) = g_a and g(b) = g_b already known (see the top of this file).
template <typename G>
EventHit LocateEvent(G&& g, double a, double g_a, double b, double g_b, const EventLocatorOptions& opt) {
  EventHit hit;
  if (g_b > 0.0) return hit;
  double lo = a, g_lo = g_a;
  if (!(g_a > 0.0)) {
    bool found = false;
    for (double frac : event_locator_detail::kProbe) {
      const double tj = a + (b - a) * frac;
      if (!(tj > a)) continue;
      const double gj = g(tj);
      ++hit.evaluations;
      if (gj > 0.0) {
        lo = tj;
        g_lo = gj;
        found = true;
        break;
      }
    }
    if (!found) {
      // Never measurably off the surface: an event at the start only if it is clearly past it at the end.
      if (g_b < -opt.on_surface_g) {
        hit.found = EventFound::kAtStart;
        hit.t_s = a;
      }
      return hit;
    }
  }
  const std::uintmax_t probes = hit.evaluations;
  hit = SolveEventBracket(g, lo, g_lo, b, g_b, opt);
  hit.evaluations += probes;
  return hit;
}

}  // namespace vb::model
