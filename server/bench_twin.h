// The bench twin on the server (issue 38, docs/track.md "On the server"): each night, each checked bench's health
// check identified (the bench's first night from scratch, every later one warm-started from it), its values kept
// in the night's record, the bench's nights tracked from those records (gap::TrackValues: no night identified
// twice); and a regressed night's failing comparison replayed on the emulator with the valve the baseline was
// measured on (the bench's check of the baseline's night; its first night when the baseline is older) and
// tonight's valve under the same code: when tonight's valve alone reproduces the change, the valve changed; when
// it does not, the code did. Where the case's spec differs from the one the baseline ran (the baseline's code),
// both codes run on both valves: the failure replayed with tonight's valve and the baseline's code, and tonight's
// code on the baseline's valve.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "common/status.h"
#include "experiment/spec.h"
#include "gap/track.h"
#include "regress/compare.h"
#include "service/bench_health.h"
#include "service/service.h"

namespace vb::server {

// One regressed metric's cause from its replay: `observed_change` (tonight minus the baseline, measured),
// `allowed` (the suite's tolerance plus noise), `valve_change` (tonight's valve minus the baseline's valve, replayed
// under tonight's code), `sigma` (the replay's repeatability) and, when the tracking saw the valve change since
// the baseline's night, what changed. "valve": the valve makes at least half the change; "code": its part is within
// the allowance by 2 sigma, the tracking saw no change and the replay is the bench (below); else "undetermined"
// with why.
struct CaseVerdict {
  std::string verdict, why;
};
// `replay_off_tonight`: tonight's valve replayed under tonight's code minus what the bench measured tonight (NaN:
// not known). "code" also needs it within the allowance: the valve's part read as small is only evidence where
// the replay is the bench (both sides under one code, so valid whether the code changed or not).
CaseVerdict DecideCase(double observed_change, double allowed, double valve_change, double sigma,
                       const std::string& changed_since_baseline, double replay_off_tonight = NAN);

// The same with the baseline's code replayed too, when the case's spec then differs from tonight's: the issue's
// question taken literally, two factors each changed alone (docs/track.md, "The baseline's code replayed too").
// `B`: the baseline's valve, `T`: tonight's; `b`: the baseline's code, `t`: tonight's.
struct CaseReplay {
  double observed_change = 0.0, allowed = 0.0;
  double valve_change = 0.0;  // T,t - B,t: tonight's valve under tonight's code (DecideCase above)
  double sigma = 0.0;         // the replay's repeatability (two identifications of one valve)
  std::string changed_since_baseline;
  double replay_off_tonight = NAN;  // tonight's replay minus tonight's measurement (DecideCase above)
  // The baseline's spec of this case found and equal to tonight's (but for tags): no code change the spec shows.
  bool spec_is_baseline_code = false;
  // And every run of the case, tonight's and the baseline's, executed by one and the same build (the executable's
  // digest, runs/build_identity.h): no code change at all, the spec's or the build's.
  bool build_is_baseline = false;
  bool baseline_code_known = false;  // the baseline's spec of this case found, and it differs from tonight's
  double code_change = 0.0;                 // B,t - B,b: tonight's code on the baseline's valve
  double valve_change_baseline_code = 0.0;  // T,b - B,b: tonight's valve under the baseline's code
  double sigma_baseline_code = 0.0;         // its repeatability
};
// When the spec change moves the metric beyond the allowance on the baseline's valve, each factor alone as a share
// of the failure: "code" when the code makes at least half and tonight's valve under the baseline's code less than
// half even 2 sigma toward it (the failure does not reproduce with the old code: the code changed, whatever the
// tracking saw); "valve" when the valve makes half and the code not; else "undetermined" saying which parts reach
// how far. A spec change within the allowance (or none) leaves DecideCase's rules above, but for one: where the
// spec is the baseline's and the valve's part alone fails the night (beyond the allowance toward the failure by 2
// sigma), "valve" even under half the change (the rest is the replay's distance from the bench).
// Where the spec and the build are the baseline's (build_is_baseline), "valve": nothing that runs as code changed,
// so what moved the metric is the bench (the valve, or the rest of its wiring); the replay's shares are said, not
// needed. The trade: what a run does not record as code (a shared library another apt upgrade brought, a server
// setting outside the spec) is called the bench's.
CaseVerdict DecideCase(const CaseReplay& r);

// Each case's build: the one build every run of the case recorded (db::ExecutionRecord::build); "" when a run of
// it recorded none (it did not execute, or ran before schema version 7) or two runs name different builds.
using CaseBuilds = std::map<std::string, std::string>;
void AddCaseBuild(CaseBuilds* builds, const std::string& case_name, const std::string& run_build);

// The code the baseline was measured with: each case's spec (its first run's) from a stored batch, and which.
struct BaselineCode {
  std::map<std::string, experiment::ExperimentSpec> specs;  // case -> spec
  std::string from;  // "the baseline's batch 12" / "night 2026-11-01's suite, batch 40"
  // Which build ran each case: the baseline's own batch's; under the night rule, the night's build for the cases
  // that night compared with this baseline and found within its allowance (it reproduced the baseline there, so
  // only what changed since that night can fail tonight), else none (NightScheduler::BaselineCodeOf).
  CaseBuilds builds;
};

class BenchTwins {
 public:
  explicit BenchTwins(StorePool* pool) : pool_(pool) {}

