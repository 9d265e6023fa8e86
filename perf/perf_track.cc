// A simulated lab for the bench twin (issue 38, docs/track.md): benches whose valves are drawn from the
// independent plant (perf/independent_valve.h: a B-H table core, an eddy ladder, Stribeck friction, a flow-
// dependent pressure force; no code shared with model/), one health check per night at conditions a little
// off the nominal ones (four switch-ons and the server's hold: gap/hold.h), and on every second bench a change of its own kind from a night drawn at random:
//   resistance: R + 0.25 % per night (a connector corroding, a winding aging);
//   spring:     k and the preload - 1 % per night (a spring relaxing);
//   turns:      N - 2 % at once (shorted turns).
// Each bench's series goes through gap::TrackSessions; printed per bench: the first flag (night, parameter), the
// night the change reaches 3 sigma of the tracked parameter it should show in, the delay; and for the lab: false
// flags per clean bench-night and changes flagged in time, with Wilson intervals.
//   perf_track [--benches 6] [--nights 60] [--seed 38] [--only BENCH] [--clean] [--report] [--verbose]
//              [--previous-detector] [--values-out FILE | --values-in FILE [--resample N [--length L]]
//              [--contradiction N]]
// --clean: every bench keeps its valve (the in-control draws the detector's false-alarm rate is measured on).
// --values-out FILE: each session's identified values, one line per session ("bench kind from JSON"), so the
// detector can be run again on them without identifying (--values-in FILE: the benches, kinds and change nights
// are read from the file; --benches, --nights, --seed and --clean are then the file's).
// --previous-detector: the detector before issue 38's outlier round (no clip, a reference of 3, a guard of 5), for
//   comparison; the own sigma and the reference's screen as today (docs/track.md, "What raised the in-control rate").
// --resample N (with --values-in): the detector alone, calibrated on draws. Every tracked parameter of every clean
// bench in the file is a pool of (value, sigma) pairs as the identification gave them night after night, with its
// outliers; N series of --length sessions are drawn from each pool (with replacement, seeded by --seed) and run
// through the detector in several variants (the clip on z, the reference's first length). Printed per variant:
// in-control series flagged (against the target's expected rate), and a step of 3 pool sigma at session 20 and
// a drift of 0.25 pool sigma per session from session 15 (3 sigma at 27) flagged within 5 sessions of 3 sigma,
// and before the change. First it prints the pools' tails: the values beyond 3 and 8 robust sigma of their pool.
// --contradiction N (with --values-in): the rule that calls an R flag "not the winding" when R_hold has not moved,
// on N draws per clean bench of its nights' (R, R_hold) pairs with a step on R alone or on both (Contradiction).
// The draws' seed is --seed; the files are made with --values-out.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <limits>
#include <map>
#include <sstream>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "gap/track.h"
#include "model/params.h"
#include "perf/independent_valve.h"

