// A valve tracked session by session (issue 38, gap/track.h, docs/track.md): the detector's statistics on draws
// of its own (false-alarm rate against the target, detection delay of steps and drifts), and the whole chain on a
// series of synthetic switch-on sessions (identification, warm starts, the flag) through benchctl track.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <random>
#include <string>

#include <sys/wait.h>
#include <unistd.h>

#include "gap/dataset.h"
#include "gap/switch_on_synth.h"
#include "gap/track.h"
#include "model/params.h"

namespace vb::gap {
namespace {

namespace fs = std::filesystem;

TEST(TrackStatistics, CusumIntervalMeetsItsRunLength) {
  const double h = CusumInterval(0.5, 20000.0);
  EXPECT_NEAR(CusumArl(0.0, 0.5, h) / 2.0, 20000.0, 1.0);
  EXPECT_GT(h, 8.0);
  EXPECT_LT(h, 10.0);
  // A 3-sigma step is flagged within 5 sessions on average at this interval (the issue's delay).
  EXPECT_LT(CusumArl(3.0, 0.5, h), 5.0);
}

TEST(TrackStatistics, SelfStartingZIsNormalForALongReferenceAndShrinksForAShortOne) {
  // n = 1000: t is nearly normal, z ~ d / (s sqrt(1 + 1/n)).
  EXPECT_NEAR(SelfStartingZ(2.0, 1.0, 1000), 2.0 / std::sqrt(1.001), 0.01);
  // n = 3 (2 degrees of freedom): a deviation of 4 spreads is far less surprising.
  const double z3 = SelfStartingZ(4.0, 1.0, 3);
  EXPECT_GT(z3, 1.5);
  EXPECT_LT(z3, 2.6);
  EXPECT_NEAR(SelfStartingZ(-4.0, 1.0, 3), -z3, 1e-12);
  EXPECT_TRUE(std::isfinite(SelfStartingZ(1e6, 1.0, 3)));
}

// In-control series: values N(mu, s^2) with the identification's sigma s given (as Gauss-Newton would).
TrackedParameter Series(std::mt19937& rng, int sessions, double shift_from, double step_sigma, double drift_sigma) {
  std::normal_distribution<double> n01;
  TrackedParameter p;
  p.name.push_back('R');
  const double mu = 40.0, s = 0.05;
  for (int j = 0; j < sessions; ++j) {
    TrackedValue v;
    double shift = 0.0;
    if (j >= shift_from) shift = step_sigma + drift_sigma * (j - shift_from + 1);
    v.value = mu + s * (n01(rng) + shift);
    v.sigma = s;
    p.sessions.push_back(v);
  }
  return p;
}

// How many of `series` in-control series of 60 sessions (Series) the detector flags, with the identification's
// sigma given as `own_sigma_factor` times the values' (NaN: none given).
int FlaggedInControl(std::mt19937& rng, int series, const TrackOptions& o, double own_sigma_factor = 1.0) {
  int flagged = 0;
  for (int i = 0; i < series; ++i) {
    auto p = Series(rng, 60, 1e9, 0.0, 0.0);
    for (auto& v : p.sessions) v.sigma *= own_sigma_factor;
    TrackParameter(&p, o);
    flagged += p.flagged >= 0;
  }
  return flagged;
}

// The false-alarm rate on draws (seed fixed before looking): with a target run length of 200 sessions per
// parameter, 57 monitored sessions flag a series with probability about 1 - exp(-57/200) = 0.25 (the run length
// is close to geometric); 2000 series give that to +-0.02 (1 sigma). The band is 4 sigma wide each way, plus the
// screening's small bias.
TEST(TrackStatistics, FalseAlarmRateMatchesTheTarget) {
  std::mt19937 rng(38001);
  TrackOptions o;
  o.target_arl0_sessions = 200.0;
  const int series = 2000;
  const double rate = static_cast<double>(FlaggedInControl(rng, series, o)) / series;
  std::printf("false-alarm rate at ARL0 200 over 57 sessions: %.3f (expected about 0.25)\n", rate);
  EXPECT_GT(rate, 0.15);
  EXPECT_LT(rate, 0.36);
  // At the default target (20000) the same draws flag almost nothing: about 500 x 57 / 20000 = 1.4 expected.
  const int strict = FlaggedInControl(rng, 500, TrackOptions{});
  std::printf("series flagged at ARL0 20000: %d of 500\n", strict);
  EXPECT_LE(strict, 8);
}

// The identification's sigma is an estimate, not a known sigma: on the independent plant's clean benches it is 0.1
// to 10 times the nights' scatter (docs/track.md). Draws (seed fixed before looking) whose given sigma is 0.8 of
// the values' true one: where it is above a short reference's scatter it sets the spread, and taken as known (a
// normal deviate, the detector before 2026-11-30) it flagged 0.41 of the series at a target of 0.25 (a guard of
// 5); as a t with the reference's degrees of freedom, 0.30 (0.36 with a guard of 5; the rest is the guard's,
// TrackOptions::guard_sessions).
TEST(TrackStatistics, AnUnderstatedOwnSigmaDoesNotRaiseTheFalseAlarmRate) {
  std::mt19937 rng(38004);
  TrackOptions o;
  o.target_arl0_sessions = 200.0;
  const int series = 2000;
  const double rate = static_cast<double>(FlaggedInControl(rng, series, o, 0.8)) / series;
  std::printf("false-alarm rate at ARL0 200 over 57 sessions, own sigma 0.8 of the true one: %.3f (expected about "
              "0.25)\n", rate);
  EXPECT_LT(rate, 0.33);
}

// A screen that keeps a session with a large z out of the reference feeds on itself: a short reference whose
// scatter is small by chance makes the next sessions' z large, and screened out they cannot widen it. Normal
// values with no own sigma, a guard of one session (Hawkins' chart, exact for normal values): at the default
// target the CUSUM itself flags about 0.22 % of 57-session series (simulated; 22 of 10000). The screen at |z| 3
// (before 2026-11-30) flagged about 0.8 %; at 4 (gap/track.cc, kJoin_z) it stays the CUSUM's own. Seed fixed
// before looking; the bound is the expected count plus 5 Poisson sigma.
TEST(TrackStatistics, TheReferencesScreenDoesNotTrapAShortReference) {
  std::mt19937 rng(38005);
  TrackOptions o;
  o.guard_sessions = 1;
  const int series = 10000;
  const int flagged = FlaggedInControl(rng, series, o, NAN);
  std::printf("normal values, guard 1, default target: %d of %d series flagged (about 22 expected)\n", flagged,
              series);
  EXPECT_LE(flagged, 45);
}

// A step of 3 sigma at session 20 and a drift of 0.25 sigma per session from session 15 (it reaches 3 sigma at
// session 26): flagged within 5 sessions of reaching 3 sigma in at least 80 % (the step; 85 % measured) and 90 %
// (the drift) of 500 draws, never before the change in more than 3 %. The step's share is the guard band's
// trade (TrackOptions::guard_sessions): a guard of 5 sessions flagged 92 % of these steps in time, at two to
// four times the in-control rate on the independent plant's values.
TEST(TrackStatistics, StepsAndDriftsAreFlaggedWithinFiveSessionsOfThreeSigma) {
  std::mt19937 rng(38002);
  TrackOptions o;
  for (const auto& [step, drift, from, at3] : {std::tuple{3.0, 0.0, 20, 20}, std::tuple{0.0, 0.25, 15, 26}}) {
    int in_time = 0, early = 0;
    const int series = 500;
    for (int i = 0; i < series; ++i) {
      auto p = Series(rng, 45, from, step, drift);
      TrackParameter(&p, o);
      if (p.flagged >= 0 && p.flagged < from) ++early;
      else if (p.flagged >= from && p.flagged <= at3 + 5) ++in_time;
    }
    std::printf("step %.2g drift %.2g: %d of %d flagged within 5 sessions of 3 sigma, %d before the change\n", step, drift,
                in_time, series, early);
    EXPECT_GE(in_time, step > 0.0 ? 400 : 450) << "step " << step << " drift " << drift;
    EXPECT_LE(early, 15);
  }
}

// Outliers: an identification that lands now and then in a neighbouring optimum gives a value far off its
// scatter (on the independent plant's clean benches 0.8 % of the values lie beyond 8 robust sigma). Draws
// (seed fixed before looking) of 60 in-control sessions where each value is, with probability 3 %, 10 sigma off
// either way: the plain CUSUM is carried past h by such sessions, the clipped one (the default) only when four
// come close together or two of one sign in a row (Lucas & Crosier's rule: 56 pairs x 0.03^2 / 2 = 2.5 % of the
// series, about 13 of 500, plus about as many from the clip alone); a 3-sigma step is still flagged within 5
// sessions in more than half the draws (the clip is at 3 sigma; the outliers that join the first reference, before
// it is long enough to screen them, widen its spread: 59 % measured, 73 % with the screen at 3 and a guard of 5,
// at the price in docs/track.md), and a gross one (10 sigma) within three (the clip alone takes four).
TEST(TrackStatistics, AnOutlyingSessionDoesNotFlagAndAStepStillDoes) {
  std::mt19937 rng(38003);
  std::uniform_real_distribution<double> u01;
  TrackOptions clipped, plain;
  plain.winsor_z = std::numeric_limits<double>::infinity();
  int flagged_clipped = 0, flagged_plain = 0, step_in_time = 0, step_in_time_plain = 0;
  const int series = 500;
  for (int i = 0; i < series; ++i) {
    for (const double step : {0.0, 3.0}) {
      auto p = Series(rng, 60, step > 0 ? 20 : 1e9, step, 0.0);
      for (int j = 0; j < 60; ++j)
        if (u01(rng) < 0.03) p.sessions[j].value += (u01(rng) < 0.5 ? -10.0 : 10.0) * p.sessions[j].sigma;
      auto q = p;
      TrackParameter(&p, clipped);
      TrackParameter(&q, plain);
      if (step > 0) {
        step_in_time += p.flagged >= 20 && p.flagged <= 25;
        step_in_time_plain += q.flagged >= 20 && q.flagged <= 25;
        continue;
      }
      flagged_clipped += p.flagged >= 0;
      flagged_plain += q.flagged >= 0;
    }
  }
  std::printf("3 %% outliers at 10 sigma: %d of %d series flagged plain, %d clipped; a 3-sigma step flagged in time in "
              "%d clipped, %d plain\n", flagged_plain, series, flagged_clipped, step_in_time, step_in_time_plain);
  EXPECT_GT(flagged_plain, 3 * flagged_clipped + 20);
  EXPECT_LE(flagged_clipped, 40);
  // The outliers that enter the first reference widen its spread, clipped or not: the clip costs no step.
  EXPECT_GE(step_in_time, step_in_time_plain - 15);
  EXPECT_GE(step_in_time, 0.5 * series);
  int second = 0;
  for (int i = 0; i < 200; ++i) {
    auto p = Series(rng, 40, 20, 10.0, 0.0);
    TrackParameter(&p, clipped);
    second += p.flagged >= 20 && p.flagged <= 22;
  }
  // The clip alone needs four sessions (3 x 2.5 < h); the self-starting z of a 10-sigma step is about 4.5.
  EXPECT_GE(second, 190) << "a 10-sigma step from index 20 flagged within its first three sessions";
}

TEST(TrackStatistics, ProjectsTheCrossingOfADeclaredLimit) {
  TrackedParameter p;
  p.name.push_back('R');
  for (int j = 0; j < 20; ++j) p.sessions.push_back({40.0 + (j >= 10 ? 0.5 * (j - 9) : 0.01 * (j % 3)), 0.01});
  TrackOptions o;
  o.limits["R"] = 50.0;
  TrackParameter(&p, o);
  ASSERT_GE(p.flagged, 10);
  EXPECT_EQ(p.direction, "up");
  EXPECT_NEAR(p.drift_per_session, 0.5, 0.01);
  // 40 + 0.5 (j - 9) = 50 at j = 29: session number 30.
  EXPECT_NEAR(p.projected_crossing, 30.0, 0.2);
}

// ---- the whole chain on synthetic sessions ---------------------------------------------------------------------

model::PlantParams Valve() {
  model::PlantParams p = *model::Preset("taghizadeh2009");
  p.R_ohm = 62.0;
  p.N_turns = 1332.0;
  p.mu_r = 90.0;
  p.x_max_m = 0.25e-3;
  p.x_t_m = 0.32e-3;
  p.k_N_per_m = 4000.0;
  p.delta_m = 0.49e-3;
  p.m_kg = 0.006;
  p.b_N_s_per_m = 0.5;
  p.A1_m2 = 20e-6;
  p.A2_m2 = 24e-6;
  p.effects.eddy_R_p_ohm = 1500.0;
  return p;
}

std::string Shell(const std::string& cmd, int* rc) {
  std::string out;
  FILE* f = ::popen(cmd.c_str(), "r");
  if (f == nullptr) return out;
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) out.append(buf, n);
  const int st = ::pclose(f);
  *rc = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return out;
}

// A valve whose closed-to-open inductance ratio L1 / L0 is above two thirds of what the family's held gap allows
// (a high-permeability core, mu_r 4000: about 4.9 of at most 5.7) is identified from scratch at its noise floor,
// then identified again from that end on the same session (what every later night does): the fit does not get
// worse. L1's box (which kept L1 < r_max L0 for every L0 in L0's box) moved such a point off its own optimum:
// first on every warm start (docs/track.md, step 1: 25.6 mA), then, with the warm start fixed, still in stage 3
// and the polish from scratch (19.4 mA; L1 is now searched as its ratio to L0, docs/real-data.md "Seventh round").
TEST(TrackSessions, AValveNearTheHeldGapsRatioIsIdentifiedAtItsNoiseAndAWarmStartKeepsIt) {
  const fs::path dir = fs::temp_directory_path() / ("vb_track_warm_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  model::PlantParams truth = Valve();
  truth.mu_r = 4000.0;
  truth.N_turns = 770.0;
  truth.x_t_m = 0.4e-3;
  truth.x_max_m = 0.33e-3;
  std::vector<SwitchOnRunPlan> runs;
  for (double bar : {1.0, 2.5, 4.0}) runs.push_back({"on_" + std::to_string(static_cast<int>(bar * 10)), 24.0, bar * 1e5, -1.0, ""});
  runs.push_back({"on_20V", 20.0, 3e5, -1.0, ""});
  ScopeChain scope;
  scope.seed = 7;
  ASSERT_TRUE(WriteSwitchOnSession(dir.string(), truth, runs, scope, "bench-a").ok());
  auto ds = LoadDataset(dir.string());
  ASSERT_TRUE(ds.ok()) << ds.status().message();
  const model::PlantParams family = *model::Preset("taghizadeh2009");
  TrackOptions o;
  auto first = IdentifyForTracking(*ds, family, nullptr, o);
  ASSERT_TRUE(first.ok()) << first.status().message();
  const double ratio = first->fitted.at("L1") / first->fitted.at("L0");
  const double r_max = (family.x_t_m - family.x_min_m) / (family.x_t_m - family.x_max_m);
  std::printf("anchor: fit %.3f mA, noise floor %.3f mA, L1/L0 %.2f (r_max %.2f)\n", 1e3 * first->fit_rmse_A,
              1e3 * first->noise_floor_A, ratio, r_max);
  ASSERT_GT(ratio, 0.98 * r_max / 1.5) << "the case this test is about: L1 / L0 above L1's box bound";
  // In the family, from scratch: within kReferenceIdentified (3x) of the noise floor, where the diagnosis trusts it.
  EXPECT_LE(first->fit_rmse_A, kReferenceIdentified * first->noise_floor_A);
  // The valves another recording could have given (the replay's repeatability, server/bench_twin.cc): drawn from
  // the white-noise covariance, so R's spread over them is its sigma_white (16 draws: within a factor 2).
  ASSERT_GE(first->repeatability_draws.size(), static_cast<std::size_t>(kRepeatabilityDraws / 2));
  double sum2 = 0.0;
  for (const auto& d : first->repeatability_draws) sum2 += std::pow(std::log(d.R_ohm / first->plant.R_ohm), 2);
  const double r_spread = std::sqrt(sum2 / first->repeatability_draws.size());
  double r_white = NAN;
  for (const auto& d : first->determined)
    if (d.name == "R") r_white = d.sigma_white / d.value;
  std::printf("R over the repeatability draws: %.3g relative, sigma_white %.3g\n", r_spread, r_white);
  EXPECT_GT(r_spread, r_white / 2.0);
  EXPECT_LT(r_spread, r_white * 2.0);
  auto again = IdentifyForTracking(*ds, family, &*first, o);
  ASSERT_TRUE(again.ok()) << again.status().message();
  std::printf("warm start from it: fit %.3f mA\n", 1e3 * again->fit_rmse_A);
  EXPECT_LE(again->fit_rmse_A, 1.01 * first->fit_rmse_A);
  fs::remove_all(dir);
}

// The anchor's basin check (IdentifyAnchored, docs/track.md step 1) on a scripted identifier: two basins, "A" (a
// fit of 10 mA, where the first session lands from scratch) and "B" (5 mA). Sessions warm-started from an A
// anchor stay in A except sessions 3 and 5, which escape to B; any session started from a B end lands in B. The
// check refits session 0 from the best session's end (3: the first of the best), finds 10 -> 5 mA (over the
// 10 % it asks), and identifies every session again from that B anchor: all of them end in B, in one round.
// Where the refit gains less than 10 % (a second basin that is not better), nothing is identified again.
TEST(TrackSessions, TheAnchorMovesToABetterBasinAndEverySessionFollows) {
  auto basin = [](char b, double fit_A) {
    MovingIdentification id;
    id.device = std::string(1, b);
    id.fit_rmse_A = fit_A;
    id.noise_floor_A = 1e-3;
    return id;
  };
  const std::vector<std::string> names = {"n1", "n2", "n3", "n4", "n5", "n6"};
  for (double b_fit_A : {5e-3, 9.5e-3}) {
    std::vector<std::pair<std::size_t, std::string>> calls;  // (session, anchor's basin or "scratch")
    const SessionIdentifier identify = [&](std::size_t i, const MovingIdentification* anchor) {
      calls.emplace_back(i, anchor ? anchor->device : "scratch");
      if (!anchor) return StatusOr<MovingIdentification>(basin('A', 10e-3));
      if (anchor->device == "B" || i == 3 || i == 5) return StatusOr<MovingIdentification>(basin('B', b_fit_A));
      return StatusOr<MovingIdentification>(basin('A', 10e-3));
    };
    std::vector<std::string> progress;
    const auto ids = IdentifyAnchored(names, identify, [&](const std::string& s) { progress.push_back(s); });
    ASSERT_EQ(ids.size(), names.size());
    std::string ends;
    for (const auto& id : ids) {
      ASSERT_TRUE(id.ok());
      ends += id->device;
    }
    if (b_fit_A < 0.9 * 10e-3) {
      EXPECT_EQ(ends, "BBBBBB") << "every session again from the refitted anchor";
      // the first pass (6), the refit of session 0 from session 3's end, the second pass (6) from a B anchor, and
      // the second round's refit check finds the first session already the best: no more calls.
      ASSERT_EQ(calls.size(), 13u);
      EXPECT_EQ(calls[0], std::make_pair(std::size_t{0}, std::string("scratch")));
      EXPECT_EQ(calls[6], std::make_pair(std::size_t{0}, std::string("B")));
      for (std::size_t k = 7; k < 13; ++k) EXPECT_EQ(calls[k].second, "B") << k;
      bool said = false;
      for (const auto& s : progress) said = said || s.find("anchor: n1 refitted from n4's end, 10") == 0;
      EXPECT_TRUE(said) << "the progress says the anchor moved and from where";
    } else {
      EXPECT_EQ(ends, "AAABAB") << "a refit that gains under 10 % keeps the first pass";
      EXPECT_EQ(calls.size(), 7u) << "the first pass and one refit";
    }
  }
}

// The server's basin check each night (server/bench_twin.h): tonight's end is tried on the anchor's session only
// when tonight fits its own runs better relative to its noise by the margin asked, and the refit replaces the
// anchor only when it lowers the anchor's fit by more than 10 %.
TEST(TrackSessions, BetterAnchorRefitsOnlyWhenAnotherNightFitsBetterAndTheRefitGainsATenth) {
  auto fit = [](double fit_A, double noise_A) {
    MovingIdentification id;
    id.fit_rmse_A = fit_A;
    id.noise_floor_A = noise_A;
    return id;
  };
  const MovingIdentification anchor = fit(10e-3, 1e-3);  // 10x its noise
  int refits = 0;
  auto refit_to = [&](double fit_A) {
    return [&refits, fit_A](const MovingIdentification* start) -> StatusOr<MovingIdentification> {
      ++refits;
      MovingIdentification r;
      r.fit_rmse_A = fit_A;
      r.noise_floor_A = 1e-3;
      r.device = start != nullptr ? "from tonight" : "scratch";
      return r;
    };
  };
  // Tonight at 5x its noise: tried, and a refit to 6 mA (40 % better) is the new anchor, from tonight's end.
  auto moved = BetterAnchor(anchor, fit(10e-3, 2e-3), 1.1, refit_to(6e-3));
  ASSERT_TRUE(moved.has_value());
  EXPECT_EQ(moved->fit_rmse_A, 6e-3);
  EXPECT_EQ(moved->device, "from tonight");
  EXPECT_EQ(refits, 1);
  // A refit that gains under a tenth keeps the anchor.
  EXPECT_FALSE(BetterAnchor(anchor, fit(10e-3, 2e-3), 1.1, refit_to(9.5e-3)).has_value());
  EXPECT_EQ(refits, 2);
  // Tonight within the margin (9.5x against 10x, a gain of 1.05 < 1.1), or worse: no refit tried at all.
  EXPECT_FALSE(BetterAnchor(anchor, fit(9.5e-3, 1e-3), 1.1, refit_to(1e-3)).has_value());
  EXPECT_FALSE(BetterAnchor(anchor, fit(20e-3, 1e-3), 1.1, refit_to(1e-3)).has_value());
  EXPECT_EQ(refits, 2);
  // A refit that fails keeps the anchor.
  EXPECT_FALSE(BetterAnchor(anchor, fit(1e-3, 1e-3), 1.0, [](const MovingIdentification*) {
                 return StatusOr<MovingIdentification>(Status::Internal("broke"));
               }).has_value());
}

// Eight nights of one valve, each recorded at declared supplies and pressures a little off the nominal ones (as
// a bench's are night to night), with the coil's resistance 4 % higher from night 6 (a corroded connector): R is
// flagged within 3 nights (the reference is nights 1-5, a t with 4 degrees of freedom, and z enters clipped at 3
// unless two nights in a row are beyond it: even a change of many sigma needs two or three nights), the first
// flag is R, and nothing is flagged before night 6.
TEST(TrackSessions, AResistanceStepIsFlaggedAsRAndNothingBefore) {
  const fs::path root = fs::temp_directory_path() / ("vb_track_" + std::to_string(::getpid()));
  fs::remove_all(root);
  std::mt19937 rng(38003);
  std::normal_distribution<double> jitter(0.0, 0.01);
  std::string dirs;
  for (int night = 1; night <= 8; ++night) {
    model::PlantParams truth = Valve();
    if (night >= 6) truth.R_ohm *= 1.04;
    std::vector<SwitchOnRunPlan> runs;
    const double v = 24.0 * (1.0 + jitter(rng));
    for (double bar : {1.0, 2.5, 4.0}) {
      const double p = bar * 1e5 * (1.0 + jitter(rng));
      std::string id = "on_";
      id += std::to_string(static_cast<int>(bar * 10));
      runs.push_back({id, v, p, -1.0, ""});
    }
    runs.push_back({"on_20V", 20.0 * (1.0 + jitter(rng)), 3e5, -1.0, ""});
    ScopeChain scope;
    scope.seed = 100 + night;
    std::string name = "night";
    name += std::to_string(night);
    const fs::path dir = root / name;
    ASSERT_TRUE(WriteSwitchOnSession(dir.string(), truth, runs, scope, "bench-a").ok());
    dirs.append(" ").append(dir.string());
  }
  int rc = -1;
  std::string cmd = VB_BENCHCTL;
  cmd.append(" track --json --limit R=70").append(dirs).append(" 2>/dev/null");
  const std::string out = Shell(cmd, &rc);
  EXPECT_EQ(rc, 1) << "exit 1: a parameter flagged";
  const auto j = nlohmann::json::parse(out, nullptr, false);
  ASSERT_FALSE(j.is_discarded()) << out;
  ASSERT_TRUE(j.contains("flags"));
  ASSERT_FALSE(j["flags"].empty()) << j.dump(1);
  const auto& first = j["flags"][0];
  EXPECT_EQ(first["parameter"], "R") << j["flags"].dump(1);
  const std::string at = first["session"];
  EXPECT_TRUE(at == "night6" || at == "night7" || at == "night8") << at;
  EXPECT_EQ(first["since"], "night6");
  for (const auto& f : j["flags"]) {
    const std::string s = f["session"];
    EXPECT_GE(std::stoi(s.substr(5)), 6) << "a flag before the change: " << f.dump();
  }
  EXPECT_NEAR(first["change_relative"].get<double>(), 0.04, 0.01);
  // The declared limit: a step with no drift after it has no crossing to project.
  for (const auto& p : j["parameters"])
    if (p["parameter"] == "R") {
      EXPECT_EQ(p["limit"], 70.0);
      EXPECT_TRUE(p["projected_crossing_session"].is_null()) << p.dump();
    }
  EXPECT_EQ(j["detector"]["winsor_z"], 3.0) << j["detector"].dump();
  EXPECT_EQ(j["detector"]["reference_min_sessions"], 5) << j["detector"].dump();
  EXPECT_EQ(j["detector"]["guard_sessions"], 3) << j["detector"].dump();
  EXPECT_EQ(j["detector"]["reference_screen_z"], 4.0) << j["detector"].dump();
  // A reference of fewer than 2 sessions: refused before anything is identified, naming the option.
  int bad_rc = -1;
  const std::string bad = Shell(std::string(VB_BENCHCTL) + " track --reference 1" + dirs + " 2>&1", &bad_rc);
  EXPECT_EQ(bad_rc, 2) << bad;
  EXPECT_NE(bad.find("--reference: at least 2 sessions form a reference (got 1)"), std::string::npos) << bad;
  if (std::getenv("VB_KEEP_SYNTHETIC") == nullptr) fs::remove_all(root);
}

}  // namespace
}  // namespace vb::gap
