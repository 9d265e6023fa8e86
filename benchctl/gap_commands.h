// benchctl's sim-to-real gap commands (docs/gap.md, docs/real-data.md), declared and run here:
//   diagnose DATASET [--model M] [--reference DIR [--reference-params SPEC,...]] [--json [FILE]] [--emit-model FILE]
//   diagnose --runs ID,...                 (runs stored on a server)
//   identify DATASET --params SPEC,... [--fix NAME=V,...] [--global | --no-global] [--model M] [--out FILE] [--json]
//   convert READINGS.csv OUTDIR [--shunt-ohm R] [--amp-ref-ohm R] [--adc-lsb-V V] [--averaged N] [--model M]
//   import DATASET                         (store a dataset's waveform runs on a server)
// SPEC is NAME, NAME=LO:HI, NAME@START or NAME=LO:HI@START (gap/identify.h).
#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <string>
#include <vector>

#include "benchctl/regress_commands.h"

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

  SharedOptions shared_;
  CLI::App* diagnose_ = nullptr;
  CLI::App* identify_ = nullptr;
  CLI::App* convert_ = nullptr;
  CLI::App* import_ = nullptr;
  std::string dataset_dir_, model_, json_path_, emit_model_, reference_dir_, out_path_, csv_path_, out_dir_;
  std::vector<std::int64_t> runs_;
  std::vector<std::string> params_, reference_params_, fixed_;
  bool no_global_ = false, global_ = false;
  double shunt_ohm_ = 0.2, amp_ref_ohm_ = 1000.0, adc_lsb_V_ = 1e-3;
  int averaged_ = 16;
  std::string convert_model_ = "ts98_coil";
};

}  // namespace vb::benchctl
