// The hold of a nightly health check (issue 38, docs/track.md "The hold"): after the pull-in the gate switches at
// a fixed duty, and with the plunger held at its stop the coil is a resistance and an inductance:
//   v = R i + d psi / dt   (seed 000 eq. 5-7, model/plant.h's coil equation, with the plunger at rest: no motion,
//                           so no back EMF)
// Over whole PWM periods of a settled hold psi returns to itself, so  R = integral(v dt) / integral(i dt),  with
// no model of the magnetic circuit, the spring or the fluid: the winding alone, the one parameter of the valve a
// switch-on's fit can trade against others (a series resistance, a supply other than declared, shorted turns).
// Within each period the flux linkage psi(t) = integral(v - R i) dt follows the current's ripple; its slope in
// the current is the coil's inductance at the held stop and the hold current (L_hold): shorted turns lower it by
// the square of the turns left, a worn or open stop by the gap's change.
#pragma once

#include <string>
#include <vector>

#include "common/status.h"
#include "gap/dataset.h"
#include "gap/moving_valve.h"
#include "model/driver.h"

namespace vb::gap {

// A hold run: a waveform whose gate starts low, rises once for the pull-in and then switches (at least four
// rises in all). A switch-on run (one rise) is not one.
bool IsHoldRun(const RunData& r);

// Moves the dataset's hold runs out of it (in order) and returns them: the identification fits switch-ons only.
std::vector<RunData> TakeHoldRuns(Dataset* ds);

struct HoldMeasurement {
  double R_ohm = NAN, R_sigma_ohm = NAN;  // integral(v) / integral(i) over the settled periods, and its 1-sigma
  double L_H = NAN, L_sigma_H = NAN;      // psi's slope in i within a period (mean over periods), and its 1-sigma
  double hold_current_A = NAN;            // the mean current over the settled periods (offset removed)
  double offset_A = 0.0;                  // the baseline removed: the mean before the gate rises (0: too few)
  double duty = NAN, frequency_Hz = NAN;  // the gate's, measured over those periods
  int periods = 0;                        // whole PWM periods measured (the hold's second half)
  bool voltage_measured = false;          // v_coil_V recorded; else the driver's voltages (see MeasureHold)
};

// Measures a hold run's resistance and inductance over the whole PWM periods of its second half (the first half
// lets the current settle to its periodic state; what is left unsettled is corrected through L: the flux at the
// window's end minus its start, L (i_end - i_start)). The coil voltage is the recorded v_coil_V; without it, a
// low-side driver with a flyback diode puts the supply on the coil while the gate is high and minus the diode's
// drop while it is low (the current never stops in a hold), and R then includes any resistance between the
// supply and the coil (a connector, the switch) for the gate's on-time. A scope's baseline offset is removed:
// the mean of the samples before the gate rises (at least kMinBaselineSamples; the health check records 5 ms).
// Each sigma is measured from the periods' scatter (see hold.cc), the offset's added to R's. InvalidArgument
// naming the run and the cause when the run is not a measurable hold.
StatusOr<HoldMeasurement> MeasureHold(const RunData& r, const model::DriverParams& driver);

// The tracked values of a session's hold runs: R_hold (inverse-variance mean over the runs) and L_hold (of the
// run with the lowest supply: L depends on the hold current through the core's saturation, so runs at other
// supplies are not averaged). A run that cannot be measured adds a note instead.
std::vector<DeterminedValue> HoldValues(const std::vector<RunData>& holds, const model::DriverParams& driver,
                                        std::vector<std::string>* notes);

}  // namespace vb::gap
