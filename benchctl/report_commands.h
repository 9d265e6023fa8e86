// benchctl report (--batch B | --run R | --regress ID | --diagnosis FILE) --html FILE: one self-contained HTML
// file (docs/report.md). Runs and batches come from the local store (--local, or no server given) or the server.
#pragma once

#include <CLI/CLI.hpp>

#include <cstdint>
#include <string>

#include "benchctl/regress_commands.h"

namespace vb::benchctl {

class ReportCli {
 public:
  ReportCli(CLI::App* app, SharedOptions shared);
  bool parsed() const { return report_->parsed(); }
  int Run(const ClientFactory& make_client);

 private:
  SharedOptions shared_;
  CLI::App* report_ = nullptr;
  std::int64_t batch_ = 0, run_ = 0, regress_ = 0;
  std::string diagnosis_, html_, svg_dir_, png_dir_;
  int max_traces_ = 100;
  bool local_ = false;
};

}  // namespace vb::benchctl