  // Tonight's health check of `bench` (the runs of its batch) identified; keeps the identification for Attribute.
  // The first night of a bench (or the first after a restart) identifies the bench's first stored check from
  // scratch as the anchor (`first_batch_id`: its batch; 0 = tonight is the first).
  // `stored_anchor`: where the anchor had moved before a restart (the store's newest "anchor_refit"; nullptr: never):
  // the first check is then identified warm-started from it, in that basin.
  // Then the anchor's basin is checked against tonight's (gap::BetterAnchor, as `benchctl track` checks it): when
  // tonight fits its runs at least kAnchorRatioGain better relative to its noise floor than the anchor fits its
  // own, the anchor's check is fitted again from tonight's end; when that lowers its fit by more than 10 %, it is
  // the anchor (at most kMaxAnchorMoves times a bench), tonight is identified again from it, and AnchorMovedTonight
  // says so: the earlier nights must then be identified again (Reidentify), or their values and tonight's would
  // come from two basins and differ by the basins' distance, not the valve's change.
  gap::SessionValues Identify(const std::string& bench, const std::string& date, std::int64_t batch_id,
                              const std::string& first_date, std::int64_t first_batch_id,
                              const StoredAnchor* stored_anchor = nullptr);
  // A tenth: the refit must gain a tenth of the fit anyway (gap::BetterAnchor), and nights of one valve whose
  // fits are within a tenth of each other relative to their noise are in one basin as far as the fit can tell;
  // without the margin every other night (half of them fit better than the anchor by chance) would cost a refit.
  static constexpr double kAnchorRatioGain = 1.1;
  static constexpr int kMaxAnchorMoves = 2;  // as `benchctl track`'s two rounds

  // Whether tonight's Identify moved the bench's anchor, and where to (a night's "anchor_refit" block).
  bool AnchorMovedTonight(const std::string& bench) const;
  StoredAnchor AnchorOf(const std::string& bench) const;
  // The bench's earlier nights (`checks`: night -> its check, before `date`) identified again from its anchor.
  std::vector<gap::SessionValues> Reidentify(const std::string& bench, const std::string& date,
                                             const std::map<std::string, StoredCheck>& checks) const;

  // The valve the night's baseline was measured on, for Attribute: the bench's check of `night` (its batch),
  // identified as the tracking identified it (warm-started from the anchor) and kept while the baseline stays;
  // "" or the anchor's night: the anchor. A check that cannot be identified leaves the anchor, with the reason
  // in Attribute's output.
  void UseBaselineNight(const std::string& bench, const std::string& night, std::int64_t batch_id);

  // Tonight's tracking flags of `bench` (Track's), for Attribute: a valve the tracking saw change since the
  // baseline's night is never cleared by its replay alone.
  void SetFlags(const std::string& bench, std::vector<gap::TrackFlag> flags);

  // The bench's nights tracked: the values stored in earlier nights' records (`history`, in date order) and
  // tonight's.
  StatusOr<gap::Tracking> Track(const std::vector<gap::SessionValues>& history, const gap::SessionValues& tonight) const;

  // Why a regressed night regressed: every regressed finding's case replayed on the emulator with each bench's
  // baseline valve (UseBaselineNight; else its anchor) and tonight's valve (`specs`: the case's spec; `benches`:
  // which benches ran the case tonight).
  // {"verdict": "valve" | "code" | "undetermined", "reason", "cases": [...], "baseline_valves": {bench: night}}.
  // `baseline_code`: the baseline's code (empty: not known); a case whose spec differs from it is replayed under
  // both codes on both valves (DecideCase(CaseReplay)). `builds`: which build ran each case tonight (AddCaseBuild);
  // a case whose spec and build are both the baseline's is the bench's, replayed or not.
  regress::Json Attribute(const regress::RegressResult& result,
                          const std::map<std::string, experiment::ExperimentSpec>& specs,
                          const std::map<std::string, std::vector<std::string>>& benches,
                          const BaselineCode& baseline_code = {}, const CaseBuilds& builds = {}) const;

 private:
  struct Twin {
    std::optional<gap::MovingIdentification> anchor, tonight, baseline;
    std::string anchor_date, tonight_date, baseline_date;
    std::int64_t anchor_batch = 0;  // the anchor's check (its session is what a basin check refits)
    int anchor_moves = 0;
    bool anchor_moved_tonight = false;
    std::int64_t baseline_batch = 0;
    std::string baseline_note;  // why the anchor stands for the baseline's night
    std::vector<gap::TrackFlag> flags;  // tonight's tracking flags
    // The valve the replay compares tonight's with: the baseline's night's, else the anchor.
    const gap::MovingIdentification* Reference() const { return baseline ? &*baseline : anchor ? &*anchor : nullptr; }
    const std::string& ReferenceDate() const { return baseline ? baseline_date : anchor_date; }
  };
  // A night's health check as a switch-on session; its hold runs (gap/hold.h) are moved to *holds when given.
  StatusOr<gap::Dataset> LoadCheck(std::int64_t batch_id, model::PlantParams* family,
                                   std::vector<gap::RunData>* holds = nullptr) const;

  StorePool* pool_;
  std::map<std::string, Twin> twins_;
};

}  // namespace vb::server
