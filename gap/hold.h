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

// The drop-out at the hold's end (the classic release test): the gate falls and stays low, the current decays
// through the flyback diode, and the plunger leaves its stop when the pull, 1/2 i^2 dL/dx (seed 000 eq. 8),
// falls below the spring's force at the stop (and the pressure's, eq. 9-10). As the gap opens L falls and the
// flux linkage, continuous, pushes the current up: a dip, the mirror of the pull-in's. The current at the dip's
// bottom is the drop-out current: i^2 is the spring's force at the stop over the pull per ampere squared, with no
// model of the valve. A relaxing spring lowers it (by half the force's fraction), shorted turns raise it (the
// pull per ampere falls with the square of the turns), a more resistive winding lowers it by a tenth to a quarter
// of its own change (it sets how fast the current falls while the plunger starts to move, not where it lets go).
struct DropOutMeasurement {
  double i_A = NAN, sigma_A = NAN;  // the current at the dip's bottom (offset removed), and its 1-sigma
  double t_s = NAN;                 // from the gate's last fall to the dip's bottom
  double rise_A = NAN;              // how far the current rises after it (what makes it a release, not noise)
};

// Measures the drop-out of a hold run whose gate stays low after the PWM (at least kMinDropOutPeriods PWM periods
// long). InvalidArgument naming the run and the cause: no such tail, or no dip within it (a plunger that does
// not let go before the current dies: stuck, a tail too short, or a driver whose decay is too fast for it).
StatusOr<DropOutMeasurement> MeasureDropOut(const RunData& r);

// The tracked values of a session's hold runs: R_hold (inverse-variance mean over the runs), L_hold (of the
// run with the lowest supply: L depends on the hold current through the core's saturation, so runs at other
// supplies are not averaged) and, for runs with a drop-out tail, i_dropout (inverse-variance mean). A run that
// cannot be measured adds a note instead.
std::vector<DeterminedValue> HoldValues(const std::vector<RunData>& holds, const model::DriverParams& driver,
                                        std::vector<std::string>* notes);

}  // namespace vb::gap
