#include "runs/admit.h"

#include <unistd.h>

#include <cmath>

#include "common/format.h"
#include "experiment/capabilities.h"
#include "model/params.h"

namespace vb::runs {

namespace {

std::string LawName(const experiment::ExperimentSpec& spec) {
  const auto* f = spec.controller().GetDescriptor()->FindFieldByNumber(spec.controller().law_case());
  return f != nullptr ? f->name() : "";
}

// Step 4: the bench a run goes to (its class and requested name), or why none can take it.
StatusOr<const BenchSetup*> Match(const experiment::RunPoint& p, const experiment::Experiment& e,
                                  const std::vector<BenchSetup>& benches) {
  const std::string cls = experiment::BenchClassOf(p.spec);
  const std::string& wanted = p.spec.bench().name();
  const BenchSetup* match = nullptr;
  std::string available, refusals;
  for (const auto& b : benches) {
    available += (available.empty() ? "" : ", ") + b.name + " (" + b.bench_class + ")";
    if (b.plant_from_spec) {
      if (match == nullptr) match = &b;
      continue;
    }
    if (b.bench_class != cls) continue;
    if (!wanted.empty() && wanted != b.name) continue;
    if (Status why = experiment::CheckCapabilities(e, b.caps); !why.ok()) {
      refusals += "; " + b.name + ": " + why.message();
      continue;
    }
    if (match == nullptr) match = &b;
  }
  if (match != nullptr) return match;
  return Status::FailedPrecondition("bench: no configured bench can run it (needs " + cls +
                                    (wanted.empty() ? "" : " named " + wanted) + " at " +
                                    FormatNumber(e.run.supply_V) + " V; configured: " + available + ")" + refusals);
}

}  // namespace

double LocalTraceBudgetBytes() {
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGE_SIZE);
  if (pages <= 0 || page <= 0) return 1e9;
  return 0.25 * static_cast<double>(pages) * static_cast<double>(page);
}

