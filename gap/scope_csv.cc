#include "gap/scope_csv.h"

#include "common/split.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <cstdio>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "gap/dataset.h"

namespace vb::gap {

namespace {

namespace fs = std::filesystem;

std::string Trim(std::string s) {
  while (!s.empty() && (s.back() == '\r' || s.back() == ' ' || s.back() == '\t' || s.back() == '"')) s.pop_back();
  std::size_t a = 0;
  while (a < s.size() && (s[a] == ' ' || s[a] == '\t' || s[a] == '"')) ++a;
  return s.substr(a);
}

std::vector<std::string> Split(const std::string& line, char sep) {
  std::vector<std::string> out;
  std::string cur;
  for (char c : line) {
    if (c == sep) {
      out.push_back(Trim(cur));
      cur.clear();
    } else {
      cur += c;
    }
  }
  out.push_back(Trim(cur));
  return out;
}

bool Number(const std::string& s, double* v) {
  if (s.empty()) return false;
  const char* b = s.data();
  if (*b == '+') ++b;
  auto [p, ec] = std::from_chars(b, s.data() + s.size(), *v);
  return ec == std::errc() && p == s.data() + s.size() && std::isfinite(*v);
}

std::string Quote(const std::string& s) { return "'" + (s.size() > 40 ? s.substr(0, 40) + "..." : s) + "'"; }

}  // namespace

namespace {
double Median(std::vector<double> x) {
  if (x.empty()) return 0.0;
  const std::size_t h = x.size() / 2;
  std::nth_element(x.begin(), x.begin() + static_cast<std::ptrdiff_t>(h), x.end());
  return x[h];
}
}  // namespace

CaptureCleaning CleanSwitchOnCapture(std::vector<double>* i_A_ptr, const std::vector<std::int8_t>& gate, double dt_s,
                                     double noise_A) {
  CaptureCleaning c;
  std::vector<double>& i = *i_A_ptr;
  const std::size_t n = std::min(i.size(), gate.size());
  std::size_t on = 0;
  while (on < n && gate[on] == 0) ++on;
  if (on == 0 || on >= n || !(dt_s > 0.0)) return c;
  for (double x : i)
    if (!std::isfinite(x)) return c;  // the loader refuses such traces; nothing to clean
  // The noise: the median absolute second difference (robust to the spike itself): for white noise of sigma s a
  // second difference has sigma sqrt(6) s, and its median absolute value is 0.6745 of that. Floored at 1e-4 of
  // the trace's largest value (finer than any scope's step: a 14-bit ADC's is 6e-5 of its range), so a
  // quantised trace whose second differences are mostly 0 does not make every sample an outlier.
  double peak = 0.0;
  for (std::size_t k = 0; k < n; ++k) peak = std::max(peak, std::abs(i[k]));
  double sigma = noise_A;
  if (!(sigma > 0.0)) {
    std::vector<double> d2;
    for (std::size_t k = 2; k < n; ++k) d2.push_back(std::abs(i[k] - 2.0 * i[k - 1] + i[k - 2]));
    sigma = Median(d2) / (0.6745 * std::sqrt(6.0));
  }
  sigma = std::max(sigma, 1e-4 * peak);
  if (!(sigma > 0.0)) return c;  // an all-zero trace: nothing to clean
  std::vector<std::string> said;
  char buf[200];
  // The baseline: the pre-trigger samples' median, away from the edge's last 2 samples (a spike may start there).
  const std::size_t pre_end = on > 4 ? on - 2 : on;
  if (pre_end >= 3) {
    const double off = Median(std::vector<double>(i.begin(), i.begin() + static_cast<std::ptrdiff_t>(pre_end)));
    const double se = 1.25 * sigma / std::sqrt(static_cast<double>(pre_end));
    if (std::abs(off) > 4.0 * se) {
      for (double& x : i) x -= off;
      c.offset_A = off;
      std::snprintf(buf, sizeof buf, "a baseline offset of %.4g mA (the median of %zu pre-trigger samples) removed",
                    off * 1e3, pre_end);
      said.push_back(buf);
    }
  }
  // The polarity.
  double on_sum = 0.0;
  for (std::size_t k = on; k < n; ++k) on_sum += i[k];
  const double on_mean = on_sum / static_cast<double>(n - on);
  if (on_mean < -6.0 * sigma) {
    for (double& x : i) x = -x;
    c.inverted = true;
    said.push_back("the trace was negative with the gate on (a probe or shunt wired the other way): negated");
  }
  // The spike at the edge.
  const std::size_t span = std::max<std::size_t>(2, static_cast<std::size_t>(std::ceil(50e-6 / dt_s)));
  const std::size_t from = on >= 2 ? on - 2 : 0, to = std::min(n, on + span);
  const std::vector<double> raw(i.begin(), i.begin() + static_cast<std::ptrdiff_t>(n));
  for (std::size_t k = from; k < to; ++k) {
    const std::size_t a = k >= 3 ? k - 3 : 0, b = std::min(n, k + 4);
    const double med = Median(std::vector<double>(raw.begin() + static_cast<std::ptrdiff_t>(a),
                                                  raw.begin() + static_cast<std::ptrdiff_t>(b)));
    const double dev = raw[k] - med;
    if (std::abs(dev) > 6.0 * sigma) {
      i[k] = med;
      ++c.spike_samples;
      if (std::abs(dev) > std::abs(c.spike_A)) c.spike_A = dev;
    }
  }
  if (c.spike_samples > 0) {
    std::snprintf(buf, sizeof buf, "a switching spike at the gate edge (%d sample%s, up to %+.4g mA) masked by the "
                  "running median of 7 samples", c.spike_samples, c.spike_samples == 1 ? "" : "s", c.spike_A * 1e3);
    said.push_back(buf);
  }
  for (const auto& w : said) c.note += (c.note.empty() ? "" : "; ") + w;
  return c;
}

StatusOr<ScopeRun> ConvertScopeCsv(const std::string& csv_path, const std::string& out_dir, const ScopeCsvOptions& o) {
  const std::string name = fs::path(csv_path).filename().string();
  if (o.current_channel.empty()) return Status::InvalidArgument("--channel: name the current's column (name or 1-based index)");
  if ((o.shunt_ohm > 0.0) == (o.probe_A_per_V > 0.0))
    return Status::InvalidArgument("give exactly one of --shunt-ohm (current = V / R) and --probe-A-per-V (a current probe's scale), > 0");
  if (o.gate_channel.empty() == std::isnan(o.trigger_s))
    return Status::InvalidArgument("give exactly one of --gate-channel (the gate drive's column) and --trigger-s (the gate's rising edge)");
  if (!(o.supply_V > 0.0) || !std::isfinite(o.supply_V)) return Status::InvalidArgument("--supply-V: the supply, > 0, is required");
  if (!(o.supply_pressure_Pa >= 0.0) || !std::isfinite(o.supply_pressure_Pa))
    return Status::InvalidArgument("--pressure-Pa: must be a finite number >= 0");
  if (!ParseSplit(o.split).ok()) return Status::InvalidArgument("--split: " + Quote(o.split) + " is not fit or holdout");
  std::ifstream in(csv_path);
  if (!in) return Status::InvalidArgument(csv_path + ": cannot open");
  // Header lines until the first line whose time and current columns are numbers; the last header line with as
  // many fields as the data rows names the columns.
  std::vector<std::string> header;
  std::string line;
  int line_no = 0;
  char sep = ',';
  std::vector<std::vector<std::string>> pre;
  std::vector<double> t, v, g;
  int ti = -1, ci = -1, gi = -1;
  auto resolve = [&](const std::string& want, const std::vector<std::string>& names, std::size_t fields,
                     const char* flag) -> StatusOr<int> {
    double idx = 0;
    if (Number(want, &idx)) {
      if (idx < 1 || idx > static_cast<double>(fields) || idx != std::floor(idx))
        return Status::InvalidArgument(std::string(flag) + ": column " + want + " does not exist (the rows have " +
                                       std::to_string(fields) + " columns)");
      return static_cast<int>(idx) - 1;
    }
    for (std::size_t k = 0; k < names.size(); ++k)
      if (names[k] == want) return static_cast<int>(k);
    std::string known;
    for (const auto& n : names) known += (known.empty() ? "" : ", ") + n;
    return Status::InvalidArgument(std::string(flag) + ": no column " + Quote(want) + " in " + name +
                                   (names.empty() ? " (no header line names the columns: give a 1-based index)"
                                                  : " (columns: " + known + ")"));
  };
  std::vector<std::string> col_names;
  bool data = false;
  while (std::getline(in, line)) {
    ++line_no;
    if (Trim(line).empty()) continue;
    if (!data) {
      // The separator: the first of , ; tab that the line holds.
      char s = line.find(',') != std::string::npos ? ',' : line.find(';') != std::string::npos ? ';' : '\t';
      auto f = Split(line, s);
      double x = 0;
      if (!Number(f[0], &x)) {
        pre.push_back(f);
        continue;
      }
      sep = s;
      data = true;
      // The column names: the header line (of as many fields as the rows) that names the current's channel;
      // scopes put names and units on separate lines ("X,CH1,CH2" then "Second,Volt,Volt").
      for (auto it = pre.rbegin(); it != pre.rend(); ++it) {
        if (it->size() != f.size()) continue;
        if (col_names.empty()) col_names = *it;
        if (std::find(it->begin(), it->end(), o.current_channel) != it->end()) {
          col_names = *it;
          break;
        }
      }
      auto t_idx = o.time_column.empty() ? StatusOr<int>(0) : resolve(o.time_column, col_names, f.size(), "--time-column");
      if (!t_idx.ok()) return t_idx.status();
      auto c_idx = resolve(o.current_channel, col_names, f.size(), "--channel");
      if (!c_idx.ok()) return c_idx.status();
      ti = *t_idx;
      ci = *c_idx;
      if (!o.gate_channel.empty()) {
        auto g_idx = resolve(o.gate_channel, col_names, f.size(), "--gate-channel");
        if (!g_idx.ok()) return g_idx.status();
        gi = *g_idx;
      }
      // One column, one role: the current cannot be the time, nor the gate the current or the time.
      if (ci == ti)
        return Status::InvalidArgument("--channel: '" + o.current_channel + "' is the time column; name the current's channel");
      if (gi >= 0 && (gi == ci || gi == ti))
        return Status::InvalidArgument("--gate-channel: '" + o.gate_channel + "' is the " +
                                       (gi == ci ? "current's channel (--channel)" : "time column") +
                                       "; name the gate drive's channel, or give --trigger-s");
    }
    auto f = Split(line, sep);
    auto column = [&](int k) { return k < static_cast<int>(col_names.size()) ? col_names[k] : std::to_string(k + 1); };
    for (int k : {ti, ci, gi}) {
      if (k < 0) continue;
      double x = 0;
      if (k >= static_cast<int>(f.size()))
        return Status::InvalidArgument(name + ":" + std::to_string(line_no) + ": column " + column(k) + ": missing (the line has " +
                                       std::to_string(f.size()) + " fields)");
      if (!Number(f[k], &x))
        return Status::InvalidArgument(name + ":" + std::to_string(line_no) + ": column " + column(k) + ": " + Quote(f[k]) +
                                       " is not a number");
      if (k == ti) {
        if (!t.empty() && !(x > t.back()))
          return Status::InvalidArgument(name + ":" + std::to_string(line_no) + ": column " + column(k) + ": time " + f[k] +
                                         " does not increase");
        t.push_back(x);
      } else if (k == ci) {
        v.push_back(x);
      } else {
        g.push_back(x);
      }
    }
  }
  if (t.size() < 3) return Status::InvalidArgument(name + ": fewer than 3 data rows (a time column and channels of numbers)");
  const double dt = (t.back() - t.front()) / static_cast<double>(t.size() - 1);
  for (std::size_t k = 1; k < t.size(); ++k)
    if (std::abs(t[k] - t[k - 1] - dt) > 0.01 * dt)
      return Status::InvalidArgument(name + ": data row " + std::to_string(k + 1) + ": the time step " +
                                     std::to_string(t[k] - t[k - 1]) + " s differs from the mean " + std::to_string(dt) +
                                     " s by over 1 %: the dataset needs a uniform grid");
  // The gate.
  std::vector<int> gate(t.size(), 0);
  double on_s = NAN;
  if (gi >= 0) {
    const auto [mn, mx] = std::minmax_element(g.begin(), g.end());
    const double thr = std::isfinite(o.gate_threshold_V) ? o.gate_threshold_V : 0.5 * (*mn + *mx);
    if (!(*mx > thr) || !(*mn < thr))
      return Status::InvalidArgument("--gate-channel: the channel never crosses " + std::to_string(thr) + " V: no gate edge");
    for (std::size_t k = 0; k < g.size(); ++k) gate[k] = g[k] > thr;
    if (gate.front() == 1)
      return Status::InvalidArgument("--gate-channel: the gate is already high at the first sample: a switch-on capture "
                                     "starts before the edge (pre-trigger)");
    for (std::size_t k = 0; k < gate.size(); ++k)
      if (gate[k]) {
        on_s = t[k];
        break;
      }
  } else {
    if (!(o.trigger_s > t.front()) || !(o.trigger_s <= t.back()))
      return Status::InvalidArgument("--trigger-s: " + std::to_string(o.trigger_s) + " s is not inside the capture (" +
                                     std::to_string(t.front()) + " .. " + std::to_string(t.back()) + " s, after its first sample)");
    on_s = o.trigger_s;
    for (std::size_t k = 0; k < t.size(); ++k) gate[k] = t[k] >= o.trigger_s - 1e-9 * dt;
  }
  // The dataset: create or append.
  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) return Status::InvalidArgument(out_dir + ": " + ec.message());
  const fs::path manifest_path = fs::path(out_dir) / "manifest.json";
  nlohmann::ordered_json m;
  if (fs::exists(manifest_path)) {
    std::ifstream mf(manifest_path);
    try {
      m = nlohmann::ordered_json::parse(mf);
    } catch (const std::exception& e) {
      return Status::InvalidArgument(manifest_path.string() + ": not valid JSON: " + e.what());
    }
    if (!m.is_object() || !m.contains("runs") || !m["runs"].is_array())
      return Status::InvalidArgument(manifest_path.string() + ": not a valve-runs manifest (no runs array)");
  } else {
    m["format"] = "valve-runs/2";
    m["model"] = o.model;
    if (!o.device.empty()) m["device"] = o.device;
    m["description"] = "scope captures converted by benchctl convert";
    nlohmann::ordered_json sensor = nlohmann::ordered_json::object();
    if (std::isfinite(o.noise_A)) sensor["noise_A"] = o.noise_A;
    if (o.averaged > 0) sensor["averaged"] = o.averaged;
    if (std::isfinite(o.lsb_A)) sensor["adc_lsb_A"] = o.lsb_A;
    if (!sensor.empty()) m["sensor"] = sensor;
    m["runs"] = nlohmann::ordered_json::array();
  }
  ScopeRun out;
  out.directory = out_dir;
  out.run_id = o.run_id.empty() ? fs::path(csv_path).stem().string() : o.run_id;
  out.file = out.run_id + ".csv";
  double last = -1.0;
  for (const auto& r : m["runs"]) {
    if (r.value("id", "") == out.run_id)
      return Status::InvalidArgument(manifest_path.string() + ": a run '" + out.run_id + "' exists already (--run-id)");
    if (r.contains("t_start_s") && r["t_start_s"].is_number()) last = std::max(last, r["t_start_s"].get<double>());
  }
  const double t_start = std::isfinite(o.t_start_s) ? o.t_start_s : last < 0.0 ? 0.0 : last + 1.0;
  if (t_start < last)
    return Status::InvalidArgument("--t-start-s: " + std::to_string(t_start) + " s is before the dataset's last run (" +
                                   std::to_string(last) + " s); runs are listed in time order");
  std::vector<double> current(t.size());
  for (std::size_t k = 0; k < t.size(); ++k) current[k] = o.shunt_ohm > 0.0 ? v[k] / o.shunt_ohm : v[k] * o.probe_A_per_V;
  if (o.clean) {
    const std::vector<std::int8_t> g8(gate.begin(), gate.end());
    out.cleaning = CleanSwitchOnCapture(&current, g8, dt, 0.0);
  }
  std::ofstream csv(fs::path(out_dir) / out.file);
  if (!csv) return Status::InvalidArgument((fs::path(out_dir) / out.file).string() + ": cannot write");
  csv << "t_s,gate,i_A\n";
  char buf[96];
  for (std::size_t k = 0; k < t.size(); ++k) {
    std::snprintf(buf, sizeof buf, "%.9g,%d,%.9g\n", static_cast<double>(k) * dt, gate[k], current[k]);
    csv << buf;
  }
  nlohmann::ordered_json run = {{"id", out.run_id}, {"file", out.file}, {"supply_V", o.supply_V},
                                {"supply_pressure_Pa", o.supply_pressure_Pa}, {"t_start_s", t_start}};
  if (!o.split.empty()) run["split"] = o.split;
  m["runs"].push_back(run);
  // What the cleaning did is kept with the data (the manifest's description; a run has no free-text key).
  if (!out.cleaning.note.empty())
    m["description"] = m.value("description", std::string()) + "; run " + out.run_id + ": " + out.cleaning.note;
  csv.close();
  {
    std::ofstream mf(manifest_path);
    mf << m.dump(1) << "\n";
    mf.close();
    if (!mf) return Status::InvalidArgument(manifest_path.string() + ": cannot write");
  }
  out.samples = t.size();
  out.sample_period_s = dt;
  out.gate_on_s = on_s - t.front();
  // The result must load as a dataset.
  auto ds = LoadDataset(out_dir, {o.model, std::string(m.value("model", o.model))});
  if (!ds.ok()) return ds.status().WithContext("the converted dataset");
  return out;
}

}  // namespace vb::gap
