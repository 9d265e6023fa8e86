// benchctl's sim-to-real gap commands (docs/gap.md, docs/real-data.md), declared and run here:
//   diagnose DATASET [--model M] [--reference DIR [--reference-params SPEC,...]] [--json] [--json-out FILE]
//            [--model-out FILE]
//   diagnose --runs ID,...                 (stored runs: the server's, or the local store's)
//   identify DATASET --params SPEC,... [--fix NAME=V,...] [--global | --no-global] [--model M] [--model-out FILE]
//            [--json]
//   convert READINGS.csv OUTDIR [--shunt-ohm R] [--amp-ref-ohm R] [--adc-lsb-V V] [--averaged N] [--model M]
//   import DATASET                         (store a dataset's waveform runs on a server)
//   track SESSION_DIR... [--model M] [--limit NAME=VALUE,...] [--arl0 SESSIONS] [--reference N] [--json]
//                                          (a valve tracked night by night, gap/track.h; exit 1 when flagged)
//   health [BENCH] [--model M] [--limit ...] [--arl0 NIGHTS] [--recompute] [--json]
//                                          (each bench's nightly health checks tracked, server/health_check.h)
// --json is JSON on stdout; files are --json-out and --model-out (the ModelSpec --model reads back). The old
// spellings --json FILE, --emit-model FILE and identify --out FILE still work, with a note on stderr.
// SPEC is NAME, NAME=LO:HI, NAME@START or NAME=LO:HI@START (gap/identify.h).
#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <cmath>
#include <string>
#include <vector>

#include "benchctl/regress_commands.h"
#include "gap/track.h"

namespace vb::benchctl {

class GapCli {
 public:
  GapCli(CLI::App* app, SharedOptions shared);
  bool parsed() const;
  int Run(const ClientFactory& make_client);

 private:
  int Diagnose(const ClientFactory& make_client);
  int Identify();
  int Convert();
  int Import(const ClientFactory& make_client);
  int Track();
  int Health(const ClientFactory& make_client);
  // The sessions of one valve tracked (their family, or --model) with --limit and --arl0.
  StatusOr<gap::Tracking> TrackValve(std::vector<gap::TrackSession>* sessions);
  // --model-out, or its deprecated spelling `old` (with a note on stderr).
  std::string ModelOut(const std::string& old, const char* old_flag) const;

  SharedOptions shared_;
  CLI::App* diagnose_ = nullptr;
  CLI::App* identify_ = nullptr;
  CLI::App* convert_ = nullptr;
  CLI::App* import_ = nullptr;
  CLI::App* track_ = nullptr;
  CLI::App* health_ = nullptr;
  std::string health_bench_;
  bool health_recompute_ = false;
  std::vector<std::string> track_dirs_, track_limits_;
  double track_arl0_ = 20000.0;
  int track_reference_ = gap::TrackOptions{}.min_reference;
  std::string dataset_dir_, model_, json_path_, json_out_, model_out_, suggest_out_, emit_model_, reference_dir_, out_path_,
      csv_path_, out_dir_;
  bool local_ = false;
  std::vector<std::int64_t> runs_, add_runs_;
  std::vector<std::string> params_, reference_params_, fixed_;
  bool no_global_ = false, global_ = false;
  double shunt_ohm_ = 0.2, amp_ref_ohm_ = 1000.0, adc_lsb_V_ = 1e-3;
  int averaged_ = 16;
  std::string convert_model_ = "ts98_coil";
  // convert of a scope capture (--channel given): gap/scope_csv.h
  std::string scope_channel_, scope_time_column_, scope_gate_channel_, scope_run_id_, scope_split_, scope_device_;
  double scope_probe_A_per_V_ = 0.0, scope_gate_threshold_V_ = NAN, scope_trigger_s_ = NAN, scope_supply_V_ = 0.0,
         scope_pressure_Pa_ = 0.0, scope_t_start_s_ = NAN, scope_noise_A_ = NAN, scope_lsb_A_ = NAN;
};

}  // namespace vb::benchctl