StatusOr<Admitted> Admit(const Submission& submission, const Policy& policy) {
  const Limits& lim = policy.limits;
  const auto& specs = submission.specs;
  if (specs.empty()) return Status::InvalidArgument("specs: at least one spec is needed");
  if (!submission.keys.empty() && submission.keys.size() != specs.size())
    return Status::InvalidArgument("keys: " + std::to_string(submission.keys.size()) + " keys for " +
                                   std::to_string(specs.size()) + " specs (give none, or one per spec)");
  Admitted out;
  out.submitter = submission.submitter;
  out.batch_name = submission.batch_name;
  out.batch_json = submission.batch_json;
  if (out.batch_json.empty() && specs.size() == 1) out.batch_json = experiment::SpecToJson(specs[0], false);
  for (size_t s = 0; s < specs.size(); ++s) {
    const std::string where = specs.size() > 1 ? "specs[" + std::to_string(s) + "]" : "spec";
    // 1. Size.
    if (specs[s].ByteSizeLong() > lim.max_spec_bytes)
      return Status::ResourceExhausted(where + ": " + std::to_string(specs[s].ByteSizeLong()) +
                                       " bytes exceed the server limit of " + std::to_string(lim.max_spec_bytes));
    // 2. Expansion.
    auto points = experiment::ExpandRuns(specs[s], lim.max_runs_per_submission);
    if (!points.ok()) return points.status();
    if (!submission.keys.empty()) {
      const RunKey& key = submission.keys[s];
      if (points->size() != 1)
        return Status::InvalidArgument(where + ": a spec with a key must be a single run, it expands to " +
                                       std::to_string(points->size()));
      if (key.name.empty()) return Status::InvalidArgument("keys[" + std::to_string(s) + "].name: must not be empty");
      (*points)[0].key = key;
    }
    for (size_t k = 0; k < points->size(); ++k) {
      const experiment::RunPoint& p = (*points)[k];
      const std::string run_where =
          points->size() > 1 ? "run " + std::to_string(k) + " (" + p.key.DisplayName() + ")" : "";
      auto ctxt = [&](const Status& st) { return run_where.empty() ? st : st.WithContext(run_where); };
      // 3. Every field, and the limits on what it asks for.
      auto e = experiment::BuildExperiment(p.spec);
      if (!e.ok()) return ctxt(e.status());
      if (e->duration_s > lim.max_duration_s)
        return ctxt(Status::ResourceExhausted("duration_s: " + FormatNumber(e->duration_s) +
                                              " s exceeds the server limit of " + FormatNumber(lim.max_duration_s) + " s"));
      if (e->run.sample_rate_Hz > lim.max_record_rate_Hz)
        return ctxt(Status::ResourceExhausted("recording.rate_Hz: " + FormatNumber(e->run.sample_rate_Hz) +
                                              " Hz exceeds the server limit of " + FormatNumber(lim.max_record_rate_Hz) +
                                              " Hz"));
      // The trace's memory, computed in double (no overflow): samples as the Runner reserves them.
      const double samples = e->run.sample_rate_Hz > 0.0 ? std::floor(e->duration_s * e->run.sample_rate_Hz) + 2.0 : 0.0;
      const double bytes = samples * static_cast<double>(experiment::Trace::kBytesPerSample);
      out.trace_bytes_raw += samples * static_cast<double>(experiment::Trace::ChannelNames().size() * sizeof(double));
      if (bytes > lim.max_trace_bytes_per_run)
        return ctxt(Status::ResourceExhausted(
            "recording: the trace would take " + FormatNumber(std::round(bytes / 1e6)) + " MB (" +
            FormatNumber(samples) + " samples at " + FormatNumber(e->run.sample_rate_Hz) + " Hz over " +
            FormatNumber(e->duration_s) + " s), over the per-run budget of " +
            FormatNumber(std::round(lim.max_trace_bytes_per_run / 1e6)) +
            " MB; lower recording.rate_Hz or duration_s"));
      // 4. A bench.
      auto bench = Match(p, *e, policy.benches);
      if (!bench.ok()) return ctxt(bench.status());
      db::RunRecord r;
      r.key = p.key;
      r.controller = LawName(p.spec);
      r.bench_kind = (*bench)->bench_class;
      r.bench_name = (*bench)->plant_from_spec ? "" : p.spec.bench().name();
      r.spec_json = experiment::SpecToJson(p.spec, false);
      r.submitter = submission.submitter;
      r.priority = p.spec.priority();
      r.requeue_on_interrupt = !p.spec.never_requeue();
      r.tags.assign(p.spec.tags().begin(), p.spec.tags().end());
      out.runs.push_back(std::move(r));
      if (out.runs.size() > lim.max_runs_per_submission)
        return Status::ResourceExhausted("submission expands to more than " +
                                         std::to_string(lim.max_runs_per_submission) + " runs");
    }
  }
  return out;
}

StatusOr<Queued> Enqueue(db::Store* store, Admitted admitted, const Policy& policy) {
  const std::uint64_t limit = policy.limits.max_queued_runs_per_user;
  if (limit != std::numeric_limits<std::uint64_t>::max()) {
    auto queued = store->CountQueued(admitted.submitter);
    if (!queued.ok()) return queued.status();
    if (static_cast<std::uint64_t>(*queued) + admitted.runs.size() > limit)
      return Status::ResourceExhausted("user " + admitted.submitter + " has " + std::to_string(*queued) +
                                       " queued runs; " + std::to_string(admitted.runs.size()) +
                                       " more would exceed the limit of " + std::to_string(limit));
  }
  if (const double budget = policy.limits.max_disk_bytes_per_user; std::isfinite(budget)) {
    auto used = store->StoredTraceBytes(admitted.submitter);
    if (!used.ok()) return used.status();
    const double after = static_cast<double>(*used) + admitted.trace_bytes_raw;
    if (after > budget)
      return Status::ResourceExhausted(
          "limits.max_disk_MB_per_user: user " + admitted.submitter + "'s stored traces take " +
          FormatNumber(std::round(static_cast<double>(*used) / 1e6)) + " MB and these runs may add up to " +
          FormatNumber(std::round(admitted.trace_bytes_raw / 1e6)) + " MB (uncompressed), over the per-user budget of " +
          FormatNumber(std::round(budget / 1e6)) + " MB; prune old runs (benchctl prune) or lower recording.rate_Hz "
          "or duration_s");
  }
  Queued out;
  auto batch = store->SubmitBatch(admitted.submitter, admitted.batch_name, admitted.batch_json,
                                  std::move(admitted.runs), &out.run_ids);
  if (!batch.ok()) return batch.status();
  out.batch_id = *batch;
  return out;
}

}  // namespace vb::runs
