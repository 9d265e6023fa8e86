// The opening dip of a switch-on current, one finder for the diagnosis's landmarks and a moving valve's marks.
// While the plunger moves, L(x) rises and the motional back-EMF (seed 000 eq. 7) makes the coil current fall
// until the plunger arrives; the dip's time is the pull-in, its depth how much motion the current saw.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace vb::gap {

struct OpeningDip {
  bool found = false;     // false: the current never dipped by more than the threshold (no pull-in seen)
  std::size_t low_k = 0;  // the sample at the dip's bottom
  double peak_A = NAN;    // the peak before it
  double low_A = NAN;     // the bottom
};

// On a smoothed trace between gate-on (on) and gate-off (off): a peak, then a fall of more than threshold_A,
// then a rise of more than threshold_A (a fall that never recovers is not a dip: a decaying current is not one).
inline OpeningDip FindOpeningDip(const std::vector<double>& smoothed, std::size_t on, std::size_t off,
                                 double threshold_A) {
  OpeningDip d;
  double peak = -INFINITY, low = 0.0;
  std::size_t low_k = 0;
  bool falling = false;
  for (std::size_t k = on; k < off && k < smoothed.size(); ++k) {
    const double s = smoothed[k];
    if (!falling) {
      peak = std::max(peak, s);
      if (s < peak - threshold_A) {
        falling = true;
        low = s;
        low_k = k;
      }
    } else if (s < low) {
      low = s;
      low_k = k;
    } else if (s > low + threshold_A) {
      d.found = true;
      d.low_k = low_k;
      d.peak_A = peak;
      d.low_A = low;
      return d;
    }
  }
  return d;
}

}  // namespace vb::gap
