#include "gap/readings_csv.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <tuple>

#include <nlohmann/json.hpp>

#include "common/format.h"

namespace vb::gap {

namespace {

namespace fs = std::filesystem;

constexpr const char* kColumns[] = {"device",        "supply_V",       "amp_feedback_ohm", "temp_C",
                                    "stroke_mm",     "pwm_Hz",         "on_time_s",        "sample",
                                    "t_after_edge_s", "v_mV_mean",     "v_mV_sd",          "repeats"};
constexpr int kColumnCount = 12;

struct Reading {
  std::string sample;
  double t_after_edge_s, i_A, sd_A;
  int repeats;
};

// A session's key: device, supply, amplifier, temperature, stroke. A run's key within it: PWM frequency, on-time.
using SessionKey = std::tuple<std::string, double, double, double, double>;
using RunKey = std::pair<double, double>;

std::vector<std::string_view> Split(std::string_view line) {
  std::vector<std::string_view> out;
  for (std::size_t start = 0;;) {
    const std::size_t comma = line.find(',', start);
    out.push_back(line.substr(start, comma == std::string_view::npos ? std::string_view::npos : comma - start));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return out;
}

std::string Tag(double v) {
  std::string s = FormatNumber(v);
  std::replace(s.begin(), s.end(), '.', 'p');
  std::replace(s.begin(), s.end(), '-', 'm');
  return s;
}

// Well-formed UTF-8 (no overlong forms, surrogates or code points above U+10FFFF): what a JSON manifest can hold.
bool IsUtf8(std::string_view s) {
  for (std::size_t k = 0; k < s.size();) {
    const auto c = static_cast<unsigned char>(s[k]);
    std::size_t n = c < 0x80 ? 1 : (c >> 5) == 0x6 ? 2 : (c >> 4) == 0xE ? 3 : (c >> 3) == 0x1E ? 4 : 0;
    if (n == 0 || k + n > s.size()) return false;
    std::uint32_t cp = n == 1 ? c : c & (0x7F >> n);
    for (std::size_t j = 1; j < n; ++j) {
      const auto cc = static_cast<unsigned char>(s[k + j]);
      if ((cc >> 6) != 0x2) return false;
      cp = (cp << 6) | (cc & 0x3F);
    }
    static constexpr std::uint32_t kMin[] = {0, 0, 0x80, 0x800, 0x10000};
    if (cp < kMin[n] || cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) return false;
    k += n;
  }
  return true;
}

std::string SafeName(std::string s) {
  for (char& c : s)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '_';
  return s.empty() ? "device" : s;
}

}  // namespace

StatusOr<std::vector<ReadingsSession>> ConvertReadingsCsv(const std::string& csv_path, const std::string& out_dir,
                                                          const ReadingsCsvOptions& opt) {
  const std::string display = fs::path(csv_path).filename().string();
  std::ifstream in(csv_path, std::ios::binary);
  if (!in) return Status::InvalidArgument(csv_path + ": cannot open");
  if (!(opt.shunt_ohm > 0.0) || !(opt.amp_ref_ohm > 0.0))
    return Status::InvalidArgument("options: shunt_ohm and amp_ref_ohm must be > 0");

  std::string line;
  if (!std::getline(in, line)) return Status::InvalidArgument(display + ": empty file; expected the header row");
  if (!line.empty() && line.back() == '\r') line.pop_back();
  if (line.size() >= 3 && line.compare(0, 3, "\xEF\xBB\xBF") == 0) line.erase(0, 3);
  const auto header = Split(line);
  int col[kColumnCount];
  for (int c = 0; c < kColumnCount; ++c) {
    const auto it = std::find(header.begin(), header.end(), kColumns[c]);
    if (it == header.end())
      return Status::InvalidArgument(display + ":1: missing column " + kColumns[c] + " (header '" + line.substr(0, 80) + "')");
    col[c] = static_cast<int>(it - header.begin());
  }

  std::map<SessionKey, std::map<RunKey, std::vector<Reading>>> sessions;
  int line_no = 1;
  while (std::getline(in, line)) {
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty()) continue;
    const auto f = Split(line);
    const std::string at = display + ":" + std::to_string(line_no) + ":";
    if (f.size() != header.size()) {
      return Status::InvalidArgument(at + " " + std::to_string(f.size()) + " fields, but the header has " +
                                     std::to_string(header.size()));
    }
    double v[kColumnCount] = {};
    for (int c = 0; c < kColumnCount; ++c) {
      if (c == 0 || c == 7) continue;  // device, sample: text
      const std::string_view field = f[static_cast<std::size_t>(col[c])];
      auto [ptr, ec] = std::from_chars(field.data(), field.data() + field.size(), v[c]);
      if (field.empty() || ec != std::errc() || ptr != field.data() + field.size() || !std::isfinite(v[c]))
        return Status::InvalidArgument(at + " column " + kColumns[c] + ": '" + std::string(field.substr(0, 40)) +
                                       "' is not a finite number");
    }
    auto bad = [&](int c, const std::string& what) {
      return Status::InvalidArgument(at + " column " + kColumns[c] + ": " + FormatNumber(v[c]) + " " + what);
    };
    if (!(v[1] > 0.0) || v[1] > 1e4) return bad(1, "V is outside (0, 10000] V");
    if (!(v[2] >= 0.0) || v[2] > 1e9) return bad(2, "ohm is outside [0, 1e9] ohm");
    if (v[3] < -100.0 || v[3] > 400.0) return bad(3, "C is outside [-100, 400] C");
    if (v[4] < 0.0 || v[4] > 1000.0) return bad(4, "mm is outside [0, 1000] mm");
    if (!(v[5] > 0.0) || v[5] > 1e6) return bad(5, "Hz is outside (0, 1e6] Hz");
    const double period_s = 1.0 / v[5];
    if (!(v[6] > 0.0) || v[6] > period_s * (1 + 1e-9)) return bad(6, "s is outside (0, period]");
    if (v[8] < 0.0 || !(v[8] < period_s)) return bad(8, "s is outside [0, period)");
    if (std::abs(v[9]) > 1e6) return bad(9, "mV is outside [-1e6, 1e6] mV");
    if (!(v[10] >= 0.0) || v[10] > 1e6) return bad(10, "mV is outside [0, 1e6] mV");
    if (!(v[11] >= 1.0) || v[11] > 1e9 || v[11] != std::floor(v[11])) return bad(11, "is not a whole number >= 1");
    const double gain = 1.0 + v[2] / opt.amp_ref_ohm;
    const double A_per_mV = 1e-3 / (opt.shunt_ohm * gain);
    // The dataset reader takes currents in [-1000, 1000] A: refuse here what it would refuse there.
    if (std::abs(v[9] * A_per_mV) > 1e3)
      return bad(9, "mV is " + FormatNumber(v[9] * A_per_mV) + " A through the shunt and amplifier, outside [-1000, 1000] A");
    const std::string device(f[static_cast<std::size_t>(col[0])]);
    if (device.empty()) return Status::InvalidArgument(at + " column device: empty");
    if (!IsUtf8(device)) return Status::InvalidArgument(at + " column device: not valid UTF-8");
    Reading r{std::string(f[static_cast<std::size_t>(col[7])]), v[8], v[9] * A_per_mV, v[10] * A_per_mV,
              static_cast<int>(v[11])};
    sessions[{device, v[1], v[2], v[3], v[4]}][{v[5], v[6]}].push_back(r);
  }
  if (sessions.empty()) return Status::InvalidArgument(display + ": no readings after the header");

