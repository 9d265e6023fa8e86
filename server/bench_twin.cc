#include "server/bench_twin.h"

#include <algorithm>
#include <cmath>

#include <fmt/format.h>
#include <google/protobuf/util/message_differencer.h>
#include <spdlog/spdlog.h>

#include "experiment/runner.h"
#include "gap/hold.h"
#include "gap/stored_runs.h"
#include "hw/emulated_bench.h"
#include "model/params.h"
#include "runs/execute.h"
#include "runs/query.h"
#include "service/stored_run.h"

namespace vb::server {

StatusOr<gap::Dataset> BenchTwins::LoadCheck(std::int64_t batch_id, model::PlantParams* family,
                                              std::vector<gap::RunData>* holds) const {
  auto store = pool_->Acquire();
  if (!store.ok()) return store.status();
  auto listed = runs::ListBatch(store->get(), batch_id);
  if (!listed.ok()) return listed.status();
  std::vector<gap::StoredRun> stored;
  for (const auto& r : *listed) {
    if (r.status != db::RunStatus::kDone) continue;  // a run that failed tonight leaves the others
    auto s = LoadStoredRun(store->get(), r.id);
    if (!s.ok()) return s.status();
    stored.push_back(std::move(*s));
  }
  if (stored.empty()) return Status::FailedPrecondition(fmt::format("health check batch {}: no run finished", batch_id));
  auto ds = gap::DatasetOfStoredRuns(std::move(stored));
  if (!ds.ok()) return ds.status().WithContext(fmt::format("health check batch {}", batch_id));
  auto held = gap::TakeHoldRuns(&*ds);  // the identification fits the switch-ons
  if (holds != nullptr) *holds = std::move(held);
  if (ds->runs.empty())
    return Status::FailedPrecondition(fmt::format("health check batch {}: no switch-on run finished", batch_id));
  auto preset = model::Preset(ds->model.empty() ? "taghizadeh2009" : ds->model);
  if (!preset.ok()) return preset.status();
  *family = *preset;
  if (!gap::IsSwitchOnSession(*ds, *family))
    return Status::FailedPrecondition(fmt::format(
        "health check batch {}: not a switch-on session of a moving valve (model {})", batch_id, ds->model));
  return ds;
}

gap::SessionValues BenchTwins::Identify(const std::string& bench, const std::string& date, std::int64_t batch_id,
                                        const std::string& first_date, std::int64_t first_batch_id,
                                        const StoredAnchor* stored_anchor) {
  Twin& twin = twins_[bench];
  twin.tonight.reset();
  twin.anchor_moved_tonight = false;
  twin.flags.clear();  // tonight's tracking sets them again (SetFlags)
  gap::TrackOptions options;
  model::PlantParams family;
  std::vector<gap::RunData> holds;
  auto ds = LoadCheck(batch_id, &family, &holds);
  if (!ds.ok()) return gap::ValuesOfSession(date, gap::Dataset{}, StatusOr<gap::MovingIdentification>(ds.status()));
  if (!twin.anchor && first_batch_id != 0 && first_batch_id != batch_id) {
    // The anchor is the bench's first check (docs/track.md, step 1), identified again after a restart: from
    // scratch, or from where the anchor had moved (its stored values as a warm start, in that basin).
    model::PlantParams first_family;
    auto first = LoadCheck(first_batch_id, &first_family);
    if (first.ok()) {
      gap::MovingIdentification moved;
      if (stored_anchor != nullptr) {
        moved.fitted = stored_anchor->fitted;
        moved.effects = stored_anchor->effects;
      }
      auto id = gap::IdentifyForTracking(*first, first_family, stored_anchor ? &moved : nullptr, options);
      if (id.ok()) {
        twin.anchor = std::move(*id);
        twin.anchor_date = first_date;
        twin.anchor_batch = first_batch_id;
        twin.anchor_moves = stored_anchor ? stored_anchor->moves : 0;
      } else spdlog::warn("bench {}: its first health check (batch {}) not identified: {}", bench, first_batch_id,
                        id.status().message());
    }
  }
  auto id = gap::IdentifyForTracking(*ds, family, twin.anchor ? &*twin.anchor : nullptr, options);
  if (id.ok() && twin.anchor && twin.anchor_batch != 0 && twin.anchor_batch != batch_id &&
      twin.anchor_moves < kMaxAnchorMoves) {
    const double before_A = twin.anchor->fit_rmse_A;
    auto better = gap::BetterAnchor(
        *twin.anchor, *id, kAnchorRatioGain,
        [&](const gap::MovingIdentification* start) -> StatusOr<gap::MovingIdentification> {
          model::PlantParams first_family;
          auto first = LoadCheck(twin.anchor_batch, &first_family);
          if (!first.ok()) return first.status();
          return gap::IdentifyForTracking(*first, first_family, start, options);
        });
    if (better) {
      spdlog::info("bench {}: night {}: the anchor ({}) refitted from tonight's end, {:.3f} -> {:.3f} mA: tonight "
                   "and every earlier night identified again from there",
                   bench, date, twin.anchor_date, 1e3 * before_A, 1e3 * better->fit_rmse_A);
      twin.anchor = std::move(*better);
      ++twin.anchor_moves;
      twin.anchor_moved_tonight = true;
      twin.baseline.reset();  // identified from the old anchor
      twin.baseline_batch = 0;
      id = gap::IdentifyForTracking(*ds, family, &*twin.anchor, options);
    }
  }
  gap::SessionValues values = gap::ValuesOfSession(date, *ds, id);
  gap::AddHoldValues(&values, holds, ds->driver);
  if (id.ok()) {
    if (!twin.anchor) {
      twin.anchor = *id;
      twin.anchor_date = date;
      twin.anchor_batch = batch_id;
    }
    twin.tonight = std::move(*id);
    twin.tonight_date = date;
  }
  return values;
}

bool BenchTwins::AnchorMovedTonight(const std::string& bench) const {
  const auto t = twins_.find(bench);
  return t != twins_.end() && t->second.anchor_moved_tonight;
}

StoredAnchor BenchTwins::AnchorOf(const std::string& bench) const {
  StoredAnchor a;
  const auto t = twins_.find(bench);
  if (t == twins_.end() || !t->second.anchor) return a;
  a.anchor_night = t->second.anchor_date;
  a.fitted = t->second.anchor->fitted;
  a.effects = t->second.anchor->effects;
  a.moves = t->second.anchor_moves;
  return a;
}

std::vector<gap::SessionValues> BenchTwins::Reidentify(const std::string& bench, const std::string& date,
                                                       const std::map<std::string, StoredCheck>& checks) const {
  std::vector<gap::SessionValues> out;
  const auto t = twins_.find(bench);
  if (t == twins_.end() || !t->second.anchor) return out;
  for (const auto& [night, check] : checks) {
    if (night >= date || check.batch_id == 0) continue;
    model::PlantParams family;
    std::vector<gap::RunData> holds;
    auto ds = LoadCheck(check.batch_id, &family, &holds);
    auto id = ds.ok() ? gap::IdentifyForTracking(*ds, family, &*t->second.anchor, gap::TrackOptions{})
                      : StatusOr<gap::MovingIdentification>(ds.status());
    out.push_back(gap::ValuesOfSession(night, ds.ok() ? *ds : gap::Dataset{}, id));
    if (ds.ok()) gap::AddHoldValues(&out.back(), holds, ds->driver);
  }
  return out;
}

void BenchTwins::UseBaselineNight(const std::string& bench, const std::string& night, std::int64_t batch_id) {
  Twin& twin = twins_[bench];
  if (night.empty() || batch_id == 0 || night == twin.anchor_date || !twin.anchor) {
    twin.baseline.reset();
    twin.baseline_batch = 0;
    twin.baseline_note.clear();
    return;
  }
  if (twin.baseline_batch == batch_id) return;  // identified on an earlier night: the same baseline
  twin.baseline.reset();
  twin.baseline_batch = batch_id;
  twin.baseline_date = night;
  twin.baseline_note.clear();
  model::PlantParams family;
  auto ds = LoadCheck(batch_id, &family);
  auto id = ds.ok() ? gap::IdentifyForTracking(*ds, family, &*twin.anchor, gap::TrackOptions{})
                    : StatusOr<gap::MovingIdentification>(ds.status());
  if (id.ok()) {
    twin.baseline = std::move(*id);
    return;
  }
  twin.baseline_note = fmt::format("the check of the baseline's night {} was not identified ({}); the first night's "
                                   "valve stands for it", night, id.status().message());
  spdlog::warn("bench {}: {}", bench, twin.baseline_note);
}

void BenchTwins::SetFlags(const std::string& bench, std::vector<gap::TrackFlag> flags) {
  twins_[bench].flags = std::move(flags);
}

StatusOr<gap::Tracking> BenchTwins::Track(const std::vector<gap::SessionValues>& history,
                                          const gap::SessionValues& tonight) const {
  std::vector<gap::SessionValues> all = history;
  all.push_back(tonight);
  return gap::TrackValues(all, gap::TrackOptions{});
}

namespace {

// One run of `spec` on the emulator with `plant` in place of the spec's: the named metric.
StatusOr<double> ReplayMetric(const experiment::ExperimentSpec& spec, const model::PlantParams& plant,
                              const std::string& metric) {
  auto e = experiment::BuildExperiment(spec);
  if (!e.ok()) return e.status();
  e->plant = plant;
  hw::EmulatedBench bench(experiment::EmulatedBenchFor(*e));
  experiment::Trace trace;
  const experiment::RunSummary s = experiment::Runner::Run(*e, bench, &trace);
  if (!s.ok()) return Status::Internal("the replay failed: " + s.message);
  for (const auto& m : runs::RecordedMetrics(s.metrics))
    if (m.name == metric) return m.value;
  return Status::NotFound("the replay has no metric " + metric);
}

// The replayed metric's spread over the valves another recording of the same valve could have given
// (gap::MovingIdentification::repeatability_draws): 1.4826 x the median absolute deviation, a standard deviation
// for normal values that one draw in an odd corner (a hold that no longer pulls the plunger in) does not set; 0
// when fewer than half of them replay (not known).
double ReplaySpread(const experiment::ExperimentSpec& spec, const gap::MovingIdentification& id,
                    const std::string& metric) {
  std::vector<double> v;
  for (const auto& plant : id.repeatability_draws) {
    auto m = ReplayMetric(spec, plant, metric);
    if (m.ok() && std::isfinite(*m)) v.push_back(*m);
  }
  if (static_cast<int>(v.size()) < gap::kRepeatabilityDraws / 2) return 0.0;
  auto median = [](std::vector<double> x) {
    std::sort(x.begin(), x.end());
    const std::size_t n = x.size();
    return n % 2 ? x[n / 2] : 0.5 * (x[n / 2 - 1] + x[n / 2]);
  };
  const double mid = median(v);
  for (double& x : v) x = std::abs(x - mid);
  return 1.4826 * median(v);
}

// Whether two runs' specs are the same code: equal but for their tags (a night's tags name the night).
bool SameCode(experiment::ExperimentSpec a, experiment::ExperimentSpec b) {
  a.clear_tags();
  b.clear_tags();
  return google::protobuf::util::MessageDifferencer::Equals(a, b);
}

}  // namespace

CaseVerdict DecideCase(double observed_change, double allowed, double valve_change, double sigma,
                       const std::string& changed_since_baseline, double replay_off_tonight) {
  const double share = valve_change / observed_change;
  if (share >= 0.5) return {"valve", ""};  // tonight's valve alone makes at least half the change, in its direction
  if (std::abs(valve_change) + 2.0 * sigma <= allowed) {
    // The valve's change alone stays within what the suite allows, even where two identifications of one valve
    // would replay it twice their repeatability further (two-sided 95 % for a normal spread): a valve change the
    // replay cannot resolve is never taken for none.
    // The valve's part is read off the replay, so the replay must be the bench here: tonight's valve under
    // tonight's code within the allowance of what the bench measured tonight (the scale the suite compares two
    // nights on). Measured in the 60-night lab (docs/track.md): the PI hold's code nights replay 0.19-0.16 mA
    // off against 0.78-1.6 mA allowed; the map at duty 0.3 on a valve 1 % warmer, before the flag, 6.7 points off
    // against 0.5, and its valve part, small by the replay, was taken for none ("code" where the valve changed).
    if (changed_since_baseline.empty() && !(std::abs(replay_off_tonight) > allowed)) return {"code", ""};
    if (changed_since_baseline.empty())
      return {"undetermined",
              fmt::format("the valve's replayed part is within the allowance ({:.4g} of {:.4g} allowed), but tonight's "
                          "identified valve replays this case {:.4g} off what the bench measured tonight: the replay "
                          "does not show what the valve does here",
                          valve_change, allowed, replay_off_tonight)};
    // The tracking saw the valve change since the baseline's night, and its replay says the change does not move
    // this metric. The replay is only as good as the identified valve at this operating point (a valve identified
    // from its switch-on current may replay a case near full opening at the bound where the bench's valve is not:
    // measured in the 60-night lab, docs/track.md), so the tracking's flag is not overruled by it.
    return {"undetermined",
            fmt::format("the valve changed since the baseline ({}), and its identified valve's replay moves this "
                        "metric by only {:.4g} (allowed {:.4g}): the code changed too, or the replay misses what that "
                        "change does here",
                        changed_since_baseline, valve_change, allowed)};
  }
  if (std::abs(valve_change) <= std::max(allowed, 2.0 * sigma))
    return {"undetermined",
            fmt::format("the replay cannot resolve the valve's part here: identifications of one valve replay this "
                        "metric {:.2g} apart (1 sigma) against {:.4g} allowed, and the valve's part, {:.4g}, is within "
                        "that (an operating point near the valve's edge)",
                        sigma, allowed, valve_change)};
  return {"undetermined",
          fmt::format("the valve makes {:.0f} % of the change and more than the suite allows ({:.4g} against {:.4g} "
                      "allowed; the replay repeatable to {:.2g}): both changed, or the identification misses what "
                      "moved",
                      100.0 * share, valve_change, allowed, sigma)};
}

void AddCaseBuild(CaseBuilds* builds, const std::string& case_name, const std::string& run_build) {
  const auto [at, first] = builds->emplace(case_name, run_build);
  if (!first && at->second != run_build) at->second.clear();  // two builds (or one unknown): not one known build
}

CaseVerdict DecideCase(const CaseReplay& r) {
  if (r.spec_is_baseline_code && r.build_is_baseline) {
    // Nothing that runs as code changed: the spec is the baseline's and the same executable ran both (its digest,
    // runs/build_identity.h). The metric moved beyond the allowance, so the bench did: the valve or its wiring. The
    // replay's share is said for what it shows, and a share the replay cannot account for says the health check
    // does not see what moved.
    const double share = r.valve_change / r.observed_change;
    std::string why = "the spec and the build that ran it are the baseline's code's: no code changed, the bench did";
    if (std::isfinite(share)) {
      if (share >= 0.5)
        why += fmt::format(" (tonight's identified valve replays {:.0f} % of the change)", 100.0 * share);
      else if (!r.changed_since_baseline.empty())
        why += fmt::format(" ({}; its identified valve replays {:.0f} % of the change: the rest is what the "
                           "replay does not carry at this operating point)",
                           r.changed_since_baseline, 100.0 * share);
      else
        why += fmt::format(" (tonight's identified valve replays {} and the tracking flagged nothing: what moved "
                           "is not seen by the health check, or not yet beyond its limits)",
                           share < 0.0 ? fmt::format("the change the other way ({:.0f} %)", 100.0 * share)
                                       : fmt::format("only {:.0f} % of the change", 100.0 * share));
    }
    return {"valve", why};
  }
  // A spec change whose replay on the baseline's valve stays within the allowance is no change this metric sees
  // (another seed's jitter, a field the law does not read): DecideCase's rules, on tonight's code, decide.
  if (r.spec_is_baseline_code) {
    // The spec is the one the baseline ran. The valve's part toward the failure, less twice its repeatability, is
    // beyond the allowance: the valve alone fails the night. Under half the change only because the replay is not
    // the bench: the measured change less the replayed one is exactly the replay's distance from the bench on the
    // baseline's side less tonight's. "both changed" would need a code change the spec does not show (the
    // server's build): the trade, a build changed on the same night as the valve is called the valve's.
    // Measured in the 60-night lab's fourth run (docs/track.md): the relaxing spring's map nights, 1.13 points of
    // 2.52 (0.5 allowed, repeatability 0.12), the first night's valve replayed 1.4 points above the bench.
    const double share = r.valve_change / r.observed_change;
    if (share > 0.0 && share < 0.5 && std::abs(r.valve_change) - 2.0 * r.sigma > r.allowed)
      return {"valve", fmt::format("the valve alone moves this metric {:.4g} toward the failure ({:.0f} % of the "
                                   "change; allowed {:.4g}, the replay repeatable to {:.2g}), and the spec is the "
                                   "baseline's: the rest is the replay's distance from the bench",
                                   r.valve_change, 100.0 * share, r.allowed, r.sigma)};
  }
  if (!r.baseline_code_known || !(std::abs(r.code_change) > r.allowed))
    return DecideCase(r.observed_change, r.allowed, r.valve_change, r.sigma, r.changed_since_baseline,
                      r.replay_off_tonight);
  // Each factor changed alone, as a share of the failure (signed: a part against the change reproduces none of
  // it). Half, as DecideCase's valve rule: a factor that alone makes at least half the failure is its cause.
  const double code_share = r.code_change / r.observed_change;
  const double valve_share = r.valve_change_baseline_code / r.observed_change;
  // The valve's share twice its repeatability toward the failure: what another identification of the two valves
  // could have replayed.
  const double valve_share_high =
      (r.valve_change_baseline_code + std::copysign(2.0 * r.sigma_baseline_code, r.observed_change)) /
      r.observed_change;
  if (code_share >= 0.5 && valve_share_high < 0.5) {
    // The test: the failure replayed with tonight's valve and the baseline's code does not reproduce (not
    // half of it, even 2 sigma toward it), and tonight's code on the baseline's valve does: the code changed. A
    // valve the tracking flagged does not stand against this (DecideCase above keeps a flagged valve from being
    // cleared by a replay that reads its part as none; here the code's part is read as present).
    CaseVerdict v{"code", ""};
    if (!r.changed_since_baseline.empty())
      v.why = fmt::format("the valve changed since the baseline ({}), but under the baseline's code tonight's valve "
                          "makes {:.0f} % of the change ({:.4g}), and tonight's code on the baseline's valve {:.0f} %",
                          r.changed_since_baseline, 100.0 * valve_share, r.valve_change_baseline_code,
                          100.0 * code_share);
    return v;
  }
  if (code_share >= 0.5 && valve_share >= 0.5)
    return {"undetermined",
            fmt::format("both changed: tonight's code on the baseline's valve makes {:.0f} % of the change and "
                        "tonight's valve under the baseline's code {:.0f} %",
                        100.0 * code_share, 100.0 * valve_share)};
  if (code_share >= 0.5)
    return {"undetermined",
            fmt::format("tonight's code on the baseline's valve makes {:.0f} % of the change, and tonight's valve "
                        "under the baseline's code {:.0f} %, repeatable to {:.2g}: the replay cannot resolve whether "
                        "the valve makes half of it too",
                        100.0 * code_share, 100.0 * valve_share, r.sigma_baseline_code)};
  if (valve_share >= 0.5) {
    CaseVerdict v{"valve", ""};
    v.why = fmt::format("tonight's valve under the baseline's code makes {:.0f} % of the change; tonight's code on "
                        "the baseline's valve {:.0f} %",
                        100.0 * valve_share, 100.0 * code_share);
    return v;
  }
  if (r.changed_since_baseline.empty() &&
      std::abs(r.valve_change_baseline_code) + 2.0 * r.sigma_baseline_code <= r.allowed &&
      !(std::abs(r.replay_off_tonight) > r.allowed))
    // As DecideCase's code rule: the valve's part within the allowance by 2 sigma and no change tracked; the spec
    // changed and moves the metric beyond the allowance, if not by half (the rest: code the spec does not show).
    return {"code", fmt::format("tonight's code on the baseline's valve makes {:.0f} % of the change, tonight's "
                                "valve under the baseline's code {:.4g} (allowed {:.4g})",
                                100.0 * code_share, r.valve_change_baseline_code, r.allowed)};
  return {"undetermined",
          fmt::format("the code's change moves this metric by {:.4g} on the baseline's valve ({:.0f} % of the "
                      "change, allowed {:.4g}) and tonight's valve under the baseline's code by {:.4g} ({:.0f} %): "
                      "neither makes half the change alone",
                      r.code_change, 100.0 * code_share, r.allowed, r.valve_change_baseline_code,
                      100.0 * valve_share)};
}

regress::Json BenchTwins::Attribute(const regress::RegressResult& result,
                                    const std::map<std::string, experiment::ExperimentSpec>& specs,
                                    const std::map<std::string, std::vector<std::string>>& benches,
                                    const BaselineCode& baseline_code, const CaseBuilds& builds) const {
  regress::Json cases = regress::Json::array();
  regress::Json baseline_valves = regress::Json::object();
  int valve = 0, code = 0, undetermined = 0;
  int code_replayed = 0;  // "code" cases whose code change the replay reproduced (DecideCase(CaseReplay))
  int valve_by_build = 0;  // "valve" cases whose spec and build were the baseline's
  std::string first_undetermined;
  for (const auto& f : result.findings) {
    if (f.verdict != regress::Verdict::kRegressed) continue;
    regress::Json c = {{"case", f.case_name}, {"metric", f.metric}, {"observed_change", f.delta},
                       {"allowed", f.allowed}};
    std::string why;
    double reference_sum = 0.0, tonight_sum = 0.0, var_sum = 0.0;
    // The same under the baseline's code, when its spec of this case differs from tonight's.
    double reference_old_sum = 0.0, tonight_old_sum = 0.0, var_old_sum = 0.0;
    int n = 0;
    std::string changed;  // a bench that ran it whose valve the tracking saw change since the baseline's night
    const auto spec = specs.find(f.case_name);
    const auto ran = benches.find(f.case_name);
    const auto old_spec = baseline_code.specs.find(f.case_name);
    const bool same_spec =
        spec != specs.end() && old_spec != baseline_code.specs.end() && SameCode(old_spec->second, spec->second);
    const bool code_known = spec != specs.end() && old_spec != baseline_code.specs.end() && !same_spec;
    // One known build ran the case tonight and the same one ran the baseline's runs of it.
    const auto build = builds.find(f.case_name);
    const auto old_build = baseline_code.builds.find(f.case_name);
    const bool same_build = build != builds.end() && old_build != baseline_code.builds.end() &&
                            !build->second.empty() && build->second == old_build->second;
    if (build != builds.end() && !build->second.empty()) c["build"] = build->second;
    if (old_build != baseline_code.builds.end() && !old_build->second.empty()) {
      c["baseline_build"] = old_build->second;
      c["baseline_code"] = baseline_code.from;
    }
    if (!std::isfinite(f.delta)) {
      why = "the metric has no value on one side";
    } else if (spec == specs.end() || ran == benches.end() || ran->second.empty()) {
      why = "the case's runs are not known";
    } else {
      for (const auto& b : ran->second) {
        const auto t = twins_.find(b);
        if (t == twins_.end() || t->second.Reference() == nullptr || !t->second.tonight) {
          why = "bench " + b + " ran it and has no identified health check tonight (a \"health\" block)";
          break;
        }
        baseline_valves[b] = t->second.ReferenceDate() +
                             (t->second.baseline_note.empty() ? "" : " (" + t->second.baseline_note + ")");
        auto a = ReplayMetric(spec->second, t->second.Reference()->plant, f.metric);
        auto now = ReplayMetric(spec->second, t->second.tonight->plant, f.metric);
        if (!a.ok() || !now.ok()) {
          why = "the replay on bench " + b + "'s valve: " + (a.ok() ? now.status() : a.status()).message();
          break;
        }
        reference_sum += *a, tonight_sum += *now, ++n;
        for (const auto& flag : t->second.flags)
          if (changed.empty() && flag.since >= t->second.ReferenceDate())
            changed = fmt::format("bench {}'s {} {} since {} (flagged {})", b, flag.parameter, flag.direction,
                                  flag.since, flag.session);
        const double sa = ReplaySpread(spec->second, *t->second.Reference(), f.metric);
        const double st = ReplaySpread(spec->second, *t->second.tonight, f.metric);
        var_sum += sa * sa + st * st;
        if (code_known) {
          auto a_old = ReplayMetric(old_spec->second, t->second.Reference()->plant, f.metric);
          auto now_old = ReplayMetric(old_spec->second, t->second.tonight->plant, f.metric);
          if (!a_old.ok() || !now_old.ok()) {
            why = "the replay of the baseline's code on bench " + b + "'s valve: " +
                  (a_old.ok() ? now_old.status() : a_old.status()).message();
            break;
          }
          reference_old_sum += *a_old, tonight_old_sum += *now_old;
          const double sa_old = ReplaySpread(old_spec->second, *t->second.Reference(), f.metric);
          const double st_old = ReplaySpread(old_spec->second, *t->second.tonight, f.metric);
          var_old_sum += sa_old * sa_old + st_old * st_old;
        }
      }
    }
    std::string verdict;
    if (why.empty() && n > 0) {
      // The valve's share of the change: the same code on tonight's valve against the baseline's valve.
      const double valve_change = (tonight_sum - reference_sum) / n;
      c["replay_baseline_valve"] = reference_sum / n;
      c["replay_tonight_valve"] = tonight_sum / n;
      c["valve_change"] = valve_change;
      // What two identifications of one valve replay apart: each valve's replays over its repeatability draws.
      const double sigma = std::sqrt(var_sum) / n;
      c["valve_change_sigma"] = sigma;
      c["valve_share"] = valve_change / f.delta;
      CaseReplay replay{f.delta, f.allowed, valve_change, sigma, changed};
      replay.replay_off_tonight = tonight_sum / n - f.now.mean;
      replay.spec_is_baseline_code = same_spec;
      replay.build_is_baseline = same_build;
      if (code_known) {
        // Both codes on both valves: the code's change on the baseline's valve, the valve's under the baseline's
        // code, each with its own repeatability.
        replay.baseline_code_known = true;
        replay.code_change = (reference_sum - reference_old_sum) / n;
        replay.valve_change_baseline_code = (tonight_old_sum - reference_old_sum) / n;
        replay.sigma_baseline_code = std::sqrt(var_old_sum) / n;
        c["baseline_code"] = baseline_code.from;
        c["replay_baseline_valve_baseline_code"] = reference_old_sum / n;
        c["replay_tonight_valve_baseline_code"] = tonight_old_sum / n;
        c["code_change"] = replay.code_change;
        c["valve_change_baseline_code"] = replay.valve_change_baseline_code;
        c["valve_change_baseline_code_sigma"] = replay.sigma_baseline_code;
      }
      const CaseVerdict d = DecideCase(replay);
      verdict = d.verdict;
      why = d.why;
      // Where the replay leaves it undetermined, whether the replay is the bench at this operating point: the
      // identified valves' replays (tonight's code) against what the bench measured on either side. Off by more
      // than the allowance, the identification does not carry this case (a valve identified from its switch-on
      // current replays a hold near its edge where the bench's valve is not: docs/track.md).
      // The baseline's side only under the baseline's code, where it is known or is tonight's (the bench measured it
      // under that; under another code the difference would hold the code's change too).
      const double base_replay = (code_known ? reference_old_sum : reference_sum) / n;
      const double off_baseline = base_replay - f.baseline.mean, off_tonight = replay.replay_off_tonight;
      const bool baseline_side = code_known || same_spec;  // the baseline's side under the baseline's code
      if (baseline_side) c["replay_minus_measured_baseline"] = off_baseline;
      c["replay_minus_measured_tonight"] = off_tonight;
      if (verdict == "undetermined" &&
          std::max(baseline_side ? std::abs(off_baseline) : 0.0, std::abs(off_tonight)) > f.allowed)
        why += fmt::format("; the identified valves replay this case at {:.4g} and {:.4g} where the bench measured "
                           "{:.4g} and {:.4g}: the replay is not the bench here (a health run at this case's "
                           "operating point would pin it)",
                           base_replay, tonight_sum / n, f.baseline.mean, f.now.mean);
    } else if (std::isfinite(f.delta) && same_spec && same_build) {
      // No replay (a bench without an identified check tonight, a replay that failed), but nothing that runs as
      // code changed (DecideCase(CaseReplay)): the bench did, whatever the replay could not say.
      verdict = "valve";
      why = "the spec and the build that ran it are the baseline's code's: no code changed, the bench did (not "
            "replayed: " + why + ")";
    } else {
      verdict = "undetermined";
    }
    if (verdict == "valve" && same_spec && same_build) ++valve_by_build;
    if (same_spec && build != builds.end() && old_build != baseline_code.builds.end() && !build->second.empty() &&
        !old_build->second.empty() && build->second != old_build->second)
      // The spec is the baseline's and the build is not: a code change the spec does not show, which the replay
      // (on this server's build, both sides) cannot replay. Said, so that a `code` here reads as the build's.
      why += std::string(why.empty() ? "" : "; ") + "the spec is the baseline's code's but the build is not (" +
             old_build->second + " -> " + build->second + ")";
    c["verdict"] = verdict;
    if (!why.empty()) c["reason"] = why;
    (verdict == "valve" ? valve : verdict == "code" ? code : undetermined)++;
    if (verdict == "code" && c.contains("code_change") && std::abs(c["code_change"].get<double>()) > f.allowed)
      ++code_replayed;
    if (verdict == "undetermined" && first_undetermined.empty()) first_undetermined = f.case_name + " " + f.metric + ": " + why;
    cases.push_back(std::move(c));
  }
  regress::Json out = {{"cases", cases}};
  if (!baseline_valves.empty()) out["baseline_valves"] = baseline_valves;
  if (cases.empty()) {
    out["verdict"] = "undetermined";
    out["reason"] = "no metric regressed (runs failed): the replay compares metrics";
  } else if (undetermined > 0) {
    out["verdict"] = "undetermined";
    out["reason"] = first_undetermined;
  } else if (valve > 0 && code > 0) {
    out["verdict"] = "undetermined";
    out["reason"] =
        fmt::format("tonight's valve reproduces {} regressed metric(s) and not {}: both changed", valve, code);
  } else if (valve > 0 && valve_by_build == valve) {
    out["verdict"] = "valve";
    out["reason"] = "every regressed case ran the spec and the build of the baseline's code (" + baseline_code.from +
                    "): no code changed, the bench did";
  } else if (valve > 0) {
    out["verdict"] = "valve";
    out["reason"] = valve_by_build > 0
                        ? "every regressed metric is the bench's: its case ran the spec and the build of the "
                          "baseline's code, or the same code on tonight's identified valve reproduces it"
                        : "the same code on tonight's identified valve reproduces every regressed metric (the valve "
                          "of the baseline's night does not)";
  } else if (code_replayed == code) {
    out["verdict"] = "code";
    out["reason"] = "tonight's code on the baseline's night's valve makes at least half of every regressed metric's "
                    "change, and tonight's identified valve under the baseline's code (" + baseline_code.from +
                    ") stays within the suite's allowance: the code changed";
  } else {
    out["verdict"] = "code";
    out["reason"] = "tonight's identified valve, under the same code, stays within the suite's allowance of the "
                    "baseline's night's valve on every regressed metric: the code changed";
  }
  return out;
}

}  // namespace vb::server
