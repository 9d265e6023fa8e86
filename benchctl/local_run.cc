#include "benchctl/local_run.h"

#include <cstdio>
#include <memory>

#include "hw/emulated_bench.h"

namespace vb::benchctl {

StatusOr<std::vector<LocalRunResult>> RunLocal(const experiment::ExperimentSpec& spec, bool realtime,
                                               bool keep_traces) {
  auto points = experiment::ExpandSweep(spec);
  if (!points.ok()) return points.status();
  // Build everything first: a bad point fails the whole submission before anything runs.
  std::vector<experiment::Experiment> exps;
  for (size_t k = 0; k < points->size(); ++k) {
    auto e = experiment::BuildExperiment((*points)[k]);
    if (!e.ok()) return points->size() > 1 ? e.status().WithContext("run " + std::to_string(k)) : e.status();
    if (realtime) e->run.realtime = true;
    exps.push_back(std::move(e.value()));
  }
  std::vector<LocalRunResult> out;
  for (auto& e : exps) {
    hw::EmulatedBench bench(experiment::EmulatedBenchFor(e));
    LocalRunResult r;
    r.name = e.spec.name();
    for (const auto& tag : e.spec.tags()) {
      r.tags.push_back(tag);
      if (tag.rfind("sweep:", 0) == 0 || tag.rfind("repeat:", 0) == 0) r.name += " " + tag;
    }
    r.controller = std::string(e.controller->name());
    r.summary = experiment::Runner::Run(e, bench, &r.trace);
    if (!keep_traces) {
      r.trace = experiment::Trace{};
    }
    out.push_back(std::move(r));
  }
  return out;
}

Status WriteTraceCsv(const experiment::Trace& trace, const std::string& path) {
  std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(path.c_str(), "w"), &std::fclose);
  if (!f) return Status::Unavailable(path + ": cannot open for writing");
  const auto& names = experiment::Trace::ChannelNames();
  for (size_t c = 0; c < names.size(); ++c) std::fprintf(f.get(), "%s%s", c ? "," : "", names[c].c_str());
  std::fputc('\n', f.get());
  for (size_t k = 0; k < trace.size(); ++k) {
    std::fprintf(f.get(), "%.8f,%d,%.6g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.12g,%.12g,%.0f\n", trace.t_s[k],
                 trace.gate[k], trace.v_coil_V[k], trace.i_A[k], trace.x_m[k], trace.v_mps[k], trace.ref[k],
                 trace.x_avg_m[k], trace.flow_kg_per_s[k], trace.v2_int_V2s[k], trace.energy_int_J[k],
                 trace.switch_count[k]);
  }
  if (std::ferror(f.get())) return Status::DataLoss(path + ": write failed");
  return Status::Ok();
}

}  // namespace vb::benchctl
