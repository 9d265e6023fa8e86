// Synthetic switch-on sessions of a moving valve, recorded the way a lab records an industrial valve (issue 25):
// a gate step after a short pre-trigger, the current through a scope that adds white noise to each sweep,
// averages several sweeps and resolves a fixed step. The truth is our own model (any parameters, any effects),
// simulated by the event-exact emulator (gap/replay.h); the tests make valves other than practice3's with it.
#pragma once

#include <string>
#include <vector>

#include "common/status.h"
#include "model/params.h"

namespace vb::gap {

struct SwitchOnRunPlan {
  std::string id;
  double supply_V = 12.0;
  double supply_pressure_Pa = 0.0;       // the true pressure the valve sees
  double declared_pressure_Pa = -1.0;    // what the manifest says (< 0: the true one)
  std::string split;                     // "fit", "holdout" or "" (not written)
};

struct ScopeChain {
  double noise_A = 1e-3;                 // white noise of one sweep
  int averaged = 8;                      // sweeps averaged into one trace
  double lsb_A = 1.0 / 480.0;            // the trace's resolution (the averaged value is rounded to it)
  double sample_period_s = 1e-5;         // 100 kHz
  double pre_trigger_s = 1e-4;           // the gate rises here
  double duration_s = 0.0101;            // the trace's length
  unsigned seed = 1;
  // A real scope's artefacts (issue 35: odd but legal captures), each off by default. Applied to the averaged
  // trace in this order, then the resolution: a baseline offset; a switching spike of spike_A decaying by half
  // per sample over spike_samples samples from the gate's edge (either sign); mains ripple; glitches (isolated
  // samples off by glitch_A, at random); clipping at +-clip_A; the polarity inverted; an open coil (the trace is
  // the chain's noise alone).
  double offset_A = 0.0;
  double spike_A = 0.0;
  int spike_samples = 0;
  double ripple_A = 0.0, ripple_Hz = 50.0;
  double glitch_A = 0.0;
  int glitches = 0;
  double clip_A = 0.0;                   // 0: no clipping
  bool inverted = false;
  bool open_coil = false;
};

// Simulates every run from rest with the gate stepping on at pre_trigger_s and writes `directory`/manifest.json
// (valve-runs/2, model `model_family`, the scope chain declared as sensor noise, averaging and step) and one
// CSV per run (t_s, gate, i_A). Runs start 2 s apart (the model's slow states carry over as on a bench).
Status WriteSwitchOnSession(const std::string& directory, const model::PlantParams& truth,
                            const std::vector<SwitchOnRunPlan>& runs, const ScopeChain& scope,
                            const std::string& device, const std::string& model_family = model::kDefaultPreset,
                            double t_start_s = 0.0);

}  // namespace vb::gap