namespace {

struct Wilson {
  double lo, hi;
};
Wilson Interval(int k, int n) {
  if (n == 0) return {0, 1};
  const double z = 1.96, p = static_cast<double>(k) / n, d = 1 + z * z / n;
  const double c = (p + z * z / (2 * n)) / d, h = z * std::sqrt(p * (1 - p) / n + z * z / (4.0 * n * n)) / d;
  return {std::max(0.0, c - h), std::min(1.0, c + h)};
}

vb::gap::Dataset Session(const vb::perf::IndependentValve& v, int night, std::mt19937& rng) {
  std::normal_distribution<double> jitter(0.0, 0.01);
  const std::size_t on = static_cast<std::size_t>(std::llround(1e-4 / v.dt_s));
  const std::size_t n = on + static_cast<std::size_t>(std::llround(0.01 / v.dt_s)) + 1;
  vb::gap::Dataset ds;
  ds.format = vb::gap::kFormatValveRuns2;
  ds.model = "taghizadeh2009";
  ds.device = "bench";
  ds.sensor.noise_A = v.noise_A;
  ds.sensor.averaged = v.averaged;
  ds.sensor.adc_lsb_A = v.lsb_A;
  const double V = v.supply_V * (1.0 + jitter(rng));
  struct Plan {
    double V, bar;
  };
  const Plan plans[] = {{V, 1.0}, {V, 2.5}, {V, 4.0}, {0.85 * V, 3.0}};
  int r = 0;
  for (const Plan& p : plans) {
    vb::gap::RunData run;
    run.id = "night" + std::to_string(night) + "_" + std::to_string(r);
    run.supply_V = p.V;
    run.supply_pressure_Pa = p.bar * 1e5 * (1.0 + jitter(rng));
    run.t_start_s = 2.0 * r++;
    run.split = vb::Split::kFit;
    run.sample_period_s = v.dt_s;
    const auto truth = vb::perf::SimulateSwitchOn(v, run.supply_V, run.supply_pressure_Pa, n, on);
    run.i_A = vb::perf::Capture(v, truth, on, rng);
    for (std::size_t k = 0; k < n; ++k) {
      run.t_s.push_back(static_cast<double>(k) * v.dt_s);
      run.gate.push_back(k >= on ? 1 : 0);
    }
    ds.runs.push_back(std::move(run));
  }
  // The server's health check's hold (server/health_check.h defaults): a 5 ms baseline, the switch-on at the
  // night's supply and the highest pressure, then PWM at duty 0.5 and 1 kHz for 0.1 s, then the gate low for
  // 0.05 s (gap/hold.h measures R_hold and L_hold, and i_dropout from the release dip).
  vb::gap::RunData hold;
  hold.id = "night" + std::to_string(night) + "_hold";
  hold.supply_V = V;
  hold.supply_pressure_Pa = 4e5 * (1.0 + jitter(rng));
  hold.t_start_s = 2.0 * r;
  hold.split = vb::Split::kFit;
  hold.sample_period_s = v.dt_s;
  const auto rise = static_cast<std::size_t>(std::llround(5e-3 / v.dt_s));
  const std::size_t pull_in = rise + static_cast<std::size_t>(std::llround(0.01 / v.dt_s));
  const auto period = static_cast<std::size_t>(std::llround(1e-3 / v.dt_s));
  const std::size_t tail = pull_in + static_cast<std::size_t>(std::llround(0.1 / v.dt_s));
  const std::size_t hold_n = tail + static_cast<std::size_t>(std::llround(0.05 / v.dt_s)) + 1;
  for (std::size_t k = 0; k < hold_n; ++k) {
    hold.t_s.push_back(static_cast<double>(k) * v.dt_s);
    hold.gate.push_back(k < rise || k >= tail ? 0 : k < pull_in ? 1 : ((k - pull_in) % period) < period / 2 ? 1 : 0);
  }
  hold.i_A = vb::perf::Capture(v, vb::perf::SimulateGate(v, hold.supply_V, hold.supply_pressure_Pa, hold.gate), rise,
                               rng);
  ds.runs.push_back(std::move(hold));
  return ds;
}

// One tracked parameter of one clean bench: its (value, sigma) night after night.
struct Pool {
  std::string name;
  std::vector<std::pair<double, double>> draws;
  double sd = 0.0;  // the values' standard deviation (outliers included: what the tracker's spread estimates)
};

void Pools(const std::vector<vb::gap::SessionValues>& sessions, std::vector<Pool>* out) {
  std::map<std::string, Pool> by;
  for (const auto& s : sessions)
    for (const auto& d : s.determined)
      if (d.determined && std::isfinite(d.value)) {
        by[d.name].name = d.name;
        by[d.name].draws.push_back({d.value, d.sigma_white});
      }
  for (auto& [name, p] : by) {
    if (p.draws.size() < 20) continue;  // fewer values than that say little about the tails
    double m = 0.0, s2 = 0.0;
    for (const auto& d : p.draws) m += d.first / p.draws.size();
    for (const auto& d : p.draws) s2 += (d.first - m) * (d.first - m) / (p.draws.size() - 1.0);
    p.sd = std::sqrt(s2);
    if (p.sd > 0.0) out->push_back(std::move(p));
  }
}

// The pools' tails: each value against its pool's median in robust sigma (1.4826 x the median absolute deviation,
// the standard deviation of normal values), counted beyond 3 (normal values: 0.27 %) and beyond 8 (none).
// What the detector's clip and reference must live with (docs/track.md).
void PrintTails(const std::vector<Pool>& pools) {
  long n = 0, n3 = 0, n8 = 0;
  for (const Pool& p : pools) {
    std::vector<double> v;
    for (const auto& d : p.draws) v.push_back(d.first);
    auto median = [](std::vector<double> x) {
      std::sort(x.begin(), x.end());
      const std::size_t h = x.size() / 2;
      return x.size() % 2 ? x[h] : 0.5 * (x[h - 1] + x[h]);
    };
    const double med = median(v);
    std::vector<double> dev;
    for (double x : v) dev.push_back(std::abs(x - med));
    const double rs = 1.4826 * median(dev);
    if (!(rs > 0.0)) continue;
    for (double x : v) {
      const double z = std::abs(x - med) / rs;
      ++n, n3 += z > 3.0, n8 += z > 8.0;
    }
  }
  const Wilson w3 = Interval(static_cast<int>(n3), static_cast<int>(n));
  const Wilson w8 = Interval(static_cast<int>(n8), static_cast<int>(n));
  std::printf("tails: %ld values; beyond 3 robust sigma of their pool's median %.2f %% [%.2f, %.2f] (normal: 0.27 %%), "
              "beyond 8 %.2f %% [%.2f, %.2f]\n", n, n ? 100.0 * n3 / n : 0.0, 100 * w3.lo, 100 * w3.hi,
              n ? 100.0 * n8 / n : 0.0, 100 * w8.lo, 100 * w8.hi);
}

int Resample(const std::vector<Pool>& pools, int n, int length, unsigned seed, bool verbose) {
  struct Variant {
    const char* name;
    double winsor;
    int min_reference;
    double arl0;
    bool two_in_a_row = false;
    int guard = vb::gap::TrackOptions{}.guard_sessions;
  };
  const double inf = std::numeric_limits<double>::infinity();
  const Variant variants[] = {{"plain, ref 5", inf, 5, 2e4},
                              {"clip 3, ref 5", 3.0, 5, 2e4},
                              {"clip 3, ref 8", 3.0, 8, 2e4},
                              {"clip 3, ref 5, 2e5", 3.0, 5, 2e5},
                              {"clip 3 + 2 in a row, ref 5, guard 1", 3.0, 5, 2e4, true, 1},
                              {"clip 3 + 2 in a row, ref 5, guard 5", 3.0, 5, 2e4, true, 5},
                              {"clip 3 + 2 in a row, ref 5 (default)", 3.0, 5, 2e4, true}};
  const int step_at = 19, drift_from = 14;  // 0-based: sessions 20 and 15
  const double expected = 1.0 - std::exp(-(length - 3) / vb::gap::TrackOptions{}.target_arl0_sessions);
  std::printf("%zu pools (tracked parameters of clean benches), %d series of %d sessions each, seed %u\n",
              pools.size(), n, length, seed);
  PrintTails(pools);
  std::printf("%-38s %22s %22s %22s\n", "variant", "in-control flagged", "3-sigma step in time",
              "drift in time");
  for (const Variant& var : variants) {
    vb::gap::TrackOptions o;
    o.winsor_z = var.winsor;
    o.min_reference = var.min_reference;
    o.target_arl0_sessions = var.arl0;
    o.two_in_a_row = var.two_in_a_row;
    o.guard_sessions = var.guard;
    std::mt19937 rng(seed);
    std::map<std::string, std::pair<long, long>> by_name;  // in-control: flagged, series
    long series = 0, false_flags = 0, step_ok = 0, step_early = 0, step_late = 0, drift_ok = 0, drift_early = 0;
    for (const Pool& pool : pools) {
      std::uniform_int_distribution<std::size_t> pick(0, pool.draws.size() - 1);
      for (int k = 0; k < n; ++k) {
        // The first sessions without replacement: a reference of repeated draws would be tighter than any real
        // bench's first nights, and the false-alarm rate would be the resampling's.
        std::vector<std::pair<double, double>> draw = pool.draws;
        std::shuffle(draw.begin(), draw.end(), rng);
        draw.resize(std::min<std::size_t>(draw.size(), 8));
        while (static_cast<int>(draw.size()) < length) draw.push_back(pool.draws[pick(rng)]);
        for (int mode = 0; mode < 3; ++mode) {
          vb::gap::TrackedParameter p;
          p.name = pool.name;
          for (int j = 0; j < length; ++j) {
            double v = draw[j].first;
            if (mode == 1 && j >= step_at) v += 3.0 * pool.sd;
            if (mode == 2 && j >= drift_from) v += 0.25 * pool.sd * (j - drift_from + 1);
            vb::gap::TrackedValue tv;
            tv.value = v, tv.sigma = draw[j].second;
            p.sessions.push_back(tv);
          }
          vb::gap::TrackParameter(&p, o);
          if (mode == 0) false_flags += p.flagged >= 0, by_name[pool.name].first += p.flagged >= 0;
          if (mode == 0) by_name[pool.name].second += 1;
          if (mode == 1) step_early += p.flagged >= 0 && p.flagged < step_at,
                         step_ok += p.flagged >= step_at && p.flagged <= step_at + 5,
                         step_late += p.flagged > step_at + 5;
          if (mode == 2) drift_early += p.flagged >= 0 && p.flagged < drift_from,
                         drift_ok += p.flagged >= drift_from && p.flagged <= drift_from + 12 + 5;
        }
        ++series;
      }
    }
    auto cell = [&](long k, const char* extra) {
      const Wilson w = Interval(static_cast<int>(k), static_cast<int>(series));
      char b[64];
      std::snprintf(b, sizeof b, "%.4f [%.4f,%.4f]%s", static_cast<double>(k) / series, w.lo, w.hi, extra);
      return std::string(b);
    };
    std::printf("%-38s %22s %22s %22s   (early: step %ld, drift %ld; step later than in time %ld)\n", var.name,
                cell(false_flags, "").c_str(), cell(step_ok, "").c_str(), cell(drift_ok, "").c_str(), step_early,
                drift_early, step_late);
    if (verbose) {
      std::printf("   in control, by parameter:");
      for (const auto& [name, c] : by_name)
        std::printf(" %s %.3f", name.c_str(), static_cast<double>(c.first) / c.second);
      std::printf("\n");
    }
  }
  std::printf("expected in-control rate at the target run length (normal values): %.4f per series\n", expected);
  return 0;
}

// The rule that says an R flag is "not the winding" (gap/track.cc, TrackFlag::contradicted_by), on draws: each
// clean bench's nights that have both R and R_hold are a pool of pairs (one night's two values, as identified
// and measured together); n series of `length` nights are drawn from it (the first 8 without replacement), and a
// step of `size` times R's own standard deviation over the pool is added from session 20 to R alone (a change
// the winding did not make: the rule should say so) or to R and R_hold by the same fraction (the winding: it
// must not). Printed per size: the series whose R was flagged from session 20 on, and of those the share
// contradicted, with Wilson intervals; a winding's change contradicted is the rule's error.
int Contradiction(const std::map<int, std::vector<vb::gap::SessionValues>>& benches, int n, int length,
                  unsigned seed) {
  const int step_at = 19;  // 0-based: session 20
  std::printf("the R flag's contradiction by R_hold, on draws: %d series of %d sessions per clean bench, step at "
              "session 20, seed %u\n", n, length, seed);
  std::printf("%-10s %-8s %10s %28s\n", "step", "change", "R flagged", "said \"not the winding\"");
  for (const double size : {3.0, 6.0, 12.0}) {
    for (const bool winding : {false, true}) {
      std::mt19937 rng(seed);
      long flagged = 0, contradicted = 0, series = 0;
      for (const auto& [b, sessions] : benches) {
        struct Night {
          vb::gap::DeterminedValue R, R_hold;
        };
        std::vector<Night> pool;
        for (const auto& v : sessions) {
          Night night;
          int found = 0;
          for (const auto& d : v.determined)
            if (d.determined && std::isfinite(d.value)) {
              if (d.name == "R") night.R = d, found |= 1;
              if (d.name == "R_hold") night.R_hold = d, found |= 2;
            }
          if (found == 3) pool.push_back(night);
        }
        if (pool.size() < 20) continue;
        double m = 0.0, s2 = 0.0;
        for (const auto& x : pool) m += x.R.value / pool.size();
        for (const auto& x : pool) s2 += (x.R.value - m) * (x.R.value - m) / (pool.size() - 1);
        const double rel = size * std::sqrt(s2) / m;  // the step, relative
        std::uniform_int_distribution<std::size_t> pick(0, pool.size() - 1);
        for (int k = 0; k < n; ++k) {
          std::vector<Night> draw = pool;
          std::shuffle(draw.begin(), draw.end(), rng);
          draw.resize(std::min<std::size_t>(draw.size(), 8));
          while (static_cast<int>(draw.size()) < length) draw.push_back(pool[pick(rng)]);
          std::vector<vb::gap::SessionValues> values;
          for (int j = 0; j < length; ++j) {
            vb::gap::SessionValues v;
            v.name = "night" + std::to_string(j + 1);
            Night night = draw[j];
            if (j >= step_at) {
              night.R.value *= 1.0 + rel;
              if (winding) night.R_hold.value *= 1.0 + rel;
            }
            v.determined = {night.R, night.R_hold};
            values.push_back(std::move(v));
          }
          auto t = vb::gap::TrackValues(values, vb::gap::TrackOptions{});
          ++series;
          if (!t.ok()) continue;
          for (const auto& f : t->flags)
            if (f.parameter == "R" && f.session_index >= step_at) {
              ++flagged;
              contradicted += !f.contradicted_by.empty();
              break;
            }
        }
      }
      const Wilson w = Interval(static_cast<int>(contradicted), static_cast<int>(flagged));
      char size_s[32];
      std::snprintf(size_s, sizeof size_s, "%.0f R sd", size);
      std::printf("%-10s %-8s %6ld/%-6ld %12ld (%.3f [%.3f, %.3f])\n", size_s, winding ? "winding" : "R only",
                  flagged, series, contradicted, flagged ? static_cast<double>(contradicted) / flagged : 0.0, w.lo,
                  w.hi);
    }
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  int benches = 6, nights = 60;
  unsigned seed = 38;
  bool verbose = false, report = false;
  int only = -1;
  bool all_clean = false, previous = false;
  std::string values_out, values_in;
  int resample = 0, length = 60, contradiction = 0;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--benches") && i + 1 < argc) benches = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--nights") && i + 1 < argc) nights = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--seed") && i + 1 < argc) seed = static_cast<unsigned>(std::atoi(argv[++i]));
    else if (!std::strcmp(argv[i], "--verbose")) verbose = true;
    else if (!std::strcmp(argv[i], "--report")) report = true;
    else if (!std::strcmp(argv[i], "--only") && i + 1 < argc) only = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--clean")) all_clean = true;
    else if (!std::strcmp(argv[i], "--previous-detector")) previous = true;
    else if (!std::strcmp(argv[i], "--values-out") && i + 1 < argc) values_out = argv[++i];
    else if (!std::strcmp(argv[i], "--values-in") && i + 1 < argc) values_in = argv[++i];
    else if (!std::strcmp(argv[i], "--resample") && i + 1 < argc) resample = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--contradiction") && i + 1 < argc) contradiction = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--length") && i + 1 < argc) length = std::atoi(argv[++i]);
    else {
      std::fprintf(stderr,
                   "usage: perf_track [--benches N] [--nights N] [--seed S] [--only BENCH] [--clean] [--report]\n"
                   "                  [--verbose] [--previous-detector]\n"
                   "                  [--values-out FILE | --values-in FILE [--resample N [--length L]]]\n");
      return 2;
    }
  }
  auto family = vb::model::Preset("taghizadeh2009");
  if (!family.ok()) return 3;
  const char* const kinds[] = {"clean", "resistance", "clean", "spring", "clean", "turns"};
  // Each bench's identified sessions, its kind of change and the night it starts: identified here, or read back.
  struct Bench {
    std::string kind;
    int from = 0;
    std::vector<vb::gap::SessionValues> values;
  };
  std::map<int, Bench> read;
  if (!values_in.empty()) {
    std::ifstream in(values_in);
    if (!in) {
      std::fprintf(stderr, "perf_track: cannot read %s\n", values_in.c_str());
      return 2;
    }
    std::string line;
    for (int n = 1; std::getline(in, line); ++n) {
      std::istringstream ls(line);
      int b = -1, from = 0;
      std::string kind, json;
      ls >> b >> kind >> from;
      std::getline(ls >> std::ws, json);
      auto v = vb::gap::SessionValuesFromJson(json);
      if (b < 0 || !v.ok()) {
        std::fprintf(stderr, "perf_track: %s line %d: not \"bench kind from JSON\"\n", values_in.c_str(), n);
        return 2;
      }
      // A session name seen twice for one bench: files of several draws concatenated without renumbering their
      // benches would otherwise make one series of several valves (and a detector measured on it).
      for (const auto& seen : read[b].values)
        if (seen.name == v->name) {
          std::fprintf(stderr, "perf_track: %s line %d: bench %d has session %s twice (renumber the benches of "
                               "each file before concatenating)\n", values_in.c_str(), n, b, v->name.c_str());
          return 2;
        }
      read[b].kind = kind, read[b].from = from;
      read[b].values.push_back(std::move(*v));
    }
    benches = read.empty() ? 0 : read.rbegin()->first + 1;
  }
  if (contradiction > 0) {
    if (read.empty()) {
      std::fprintf(stderr, "perf_track: --contradiction needs --values-in FILE\n");
      return 2;
    }
    std::map<int, std::vector<vb::gap::SessionValues>> clean;
    for (const auto& [b, bench] : read)
      if (bench.kind == "clean") clean[b] = bench.values;
    return Contradiction(clean, contradiction, length, seed);
  }
  if (resample > 0) {
    if (read.empty()) {
      std::fprintf(stderr, "perf_track: --resample needs --values-in FILE\n");
      return 2;
    }
    std::vector<Pool> pools;
    for (const auto& [b, bench] : read)
      if (bench.kind == "clean") Pools(bench.values, &pools);
    return Resample(pools, resample, length, seed, verbose);
  }
  std::FILE* dump = values_out.empty() ? nullptr : std::fopen(values_out.c_str(), "w");
  if (!values_out.empty() && dump == nullptr) {
    std::fprintf(stderr, "perf_track: cannot write %s\n", values_out.c_str());
    return 2;
  }
  int clean_nights = 0, false_flags = 0, changes = 0, in_time = 0, named = 0, early = 0;
  std::printf("%-6s %-10s %5s %-34s %8s %6s %s\n", "bench", "change", "from", "first flag", "3-sigma", "delay", "ok");
  for (int b = 0; b < benches; ++b) {
    std::string kind;
    int from = 0;
    std::vector<vb::gap::SessionValues> values;
    vb::gap::TrackOptions o;
    if (previous)
      o.winsor_z = std::numeric_limits<double>::infinity(), o.two_in_a_row = false, o.min_reference = 3,
      o.guard_sessions = 5;
    if (verbose)
      o.progress = o.identify.progress = [](const std::string& l) { std::fprintf(stderr, "  %s\n", l.c_str()); };
    if (!values_in.empty()) {
      if (!read.count(b) || (only >= 0 && b != only)) continue;
      kind = read[b].kind, from = read[b].from, values = read[b].values;
    } else {
      std::mt19937 rng(seed * 1000u + static_cast<unsigned>(b));
      const vb::perf::IndependentValve base = vb::perf::DrawValve(rng);
      kind = all_clean ? "clean" : kinds[b % 6];
      from = std::uniform_int_distribution<int>(15, std::max(15, nights - 20))(rng);
      if (only >= 0 && b != only) continue;
      std::vector<vb::gap::TrackSession> sessions;
      for (int night = 1; night <= nights; ++night) {
        vb::perf::IndependentValve v = base;
        const int after = night - from + 1;  // nights into the change (<= 0: before)
        if (after > 0) {
          if (kind == "resistance") v.R_ohm *= 1.0 + 0.0025 * after;
          if (kind == "spring") {
            const double f = std::pow(0.99, after);
            v.k_N_per_m *= f;
            v.F0_N *= f;
          }
          if (kind == "turns") v.N *= 0.98;
        }
        sessions.push_back({"night" + std::to_string(night), Session(v, night, rng), {}});
      }
      auto identified = vb::gap::IdentifySessions(sessions, *family, o);
      if (!identified.ok()) {
        std::printf("%-6d %-10s %5d refused: %s\n", b, kind.c_str(), from, identified.status().message().c_str());
        continue;
      }
      values = std::move(*identified);
      if (dump != nullptr) {
        for (const auto& v : values)
          std::fprintf(dump, "%d %s %d %s\n", b, kind.c_str(), from, vb::gap::SessionValuesJson(v).c_str());
        std::fflush(dump);
      }
    }
    nights = static_cast<int>(values.size());
    auto t = vb::gap::TrackValues(values, o);
    if (!t.ok()) {
      std::printf("%-6d %-10s %5d refused: %s\n", b, kind.c_str(), from, t.status().message().c_str());
      continue;
    }
    if (report) std::printf("%s\n", vb::gap::TrackingReport(*t).c_str());
    std::set<std::string> expect;
    if (kind == "resistance") expect = {"R", "R_hold"};
    if (kind == "spring") expect = {"k*x_max^2", "F0*x_max", "i_dropout"};  // the force at the stop: down
    // This plant keeps R when turns short: R_hold must not move. The pull per ampere falls: i_dropout up.
    if (kind == "turns") expect = {"L0", "L1", "L_hold", "i_dropout"};
    std::string first = "none";
    int flag_night = -1;
    if (!t->flags.empty()) {
      flag_night = t->flags.front().session_index + 1;
      first = t->flags.front().parameter + " at night" + std::to_string(flag_night);
    }
    // The night the change reaches 3 sigma in a parameter it should show in (the tracker's own spread).
    int at3 = -1;
    for (const auto& p : t->parameters) {
      if (!expect.count(p.name) || !std::isfinite(p.spread)) continue;
      for (int j = from - 1; j < nights; ++j)
        if (std::isfinite(p.sessions[j].value) && std::abs(p.sessions[j].value - p.center) > 3.0 * p.spread) {
          if (at3 < 0 || j + 1 < at3) at3 = j + 1;
          break;
        }
    }
    bool ok;
    std::string delay = "-";
    if (kind == "clean") {
      clean_nights += nights;
      false_flags += static_cast<int>(t->flags.size());
      ok = t->flags.empty();
    } else {
      ++changes;
      const bool right = !t->flags.empty() && expect.count(t->flags.front().parameter) > 0;
      const bool before = flag_night > 0 && flag_night < from;
      early += before;
      named += right && !before;
      const bool timely = right && !before && (at3 < 0 || flag_night <= at3 + 5);
      if (flag_night > 0 && at3 > 0) delay = std::to_string(flag_night - at3);
      in_time += timely;
      ok = timely;
    }
    std::printf("%-6d %-10s %5d %-34s %8s %6s %s\n", b, kind.c_str(), kind == "clean" ? 0 : from, first.c_str(),
                at3 > 0 ? ("night" + std::to_string(at3)).c_str() : "-", delay.c_str(), ok ? "yes" : "NO");
    std::fflush(stdout);
  }
  const Wilson ff = Interval(false_flags, std::max(clean_nights, 1));
  const Wilson it = Interval(in_time, std::max(changes, 1));
  std::printf("\nclean benches: %d false flags in %d bench-nights (rate %.4f per night, 95 %% CI %.4f-%.4f)\n",
              false_flags, clean_nights, clean_nights ? static_cast<double>(false_flags) / clean_nights : 0.0, ff.lo,
              ff.hi);
  std::printf("changes: %d of %d flagged with the right parameter within 5 nights of 3 sigma (95 %% CI %.2f-%.2f);\n"
              "         %d named right at any time; %d flagged before the change\n",
              in_time, changes, it.lo, it.hi, named, early);
  if (dump != nullptr) std::fclose(dump);
  return 0;
}
