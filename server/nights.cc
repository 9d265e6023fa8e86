#include "server/nights.h"
#include "service/prune_rules.h"

#include <algorithm>
#include <chrono>
#include <set>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <cstdio>

#include "db/records.h"
#include "experiment/spec.h"
#include "regress/compare.h"
#include "regress/cron.h"
#include "regress/suite.h"
#include "server/health_check.h"
#include "service/bench_health.h"
#include "service/lab_benches.h"
#include "runs/query.h"

namespace vb::server {

namespace v1 = valvebench::v1;

namespace {

constexpr double kNightDeadline_s = 20 * 3600.0;  // a night still unfinished after this is stored as "error"
constexpr double kPollPeriod_s = 0.2;             // how often the batch's runs are checked while waiting

double WallClock() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

// What regress compares of one stored run: its key, whether it ended done (else why not) and its metrics.
StatusOr<regress::RunMetrics> MeasuredRun(db::Store* store, const db::RunRecord& r) {
  regress::RunMetrics m;
  m.run_id = r.id;
  m.name = r.key.DisplayName();
  m.case_name = r.key.CaseName();
  m.ok = r.status == db::RunStatus::kDone;
  m.reason = m.ok ? "" : std::string(db::RunStatusName(r.status)) + (r.reason.empty() ? "" : ": " + r.reason);
  auto metrics = store->GetMetrics(r.id);
  if (!metrics.ok()) return metrics.status();
  for (const auto& x : *metrics) m.metrics[x.name] = x.value;
  return m;
}

// The cases the stored night `night` compared with `baseline` itself (its name and version) and found within the
// allowance on every metric: there that night's code, on that night's benches, reproduced the baseline. Empty
// when the night is not stored, was compared with another baseline (or version), or its record does not read.
std::set<std::string> CasesReproducingBaseline(db::Store* store, const std::string& night,
                                               const regress::Baseline& baseline) {
  std::set<std::string> within, regressed;
  auto briefs = store->ListRegressions(/*nights_only=*/true, 1000);
  if (!briefs.ok()) return {};
  for (const auto& b : *briefs) {
    if (b.night != night) continue;
    if (b.baseline_name != baseline.name || b.baseline_version != baseline.version) return {};
    auto rec = store->GetRegression(b.id);
    if (!rec.ok()) return {};
    const auto j = regress::Json::parse(rec->result_json, nullptr, false);
    if (!j.is_object() || !j.contains("findings") || !j["findings"].is_array()) return {};
    for (const auto& f : j["findings"]) {
      if (!f.is_object() || !f.contains("case") || !f["case"].is_string()) continue;
      const std::string name = f["case"].get<std::string>();
      (f.value("verdict", "") == "regressed" || f.value("verdict", "") == "new" ? regressed : within).insert(name);
    }
    for (const auto& r : regressed) within.erase(r);
    return within;
  }
  return {};
}

}  // namespace

NightScheduler::NightScheduler(NightsSetup setup, std::vector<runs::BenchSetup> benches, StorePool* pool,
                               SubmitFn submit, ClockFn clock)
    : setup_(std::move(setup)), benches_(std::move(benches)), pool_(pool), submit_(std::move(submit)), clock_(clock ? std::move(clock) : WallClock) {}

NightScheduler::~NightScheduler() { Stop(); }

void NightScheduler::Start(int nights_now) {
  thread_ = std::thread([this, nights_now] { Loop(nights_now); });
}

void NightScheduler::Stop() {
  stop_signal_.Stop();
  if (thread_.joinable()) thread_.join();
}

void NightScheduler::Loop(int nights_now) {
  auto cron = regress::Cron::Parse(setup_.cron);
  if (!cron.ok()) {  // validated with the config; kept as a guard
    spdlog::error("nights.cron: {}", cron.status().message().c_str());
    return;
  }
  auto night = [this](double fire_unix_s) {
    auto id = RunNight(fire_unix_s);
    if (id.status().code() == StatusCode::kAlreadyExists) spdlog::info("{}", id.status().message());
    else if (!id.ok()) spdlog::error("night: {}", id.status().message().c_str());
  };
  constexpr double kDay_s = 86400.0;
  for (int k = nights_now - 1; k >= 0 && !stop_signal_.stopped(); --k) night(clock_() - k * kDay_s);
  for (;;) {
    auto next = cron->NextUnix(clock_(), setup_.utc);
    if (!next.ok()) {
      std::fprintf(stderr, "valvebench-server: nights.cron '%s': %s; no nights will run\n", setup_.cron.c_str(),
                   next.status().message().c_str());
      return;
    }
    if (!stop_signal_.SleepUntil(*next)) return;
    night(*next);
  }
}

std::vector<runs::BenchSetup> NightScheduler::CheckedBenches() {
  std::vector<runs::BenchSetup> out = benches_;
  if (setup_.lab_host.empty()) return out;
  // In a lab the host that claimed the night checks every live host's benches (docs/track.md, "In a lab"): each
  // host registers its benches' health blocks with its heartbeat, and a check pinned to a bench runs on the host
  // that has it. A host whose heartbeat is three lease TTLs behind ours (the store's clock on both) is gone: its
  // checks would hold the night until its deadline.
  auto store = pool_->Acquire();
  auto hosts = store.ok() ? (*store)->ListHosts() : StatusOr<std::vector<db::HostRecord>>(store.status());
  if (!hosts.ok()) {
    spdlog::warn("nights: the lab's hosts: {}; only this host's benches are checked", hosts.status().message());
    return out;
  }
  double newest = 0.0;
  for (const auto& h : *hosts) newest = std::max(newest, h.heartbeat_unix_s);
  std::vector<db::HostRecord> live;
  for (const auto& h : *hosts)
    if (h.heartbeat_unix_s >= newest - 3.0 * setup_.lab_lease_ttl_s) live.push_back(h);
  for (auto& b : OtherHostsBenches(live, setup_.lab_host))
    if (b.config.has_health()) out.push_back(std::move(b));
  return out;
}

StatusOr<std::int64_t> NightScheduler::SaveNight(const std::string& date, std::int64_t batch_id,
                                                 const std::string& verdict, const std::string& result_json,
                                                 double finished_unix_s) {
  auto store = pool_->Acquire();
  if (!store.ok()) return store.status();
  db::RegressionRecord rec;
  rec.night = date;
  rec.batch_id = batch_id;
  rec.verdict = verdict;
  rec.result_json = result_json;
  rec.created_unix_s = finished_unix_s;
  auto j = regress::Json::parse(result_json, nullptr, false);
  if (j.is_object()) {
    rec.suite = j.value("suite", "");
    if (j.contains("baseline") && j["baseline"].is_object()) {
      rec.baseline_name = j["baseline"].value("name", "");
      rec.baseline_version = j["baseline"].value("version", 0);
    }
  }
  auto id = (*store)->SaveRegression(rec);
  if (!id.ok()) return id.status().WithContext("night " + date);
  spdlog::info("night {}: {} (batch {}, regression {})", date.c_str(), verdict.c_str(),
               static_cast<long long>(batch_id), static_cast<long long>(*id));
  return id;
}

StatusOr<int> NightScheduler::NightNumber(const std::string& date) {
  auto store = pool_->Acquire();
  if (!store.ok()) return store.status();
  auto nights = (*store)->ListRegressions(/*nights_only=*/true, 1000);
  if (!nights.ok()) return nights.status();
  std::set<std::string> before;
  for (const auto& n : *nights)
    if (!n.night.empty() && n.night < date) before.insert(n.night);
  return static_cast<int>(before.size()) + 1;
}

StatusOr<std::int64_t> NightScheduler::RunNight(double fire_unix_s) {
  const std::string date = regress::DateOf(fire_unix_s, setup_.utc);
  if (!setup_.lab_host.empty()) {
    // A lab runs each night once, not once per host (docs/lab.md, "Nights"): the host that claims it runs it;
    // its runs go to the shared queue, so every host's benches take them.
    auto store = pool_->Acquire();
    if (!store.ok()) return store.status();
    auto won = (*store)->ClaimNight(date, setup_.lab_host);
    if (!won.ok()) return won.status().WithContext("night " + date);
    if (!*won) return Status::AlreadyExists("night " + date + ": another host of the lab runs it; skipped here");
    spdlog::info("night {}: claimed by this host ({})", date, setup_.lab_host);
  }
  const double started_unix_s = clock_();
  std::int64_t batch_id = 0;
  int night_number = 0;
  regress::Json health = regress::Json::array();
  std::string suite_name, baseline_name;
  int baseline_version = 0;
  auto error = [&](const Status& st) {
    regress::Json j = {{"night", date},
                       {"suite", suite_name},
                       {"baseline", {{"name", baseline_name}, {"version", baseline_version}}},
                       {"batch_id", batch_id},
                       {"started_unix_s", started_unix_s},
                       {"night_number", night_number},
                       {"health", health},
                       {"error", st.message()}};
    return SaveNight(date, batch_id, "error", j.dump(), clock_());
  };

  auto number = NightNumber(date);
  if (!number.ok()) return error(number.status().WithContext("the night's number"));
  night_number = *number;
  // Each bench's health check, queued ahead of the suite (its runs' priority): a failed submission is recorded
  // in the night and does not stop it.
  for (const auto& bench : CheckedBenches()) {
    auto specs = HealthCheckSpecs(bench, date, night_number);
    if (specs.empty()) continue;
    auto queued = submit_(runs::Submission{"nights", "health:" + date, std::move(specs), {}, ""});
    if (!queued.ok()) {
      spdlog::error("night {}: health check of {}: {}", date, bench.name, queued.status().message());
      health.push_back({{"bench", bench.name}, {"error", queued.status().message()}});
      continue;
    }
    health.push_back({{"bench", bench.name}, {"batch_id", queued->batch_id}, {"runs", queued->run_ids}});
    spdlog::info("night {}: health check of {}: batch {}, {} runs", date, bench.name,
                 static_cast<long long>(queued->batch_id), static_cast<int>(queued->run_ids.size()));
  }

  auto suite = regress::LoadSuite(setup_.suite_path);
  if (!suite.ok()) return error(suite.status().WithContext("nights.suite_file " + setup_.suite_path));
  suite_name = suite->suite.name();
  auto baseline = LoadBaselineFile(setup_.baseline_path);
  if (!baseline.ok()) return error(baseline.status().WithContext("nights.baseline_file"));
  baseline_name = baseline->name;
  baseline_version = baseline->version;
  const std::uint64_t seed = suite->suite.seed() != 0 ? suite->suite.seed() : 1;
  auto runs = regress::ExpandSuite(suite->suite, seed);
  if (!runs.ok()) return error(runs.status());
  std::vector<v1::ExperimentSpec> specs;
  std::map<std::string, experiment::ExperimentSpec> case_specs;          // each case's first run (the replay's)
  std::map<std::string, std::vector<std::string>> case_benches;          // the benches that ran each case
  CaseBuilds case_builds;                                                // the build that ran each case
  std::vector<RunKey> keys;
  for (auto& r : *runs) {
    keys.push_back(r.key);
    r.spec.add_tags("night");
    r.spec.add_tags("night:" + date);
    r.spec.add_tags(runs::NightNumberTag(night_number));
    case_specs.emplace(r.key.CaseName(), r.spec);
    specs.push_back(std::move(r.spec));
  }
  auto queued = submit_(runs::Submission{"nights", "night:" + date, std::move(specs), std::move(keys), ""});
  if (!queued.ok()) return error(queued.status().WithContext("submit"));
  batch_id = queued->batch_id;
  spdlog::info("night {}: suite {}, batch {}, {} runs", date.c_str(), suite_name.c_str(),
               static_cast<long long>(batch_id), static_cast<int>(queued->run_ids.size()));

  // Wait for every run of the batch to end; collect what regress compares.
  std::vector<regress::RunMetrics> measured;
  for (;;) {
    {
      if (stop_signal_.stopped())
        return Status::Aborted("night " + date + ": the server stopped before batch " + std::to_string(batch_id) +
                               " finished; nothing stored");
    }
    auto store = pool_->Acquire();
    if (!store.ok()) return error(store.status());
    auto listed = runs::ListBatch(store->get(), batch_id);
    if (!listed.ok()) return error(listed.status());
    const std::vector<db::RunRecord>& all = *listed;
    bool done = !all.empty();
    for (const auto& r : all) done = done && (Ended(r.status) || r.status == RunStatus::kInterrupted);  // nothing more will come
    if (done) {
      for (const auto& r : all) {
        auto m = MeasuredRun(store->get(), r);
        if (!m.ok()) return error(m.status());
        AddCaseBuild(&case_builds, m->case_name, r.execution ? r.execution->build : "");
        auto& ran = case_benches[m->case_name];
        if (!r.bench_name.empty() && std::find(ran.begin(), ran.end(), r.bench_name) == ran.end())
          ran.push_back(r.bench_name);
        measured.push_back(std::move(*m));
      }
      break;
    }
    if (clock_() - started_unix_s > kNightDeadline_s)
      return error(Status::Unavailable("batch " + std::to_string(batch_id) + " did not finish within " +
                                       std::to_string(static_cast<int>(kNightDeadline_s / 3600)) + " h"));
    stop_signal_.SleepFor(kPollPeriod_s);
  }

  // The health checks end too before the night is stored: the night's record is then complete (a bench's
  // tracking reads every check of the nights stored).
  for (const auto& h : health) {
    if (!h.contains("batch_id")) continue;
    const std::int64_t id = h["batch_id"].get<std::int64_t>();
    for (;;) {
      if (stop_signal_.stopped())
        return Status::Aborted("night " + date + ": the server stopped before the health check (batch " +
                               std::to_string(id) + ") finished; nothing stored");
      auto store = pool_->Acquire();
      if (!store.ok()) return error(store.status());
      auto listed = runs::ListBatch(store->get(), id);
      if (!listed.ok()) return error(listed.status());
      bool done = true;
      for (const auto& r : *listed) done = done && (Ended(r.status) || r.status == RunStatus::kInterrupted);
      if (done) break;
      if (clock_() - started_unix_s > kNightDeadline_s)
        return error(Status::Unavailable("health check batch " + std::to_string(id) + " did not finish within " +
                                         std::to_string(static_cast<int>(kNightDeadline_s / 3600)) + " h"));
      stop_signal_.SleepFor(kPollPeriod_s);
    }
  }

  regress::RegressResult r = regress::Compare(suite->suite, *baseline, regress::Summarise(measured));
  r.batch_id = batch_id;
  r.where = "server nights";
  r.night = date;
  r.seed = seed;
  regress::Json j = regress::ResultToJson(r);
  j["started_unix_s"] = started_unix_s;
  j["night_number"] = night_number;
  TwinNight(date, r, case_specs, case_benches, case_builds, *baseline, &health, &j);
  j["health"] = health;
  return SaveNight(date, batch_id, r.verdict(), j.dump(), clock_());
}

BaselineCode NightScheduler::BaselineCodeOf(const regress::Baseline& baseline,
                                            const std::map<std::string, StoredCheck>& suites) {
  // The baseline's own runs when its source names a batch of this server ("benchctl baseline set --batch") and
  // that batch's runs are the ones it summarises (a batch number from another lab's server names another batch
  // here); else the suite's runs of the night whose valve stands for the baseline's (the last night that started
  // before it was made; none: the first night stored, as the replay's valve then is the bench's first check).
  BaselineCode out;
  auto store = pool_->Acquire();
  if (!store.ok()) {
    spdlog::warn("the baseline's code: {}", store.status().message());
    return out;
  }
  auto add_specs = [&out](const std::vector<db::RunRecord>& runs) {
    for (const auto& run : runs) {
      const std::string name = run.key.CaseName();
      if (out.specs.count(name)) continue;  // each case's first run, as tonight's (RunNight's case_specs)
      auto spec = experiment::ParseSpecJson(run.spec_json);
      if (spec.ok()) out.specs.emplace(name, std::move(*spec));
    }
  };
  std::string not_own;
  if (const std::int64_t batch = db::ServerBatchOfBaselineSource(baseline.source); batch > 0) {
    auto listed = runs::ListBatch(store->get(), batch);
    std::vector<regress::RunMetrics> measured;
    Status read = listed.status();
    for (std::size_t k = 0; read.ok() && k < listed->size(); ++k) {
      auto m = MeasuredRun(store->get(), (*listed)[k]);
      if (m.ok()) measured.push_back(std::move(*m));
      read = m.status();  // a batch whose runs cannot be read cannot be checked: the night rule
    }
    not_own = read.ok() ? regress::BaselineNotOfRuns(baseline, measured) : read.message();
    if (not_own.empty()) {
      out.from = fmt::format("the baseline's batch {}", batch);
      add_specs(*listed);
      for (const auto& run : *listed)
        AddCaseBuild(&out.builds, run.key.CaseName(), run.execution ? run.execution->build : "");
      return out;
    }
    not_own = fmt::format("the baseline's source names batch {}, which is not the baseline's here ({}); ", batch,
                          not_own);
    spdlog::warn("the baseline's code: {}", not_own);
  }
  auto night = BaselineNight(suites, baseline.created_unix_s);
  if (!night && !suites.empty()) night = *suites.begin();
  if (!night) return out;
  const std::int64_t batch = night->second.batch_id;
  out.from = not_own + fmt::format("night {}'s suite, batch {}", night->first, batch);
  auto listed = runs::ListBatch(store->get(), batch);
  if (!listed.ok()) {
    spdlog::warn("the baseline's code ({}): {}", out.from, listed.status().message());
    return BaselineCode{};
  }
  add_specs(*listed);
  // That night's build stands for the baseline's only where the night reproduced the baseline: compared with it
  // and within its allowance on every metric of the case. Then what differs between that night and tonight is
  // all a regression tonight can come from; elsewhere (the night regressed too, or compared with another
  // baseline) the baseline's runs may have run other code, and the build is not known.
  const std::set<std::string> reproduced = CasesReproducingBaseline(store->get(), night->first, baseline);
  for (const auto& run : *listed) {
    const std::string name = run.key.CaseName();
    AddCaseBuild(&out.builds, name, reproduced.count(name) && run.execution ? run.execution->build : "");
  }
  return out;
}

void NightScheduler::TwinNight(const std::string& date, const regress::RegressResult& r,
                               const std::map<std::string, experiment::ExperimentSpec>& case_specs,
                               const std::map<std::string, std::vector<std::string>>& case_benches,
                               const CaseBuilds& case_builds, const regress::Baseline& baseline, regress::Json* health,
                               regress::Json* j) {
  const double baseline_created_unix_s = baseline.created_unix_s;
  bool checked = false;
  for (const auto& h : *health) checked = checked || h.contains("batch_id");
  if (!checked) return;
  // The benches' earlier nights from the store (the newest 1000 nights): their values, and each bench's first
  // check (the anchor after a restart).
  StoredHealth stored;
  {
    auto store = pool_->Acquire();
    auto loaded = store.ok() ? LoadStoredHealth(store->get(), date) : StatusOr<StoredHealth>(store.status());
    if (!loaded.ok()) {
      (*j)["twin_error"] = loaded.status().message();
      spdlog::error("night {}: the benches' stored health: {}", date, loaded.status().message());
      return;
    }
    stored = std::move(*loaded);
  }
  auto& history = stored.values;
  auto& first = stored.first_check;
  for (auto& h : *health) {
    if (!h.contains("batch_id")) continue;
    const std::string bench = h["bench"].get<std::string>();
    const auto f = first.find(bench);
    const auto moved = stored.anchor.find(bench);
    const StoredAnchor* stored_anchor = moved == stored.anchor.end() ? nullptr : &moved->second;
    const gap::SessionValues tonight =
        f == first.end() ? twins_.Identify(bench, date, h["batch_id"].get<std::int64_t>(), "", 0)
                         : twins_.Identify(bench, date, h["batch_id"].get<std::int64_t>(), f->second.first,
                                           f->second.second, stored_anchor);
    h["values"] = regress::Json::parse(gap::SessionValuesJson(tonight));
    if (twins_.AnchorMovedTonight(bench)) {
      // The anchor moved to a better basin tonight: every earlier night identified again from it, kept in this
      // night's record (the store's older records stay as they were; LoadStoredHealth reads these in their place).
      regress::Json again = regress::Json::array();
      for (auto& v : twins_.Reidentify(bench, date, stored.checks[bench])) {
        again.push_back(regress::Json::parse(gap::SessionValuesJson(v)));
        if (v.error.empty()) history[bench][v.name] = std::move(v);
      }
      h["reidentified"] = std::move(again);
      h["anchor_refit"] = StoredAnchorJson(twins_.AnchorOf(bench));
    }
    if (!tonight.error.empty()) spdlog::warn("night {}: health check of {} not identified: {}", date, bench, tonight.error);
    std::vector<gap::SessionValues> past;
    for (const auto& [d, v] : history[bench]) past.push_back(v);
    if (past.empty()) {
      h["tracking"] = "the bench's first checked night: its reference starts here";
      continue;
    }
    auto t = twins_.Track(past, tonight);
    if (!t.ok()) {
      h["tracking"] = t.status().message();
      continue;
    }
    twins_.SetFlags(bench, t->flags);
    const auto tj = regress::Json::parse(gap::TrackingJson(*t));
    h["tracked_nights"] = t->sessions.size();
    h["flags"] = tj["flags"];
    for (const auto& flag : t->flags)
      spdlog::info("night {}: bench {}: {} {} {:+.2f} % since {} (flagged {})", date, bench, flag.parameter,
                   flag.direction, 100.0 * flag.change_relative, flag.since, flag.session);
  }
  if (r.regressed()) {
    // Each bench's valve when the baseline was measured (service/bench_health.h, BaselineNight).
    for (const auto& h : *health) {
      if (!h.contains("batch_id")) continue;
      const std::string bench = h["bench"].get<std::string>();
      const auto night = BaselineNight(stored.checks[bench], baseline_created_unix_s);
      twins_.UseBaselineNight(bench, night ? night->first : "", night ? night->second.batch_id : 0);
    }
    (*j)["cause"] =
        twins_.Attribute(r, case_specs, case_benches, BaselineCodeOf(baseline, stored.suites), case_builds);
    spdlog::info("night {}: cause {}: {}", date, (*j)["cause"].value("verdict", ""),
                 (*j)["cause"].value("reason", ""));
  }
}

}  // namespace vb::server