  std::error_code ec;
  fs::create_directories(out_dir, ec);
  if (ec) return Status::Unavailable(out_dir + ": cannot create: " + ec.message());
  // One directory per session. Two devices whose names differ only in characters a directory name cannot
  // carry ("a b", "a_b") would write one session over the other: refused, naming both. One device at several
  // supplies or amplifier gains gets them in its directory names.
  std::map<std::string, std::vector<const SessionKey*>> by_dir;
  for (const auto& entry : sessions) {
    const auto& [device, supply_V, feedback_ohm, temp_C, stroke_mm] = entry.first;
    by_dir[SafeName(device) + "_s" + Tag(stroke_mm) + "mm_" + Tag(temp_C) + "C"].push_back(&entry.first);
  }
  std::map<const SessionKey*, std::string> dir_of;
  for (const auto& [name, keys] : by_dir) {
    for (const SessionKey* k : keys)
      if (std::get<0>(*k) != std::get<0>(*keys.front()))
        return Status::InvalidArgument(display + ": column device: '" + std::get<0>(*keys.front()) + "' and '" +
                                       std::get<0>(*k) + "' both become the directory " + name +
                                       " (characters other than letters, digits, - and _ become _): rename one");
    for (const SessionKey* k : keys)
      dir_of[k] = keys.size() == 1 ? name
                                   : name + "_" + Tag(std::get<1>(*k)) + "V_amp" + Tag(std::get<2>(*k)) + "ohm";
  }
  std::vector<ReadingsSession> out;
  for (const auto& [key, runs] : sessions) {
    const auto& [device, supply_V, feedback_ohm, temp_C, stroke_mm] = key;
    ReadingsSession s;
    s.device = device;
    s.supply_V = supply_V;
    s.temp_C = temp_C;
    s.stroke_m = stroke_mm * 1e-3;
    s.directory = (fs::path(out_dir) / dir_of.at(&key)).string();
    nlohmann::json m;
    m["format"] = "valve-runs/2";
    m["model"] = opt.model;
    m["device"] = device;
    m["description"] = device + " at " + FormatNumber(temp_C) + " C, plunger held at " + FormatNumber(stroke_mm) +
                       " mm: periodic steady-state readings converted from " + display;
    const double gain = 1.0 + feedback_ohm / opt.amp_ref_ohm;
    m["sensor"] = {{"shunt_ohm", opt.shunt_ohm},  {"shunt_in_switch_path", true}, {"amplifier_gain", gain},
                   {"adc_lsb_V", opt.adc_lsb_V},  {"averaged", opt.averaged}};
    m["driver"] = {{"kind", "low_side_flyback"}};
    nlohmann::json jruns = nlohmann::json::array();
    for (const auto& [rk, readings] : runs) {
      const auto& [pwm_Hz, on_time_s] = rk;
      nlohmann::json jr;
      jr["id"] = FormatNumber(pwm_Hz) + "Hz_" + FormatNumber(on_time_s * 1e3) + "ms";
      jr["kind"] = "periodic";
      jr["supply_V"] = supply_V;
      jr["ambient_C"] = temp_C;
      jr["stroke_m"] = s.stroke_m;
      jr["pwm_Hz"] = pwm_Hz;
      jr["on_time_s"] = on_time_s;
      nlohmann::json jread = nlohmann::json::array();
      for (const auto& r : readings) {
        jread.push_back({{"t_after_edge_s", r.t_after_edge_s}, {"i_A", r.i_A}, {"sd_A", r.sd_A}, {"repeats", r.repeats}});
        ++s.readings;
      }
      jr["readings"] = jread;
      jruns.push_back(jr);
      ++s.runs;
    }
    m["runs"] = jruns;
    fs::create_directories(s.directory, ec);
    if (ec) return Status::Unavailable(s.directory + ": cannot create: " + ec.message());
    std::ofstream o(fs::path(s.directory) / "manifest.json");
    o << m.dump(1, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";  // the file name may be any bytes
    if (!o) return Status::Unavailable(s.directory + "/manifest.json: cannot write");
    out.push_back(s);
  }
  std::stable_sort(out.begin(), out.end(), [](const ReadingsSession& a, const ReadingsSession& b) {
    return std::tie(a.device, a.stroke_m, a.temp_C) < std::tie(b.device, b.stroke_m, b.temp_C);
  });
  return out;
}

}  // namespace vb::gap
