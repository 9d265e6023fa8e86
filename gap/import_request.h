// A loaded dataset as the service's ImportRuns request, written once for `benchctl import` and the web
// dashboard's import (docs/web.md). A template over the request type (valvebench::v1::ImportRunsRequest), so that
// gap/ needs no gRPC code.
#pragma once

#include <cmath>
#include <string>

#include "common/status.h"
#include "gap/dataset.h"

namespace vb::gap {

// Fills `req` with the dataset's runs under `name` (the batch becomes "import:<name>"). InvalidArgument naming
// the run for what the server does not store: runs other than waveform runs, runs with a held stroke.
template <class ImportRunsRequest>
Status FillImportRequest(const Dataset& ds, const std::string& name, ImportRunsRequest* req) {
  for (std::size_t k = 0; k < ds.runs.size(); ++k)
    if (ds.runs[k].kind != RunKind::kWaveform || std::isfinite(ds.runs[k].stroke_m))
      return Status::InvalidArgument(
          "import: runs[" + std::to_string(k) + "] '" + ds.runs[k].id + "' is a " +
          std::string(RunKindName(ds.runs[k].kind)) + (std::isfinite(ds.runs[k].stroke_m) ? " run with a held stroke" : " run") +
          "; the server stores waveform runs only: diagnose this dataset locally (benchctl diagnose DIR)");
  req->set_dataset(name);
  req->set_model(ds.model);
  req->set_description(ds.description);
  for (const auto& r : ds.runs) {
    auto* out = req->add_runs();
    out->set_id(r.id);
    out->set_supply_v(r.supply_V);
    out->set_supply_pressure_pa(r.supply_pressure_Pa);
    out->set_t_start_s(r.t_start_s);
    out->set_split(SplitName(r.split));
    out->set_sample_period_s(r.sample_period_s);
    for (auto g : r.gate) out->add_gate(g);
    for (double i : r.i_A) out->add_i_a(i);
    for (double x : r.x_m) out->add_x_m(x);
    for (double v : r.v_coil_V) out->add_v_coil_v(v);
  }
  return Status::Ok();
}

}  // namespace vb::gap
