#include "common/format.h"
#include "gap/dataset.h"
#include "model/params.h"

#include <algorithm>
#include <array>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <optional>
#include <string_view>
#include <system_error>
#include <unordered_map>
#include <utility>

#include <nlohmann/json.hpp>

namespace vb::gap {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr double kStartTolerance_s = 1e-9;   // t_s of the first sample must be within this of 0
constexpr double kStepRelTolerance = 1e-6;   // every time step must equal the first within this fraction
constexpr size_t kMinSamples = 2;
constexpr size_t kMaxQuoted = 40;            // longest value quoted back in a message

// ---- message helpers -------------------------------------------------------------------------------------

// Shortest text that reads back as the same double: 2e-05, 1.5, 300000.
// A computed value (a time step) to 9 significant digits, so that 7e-05 - 4e-05 reads 3e-05.
std::string Num9(double v) {
  std::array<char, 32> buf{};
  auto [end, ec] = std::to_chars(buf.data(), buf.data() + buf.size(), v, std::chars_format::general, 9);
  if (ec != std::errc()) return "?";
  return std::string(buf.data(), end);
}

// A value quoted back to the user: 'abc', shortened, control characters made visible.
std::string Quote(std::string_view s) {
  std::string out = "'";
  const bool cut = s.size() > kMaxQuoted;
  if (cut) s = s.substr(0, kMaxQuoted);
  for (char c : s) {
    if (c == '\r') {
      out += "\\r";
    } else if (c == '\t') {
      out += "\\t";
    } else if (static_cast<unsigned char>(c) < 0x20) {
      out += '?';
    } else {
      out += c;
    }
  }
  out += cut ? "...'" : "'";
  return out;
}

std::string JsonTypeName(const json& j) {
  if (j.is_number()) return "a number";
  if (j.is_string()) return "a string";
  if (j.is_boolean()) return "a boolean";
  if (j.is_null()) return "null";
  if (j.is_array()) return "an array";
  if (j.is_object()) return "an object";
  return "something else";
}

// ---- files -----------------------------------------------------------------------------------------------

// The largest run file a dataset may have (docs/dataset-format.md, "Limits"): 512 MiB of CSV is about 12 M
// samples of four columns. A larger file is refused from its size, before a byte is read.
constexpr std::uintmax_t kMaxFileBytes = std::uintmax_t{512} << 20;

// Reads a whole file. `display` names it in the error.
Status ReadFile(const fs::path& path, const std::string& display, std::string* out) {
  struct Closer {
    void operator()(std::FILE* f) const { std::fclose(f); }
  };
  std::unique_ptr<std::FILE, Closer> f(std::fopen(path.c_str(), "rb"));
  if (!f) return Status::InvalidArgument(display + ": cannot open: " + std::strerror(errno));
  out->clear();
  std::error_code ec;
  const auto size = fs::file_size(path, ec);
  if (!ec && size > kMaxFileBytes)
    return Status::InvalidArgument(display + ": " + std::to_string(size >> 20) + " MiB exceeds the " +
                                   std::to_string(kMaxFileBytes >> 20) +
                                   " MiB a dataset file may have; split the run into several runs (files)");
  if (!ec) out->reserve(static_cast<size_t>(size));
  std::array<char, 1 << 16> buf;
  size_t n = 0;
  while ((n = std::fread(buf.data(), 1, buf.size(), f.get())) > 0) out->append(buf.data(), n);
  if (std::ferror(f.get())) return Status::InvalidArgument(display + ": read error");
  return Status::Ok();
}

// The name errors use for the dataset: the last component of its directory ("p01" for "/x/p01/").
std::string DatasetName(const std::string& directory) {
  auto last = [](const fs::path& p) {
    fs::path q = p;
    if (q.filename().empty() && q.has_parent_path()) q = q.parent_path();  // trailing '/'
    return q.filename().string();
  };
  std::string name = last(fs::path(directory).lexically_normal());
  if (name.empty() || name == "." || name == "..") {
    std::error_code ec;
    const fs::path abs = fs::absolute(directory, ec);
    if (!ec) name = last(abs.lexically_normal());
  }
  return name.empty() ? directory : name;
}

// Where a dataset's files come from: a directory (LoadDataset) or files in memory (LoadDatasetFromFiles, the
// web's upload). Paths have been checked to stay inside the dataset (CheckRunFile) before either is asked.
class FileSource {
 public:
  virtual ~FileSource() = default;
  // "" for a regular file; else why it cannot be read ("does not exist", "is not a regular file").
  virtual std::string Problem(const std::string& file) const = 0;
  virtual Status Read(const std::string& file, const std::string& display, std::string* out) const = 0;
  // What Dataset::model_file holds for a model file: its path, or (in memory) its name.
  virtual std::string Where(const std::string& file) const = 0;
};

class DirectorySource final : public FileSource {
 public:
  explicit DirectorySource(fs::path dir) : dir_(std::move(dir)) {}
  std::string Problem(const std::string& file) const override {
    std::error_code ec;
    const fs::file_status st = fs::status(dir_ / file, ec);
    if (!fs::exists(st)) return "does not exist";
    if (!fs::is_regular_file(st)) return "is not a regular file";
    return "";
  }
  Status Read(const std::string& file, const std::string& display, std::string* out) const override {
    return ReadFile(dir_ / file, display, out);
  }
  std::string Where(const std::string& file) const override { return (dir_ / file).string(); }

 private:
  fs::path dir_;
};

class MemorySource final : public FileSource {
 public:
  explicit MemorySource(const std::map<std::string, std::string>& files) : files_(files) {}
  std::string Problem(const std::string& file) const override {
    return files_.count(fs::path(file).lexically_normal().string()) ? "" : "does not exist";
  }
  Status Read(const std::string& file, const std::string& display, std::string* out) const override {
    const auto f = files_.find(fs::path(file).lexically_normal().string());
    if (f == files_.end()) return Status::InvalidArgument(display + ": does not exist");
    if (f->second.size() > kMaxFileBytes)
      return Status::InvalidArgument(display + ": " + std::to_string(f->second.size() >> 20) + " MiB exceeds the " +
                                     std::to_string(kMaxFileBytes >> 20) + " MiB a dataset file may have");
    *out = f->second;
    return Status::Ok();
  }
  std::string Where(const std::string& file) const override { return file; }

 private:
  const std::map<std::string, std::string>& files_;
};

// ---- CSV -------------------------------------------------------------------------------------------------

enum class Column { kT, kGate, kI, kX, kVCoil, kSd, kUnknown };

Column ColumnOf(std::string_view name, RunKind kind) {
  if (kind == RunKind::kSamples) {
    if (name == "t_s") return Column::kT;
    if (name == "i_A") return Column::kI;
    if (name == "i_sd_A") return Column::kSd;
    return Column::kUnknown;
  }
  if (name == "t_s") return Column::kT;
  if (name == "gate") return Column::kGate;
  if (name == "i_A") return Column::kI;
  if (name == "x_m") return Column::kX;
  if (name == "v_coil_V") return Column::kVCoil;
  return Column::kUnknown;
}

// Splits text into lines: '\n' ends a line, one '\r' before it is dropped, a final '\n' ends the last line.
class LineReader {
 public:
  explicit LineReader(std::string_view text) : text_(text) {}
  // The next line, or nullopt at the end. line_number() is then its 1-based number.
  std::optional<std::string_view> Next() {
    if (pos_ >= text_.size()) return std::nullopt;
    const char* begin = text_.data() + pos_;
    const void* nl = std::memchr(begin, '\n', text_.size() - pos_);
    size_t len = nl ? static_cast<size_t>(static_cast<const char*>(nl) - begin) : text_.size() - pos_;
    pos_ += len + (nl ? 1 : 0);
    if (len > 0 && begin[len - 1] == '\r') --len;
    ++line_;
    return std::string_view(begin, len);
  }
  size_t line_number() const { return line_; }

 private:
  std::string_view text_;
  size_t pos_ = 0;
  size_t line_ = 0;
};

enum class NumberError { kNone, kNotNumber, kNotFinite };

// The whole field must be a number in std::from_chars' general format ("1", "-0.5", "2e-05"); no blanks,
// no leading '+'.
NumberError ParseDouble(std::string_view field, double* out) {
  const char* first = field.data();
  const char* last = field.data() + field.size();
  auto [ptr, ec] = std::from_chars(first, last, *out);
  if (field.empty() || ptr != last) return NumberError::kNotNumber;
  if (ec == std::errc::result_out_of_range) return NumberError::kNotFinite;
  if (ec != std::errc()) return NumberError::kNotNumber;
  if (!std::isfinite(*out)) return NumberError::kNotFinite;
  return NumberError::kNone;
}

Status ParseCsv(std::string_view text, const std::string& display, RunData* run,
                std::vector<std::string>* warnings) {
  if (text.size() >= 3 && text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);  // UTF-8 BOM
  const bool samples = run->kind == RunKind::kSamples;
  const std::string needs_header =
      samples ? "; expected a header row such as t_s,i_A" : "; expected a header row such as t_s,gate,i_A";
  if (text.empty()) return Status::InvalidArgument(display + ": empty file" + needs_header);

  LineReader lines(text);
  const std::string_view header = *lines.Next();
  if (header.empty()) return Status::InvalidArgument(display + ":1: empty line" + needs_header);

  // Header: one role per column.
  std::vector<Column> roles;
  std::vector<std::string_view> names;
  for (size_t start = 0;;) {
    const size_t comma = header.find(',', start);
    const std::string_view name = header.substr(start, comma == std::string_view::npos ? std::string_view::npos
                                                                                       : comma - start);
    if (name.empty()) {
      return Status::InvalidArgument(display + ":1: column " + std::to_string(names.size() + 1) +
                                     " of the header has an empty name");
    }
    if (std::find(names.begin(), names.end(), name) != names.end()) {
      return Status::InvalidArgument(display + ":1: column " + std::string(name) + " appears twice in the header");
    }
    names.push_back(name);
    roles.push_back(ColumnOf(name, run->kind));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  const std::vector<const char*> required_columns =
      samples ? std::vector<const char*>{"t_s", "i_A"} : std::vector<const char*>{"t_s", "gate", "i_A"};
  for (const char* required : required_columns) {
    if (std::find(names.begin(), names.end(), required) == names.end()) {
      return Status::InvalidArgument(display + ":1: missing required column " + required + " (header " +
                                     Quote(header) + ")");
    }
  }
  bool has_x = false, has_v = false, has_sd = false;
  for (size_t c = 0; c < roles.size(); ++c) {
    if (roles[c] == Column::kX) has_x = true;
    if (roles[c] == Column::kVCoil) has_v = true;
    if (roles[c] == Column::kSd) has_sd = true;
    if (roles[c] == Column::kUnknown) {
      warnings->push_back(display + ": column " + Quote(names[c]) +
                          (samples ? " is not a samples column (t_s, i_A, i_sd_A); ignored"
                                   : " is not a valve-runs/1 column (t_s, gate, i_A, x_m, v_coil_V); ignored"));
    }
  }

  const size_t expected_rows = static_cast<size_t>(std::count(text.begin(), text.end(), '\n'));
  run->t_s.clear();
  run->gate.clear();
  run->i_A.clear();
  run->x_m.clear();
  run->v_coil_V.clear();
  run->t_s.reserve(expected_rows);
  run->gate.reserve(expected_rows);
  run->i_A.reserve(expected_rows);
  if (has_x) run->x_m.reserve(expected_rows);
  if (has_v) run->v_coil_V.reserve(expected_rows);
  run->i_sd_A.clear();
  if (has_sd) run->i_sd_A.reserve(expected_rows);

  const size_t ncol = roles.size();
  double t_prev = 0.0, step0 = 0.0;
  while (auto line = lines.Next()) {
    auto at = [&](std::string_view column) {  // "p01/x.csv:17: column i_A:", built only on error
      std::string s = display + ":" + std::to_string(lines.line_number()) + ":";
      if (!column.empty()) s += std::string(" column ") + std::string(column) + ":";
      return s;
    };
    if (line->empty()) {
      return Status::InvalidArgument(at("") + " empty line (empty lines are only allowed as the final newline)");
    }
    const size_t found = 1 + static_cast<size_t>(std::count(line->begin(), line->end(), ','));
    if (found != ncol) {
      return Status::InvalidArgument(at("") + " " + std::to_string(found) + " fields, but the header has " +
                                     std::to_string(ncol));
    }
    double t = 0.0;
    size_t start = 0;
    for (size_t c = 0; c < ncol; ++c) {
      size_t end = c + 1 == ncol ? line->size() : line->find(',', start);
      const std::string_view field = line->substr(start, end - start);
      start = end + 1;
      if (roles[c] == Column::kUnknown) continue;
      double v = 0.0;
      switch (ParseDouble(field, &v)) {
        case NumberError::kNone: break;
        case NumberError::kNotNumber:
          return Status::InvalidArgument(at(names[c]) + " " + Quote(field) + " is not a number");
        case NumberError::kNotFinite:
          return Status::InvalidArgument(at(names[c]) + " " + Quote(field) + " is not a finite number");
      }
      switch (roles[c]) {
        case Column::kT: t = v; run->t_s.push_back(v); break;
        case Column::kGate:
          if (v != 0.0 && v != 1.0) {
            return Status::InvalidArgument(at(names[c]) + " " + Quote(field) + " is not 0 or 1");
          }
          run->gate.push_back(static_cast<int8_t>(v));
          break;
        case Column::kI: run->i_A.push_back(v); break;
        case Column::kX: run->x_m.push_back(v); break;
        case Column::kVCoil: run->v_coil_V.push_back(v); break;
        case Column::kSd:
          if (v < 0.0) return Status::InvalidArgument(at(names[c]) + " " + Quote(field) + " is negative");
          run->i_sd_A.push_back(v);
          break;
        case Column::kUnknown: break;
      }
    }
    const size_t k = run->t_s.size() - 1;
    if (samples) {
      // Samples at arbitrary instants: from t >= 0, strictly increasing.
      if (k == 0 && t < 0.0)
        return Status::InvalidArgument(at("t_s") + " " + FormatNumber(t) + " s is before the run's start (t_s >= 0)");
      if (k > 0 && !(t > t_prev)) {
        return Status::InvalidArgument(at("t_s") + " time does not increase (" + FormatNumber(t) + " s after " +
                                       FormatNumber(t_prev) + " s)");
      }
      t_prev = t;
      continue;
    }
    // Uniform sampling from t = 0, checked as the rows come so the first bad line is the one named.
    if (k == 0) {
      if (std::abs(t) > kStartTolerance_s) {
        return Status::InvalidArgument(at("t_s") + " the first sample is at " + FormatNumber(t) +
                                       " s; a run starts at t_s = 0");
      }
    } else if (k == 1) {
      step0 = t - t_prev;
      if (!(step0 > 0.0)) {
        return Status::InvalidArgument(at("t_s") + " time does not increase (" + FormatNumber(t) + " s after " +
                                       FormatNumber(t_prev) + " s)");
      }
    } else {
      const double step = t - t_prev;
      if (std::abs(step - step0) > kStepRelTolerance * step0) {
        return Status::InvalidArgument(at("t_s") + " step " + Num9(step) + " s (from " + FormatNumber(t_prev) + " to " +
                                       FormatNumber(t) + " s) differs from the first step " + Num9(step0) +
                                       " s; sampling must be uniform");
      }
    }
    t_prev = t;
  }

  const size_t n = run->t_s.size();
  if (samples) {
    if (n == 0) return Status::InvalidArgument(display + ": 0 samples; a run needs at least 1");
    return Status::Ok();
  }
  if (n < kMinSamples) {
    return Status::InvalidArgument(display + ": " + std::to_string(n) + (n == 1 ? " sample" : " samples") +
                                   "; a run needs at least " + std::to_string(kMinSamples));
  }
  run->sample_period_s = (run->t_s.back() - run->t_s.front()) / static_cast<double>(n - 1);
  return Status::Ok();
}

// ---- manifest --------------------------------------------------------------------------------------------

// Error helpers for one JSON value at `path` ("runs[2].supply_V") of manifest `display`.
struct ManifestContext {
  std::string display;  // "p01/manifest.json"
  Status Error(const std::string& path, const std::string& what) const {
    return Status::InvalidArgument(display + ": " + (path.empty() ? "" : path + ": ") + what);
  }
};

Status GetString(const ManifestContext& m, const json& obj, const char* key, const std::string& path,
                 bool required, std::optional<std::string>* out) {
  const auto it = obj.find(key);
  if (it == obj.end()) {
    if (required) return m.Error(path, "missing");
    out->reset();
    return Status::Ok();
  }
  if (!it->is_string()) return m.Error(path, "must be a string, found " + JsonTypeName(*it));
  *out = it->get<std::string>();
  return Status::Ok();
}

Status GetNumber(const ManifestContext& m, const json& obj, const char* key, const std::string& path,
                 double* out) {
  const auto it = obj.find(key);
  if (it == obj.end()) return m.Error(path, "missing");
  if (!it->is_number()) return m.Error(path, "must be a number, found " + JsonTypeName(*it));
  *out = it->get<double>();
  if (!std::isfinite(*out)) return m.Error(path, FormatNumber(*out) + " is not finite");
  return Status::Ok();
}

Status GetBool(const ManifestContext& m, const json& obj, const char* key, const std::string& path, bool* out) {
  const auto it = obj.find(key);
  if (it == obj.end()) return Status::Ok();
  if (!it->is_boolean()) return m.Error(path, "must be true or false, found " + JsonTypeName(*it));
  *out = it->get<bool>();
  return Status::Ok();
}

// An optional number within [lo, hi]; left as it is when absent.
Status GetBounded(const ManifestContext& m, const json& obj, const char* key, const std::string& path, double lo,
                  double hi, const char* unit, double* out) {
  if (obj.find(key) == obj.end()) return Status::Ok();
  double v = 0.0;
  VB_RETURN_IF_ERROR(GetNumber(m, obj, key, path, &v));
  if (v < lo || v > hi) {
    return m.Error(path, FormatNumber(v) + " " + unit + " is outside [" + FormatNumber(lo) + ", " + FormatNumber(hi) +
                             "] " + unit);
  }
  *out = v;
  return Status::Ok();
}

Status WarnUnknownKeys(const ManifestContext& m, const json& j, const std::string& path,
                       const std::vector<std::string_view>& known, std::vector<std::string>* warnings) {
  for (const auto& item : j.items()) {
    if (std::find(known.begin(), known.end(), item.key()) == known.end()) {
      warnings->push_back(m.display + ": " + (path.empty() ? "" : path + ": ") + "unknown key " + Quote(item.key()) +
                          " ignored");
    }
  }
  return Status::Ok();
}

Status CheckRunFile(const ManifestContext& m, const FileSource& dir, const std::string& file,
                    const std::string& path) {
  if (file.empty()) return m.Error(path, "must not be empty");
  const fs::path p(file);
  if (p.has_root_path()) {
    return m.Error(path, Quote(file) + " is an absolute path; files must be inside the dataset directory");
  }
  const fs::path norm = p.lexically_normal();
  if (norm.empty() || *norm.begin() == "..") {
    return m.Error(path, Quote(file) + " is outside the dataset directory");
  }
  if (const std::string problem = dir.Problem(file); !problem.empty())
    return m.Error(path, Quote(file) + " " + problem);
  return Status::Ok();
}

Status ParseRun(const ManifestContext& m, const FileSource& dir, const json& j, const std::string& path,
                RunData* run, std::vector<std::string>* warnings) {
  if (!j.is_object()) return m.Error(path, "must be an object, found " + JsonTypeName(j));
  static constexpr std::array<std::string_view, 6> kKeys = {"id",        "file",  "supply_V", "supply_pressure_Pa",
                                                            "t_start_s", "split"};
  for (const auto& item : j.items()) {
    if (std::find(kKeys.begin(), kKeys.end(), item.key()) == kKeys.end()) {
      warnings->push_back(m.display + ": " + path + ": unknown key " + Quote(item.key()) + " ignored");
    }
  }
  std::optional<std::string> s;
  VB_RETURN_IF_ERROR(GetString(m, j, "id", path + ".id", true, &s));
  if (s->empty()) return m.Error(path + ".id", "must not be empty");
  run->id = *s;
  VB_RETURN_IF_ERROR(GetString(m, j, "file", path + ".file", true, &s));
  VB_RETURN_IF_ERROR(CheckRunFile(m, dir, *s, path + ".file"));
  run->file = *s;

  VB_RETURN_IF_ERROR(GetNumber(m, j, "supply_V", path + ".supply_V", &run->supply_V));
  if (!(run->supply_V > 0.0)) return m.Error(path + ".supply_V", FormatNumber(run->supply_V) + " must be > 0");
  // The same upper bounds as valve-runs/2 below (and the server's imports): no bench sees more.
  if (run->supply_V > 1e4)
    return m.Error(path + ".supply_V", FormatNumber(run->supply_V) + " V is outside (0, 10000] V");
  VB_RETURN_IF_ERROR(GetNumber(m, j, "supply_pressure_Pa", path + ".supply_pressure_Pa", &run->supply_pressure_Pa));
  if (!(run->supply_pressure_Pa >= 0.0)) {
    return m.Error(path + ".supply_pressure_Pa", FormatNumber(run->supply_pressure_Pa) + " must be >= 0");
  }
  if (run->supply_pressure_Pa > 1e8)
    return m.Error(path + ".supply_pressure_Pa", FormatNumber(run->supply_pressure_Pa) + " Pa is outside [0, 1e+08] Pa");
  VB_RETURN_IF_ERROR(GetNumber(m, j, "t_start_s", path + ".t_start_s", &run->t_start_s));
  if (!(run->t_start_s >= 0.0)) return m.Error(path + ".t_start_s", FormatNumber(run->t_start_s) + " must be >= 0");
  if (run->t_start_s > 1e9)
    return m.Error(path + ".t_start_s", FormatNumber(run->t_start_s) + " s is outside [0, 1e+09] s");

  VB_RETURN_IF_ERROR(GetString(m, j, "split", path + ".split", false, &s));
  if (s) {
    auto split = ParseSplit(*s);
    if (!split.ok() || *split == Split::kNone) return m.Error(path + ".split", Quote(*s) + " is not fit or holdout");
    run->split = *split;
  }
  return Status::Ok();
}

// valve-runs/2: a run of any kind, with its covariates.
Status ParseRunV2(const ManifestContext& m, const FileSource& dir, const json& j, const std::string& path,
                  RunData* run, std::vector<std::string>* warnings) {
  if (!j.is_object()) return m.Error(path, "must be an object, found " + JsonTypeName(j));
  VB_RETURN_IF_ERROR(WarnUnknownKeys(m, j, path,
                                     {"id", "kind", "file", "supply_V", "supply_pressure_Pa", "t_start_s", "split",
                                      "ambient_C", "coil_C", "stroke_m", "from_rest", "gate_edges_s", "pwm_Hz",
                                      "on_time_s", "readings"},
                                     warnings));
  std::optional<std::string> s;
  VB_RETURN_IF_ERROR(GetString(m, j, "id", path + ".id", true, &s));
  if (s->empty()) return m.Error(path + ".id", "must not be empty");
  run->id = *s;
  VB_RETURN_IF_ERROR(GetString(m, j, "kind", path + ".kind", false, &s));
  const std::string kind = s.value_or("waveform");
  if (kind == "waveform") {
    run->kind = RunKind::kWaveform;
  } else if (kind == "samples") {
    run->kind = RunKind::kSamples;
  } else if (kind == "periodic") {
    run->kind = RunKind::kPeriodic;
  } else {
    return m.Error(path + ".kind", Quote(kind) + " is not waveform, samples or periodic");
  }
  auto forbid = [&](const char* key, const char* why) -> Status {
    if (j.find(key) != j.end()) return m.Error(path + "." + key, std::string("not allowed for a ") + kind + " run (" + why + ")");
    return Status::Ok();
  };
  if (run->kind == RunKind::kPeriodic) {
    VB_RETURN_IF_ERROR(forbid("file", "its readings are in the manifest"));
  } else {
    VB_RETURN_IF_ERROR(GetString(m, j, "file", path + ".file", true, &s));
    VB_RETURN_IF_ERROR(CheckRunFile(m, dir, *s, path + ".file"));
    run->file = *s;
  }

  VB_RETURN_IF_ERROR(GetNumber(m, j, "supply_V", path + ".supply_V", &run->supply_V));
  if (!(run->supply_V > 0.0) || run->supply_V > 1e4)
    return m.Error(path + ".supply_V", FormatNumber(run->supply_V) + " V is outside (0, 10000] V");
  run->supply_pressure_Pa = 0.0;
  VB_RETURN_IF_ERROR(GetBounded(m, j, "supply_pressure_Pa", path + ".supply_pressure_Pa", 0.0, 1e8, "Pa",
                                &run->supply_pressure_Pa));
  run->t_start_s = kNaN;
  VB_RETURN_IF_ERROR(GetBounded(m, j, "t_start_s", path + ".t_start_s", 0.0, 1e9, "s", &run->t_start_s));
  VB_RETURN_IF_ERROR(GetString(m, j, "split", path + ".split", false, &s));
  if (s) {
    auto split = ParseSplit(*s);
    if (!split.ok() || *split == Split::kNone) return m.Error(path + ".split", Quote(*s) + " is not fit or holdout");
    run->split = *split;
  }
  VB_RETURN_IF_ERROR(GetBounded(m, j, "ambient_C", path + ".ambient_C", -100.0, 400.0, "C", &run->ambient_C));
  VB_RETURN_IF_ERROR(GetBounded(m, j, "coil_C", path + ".coil_C", -100.0, 400.0, "C", &run->coil_C));
  VB_RETURN_IF_ERROR(GetBounded(m, j, "stroke_m", path + ".stroke_m", 0.0, 1.0, "m", &run->stroke_m));

  if (run->kind != RunKind::kWaveform) VB_RETURN_IF_ERROR(forbid("from_rest", "only a waveform starts somewhere"));
  VB_RETURN_IF_ERROR(GetBool(m, j, "from_rest", path + ".from_rest", &run->from_rest));

  if (run->kind == RunKind::kSamples) {
    const auto it = j.find("gate_edges_s");
    if (it == j.end()) return m.Error(path + ".gate_edges_s", "missing (a samples run needs its gate command)");
    if (!it->is_array()) return m.Error(path + ".gate_edges_s", "must be an array, found " + JsonTypeName(*it));
    for (std::size_t k = 0; k < it->size(); ++k) {
      const std::string ep = path + ".gate_edges_s[" + std::to_string(k) + "]";
      const json& e = (*it)[k];
      if (!e.is_number()) return m.Error(ep, "must be a number, found " + JsonTypeName(e));
      const double t = e.get<double>();
      if (!std::isfinite(t) || t < 0.0) return m.Error(ep, FormatNumber(t) + " s must be finite and >= 0");
      if (!run->gate_edges_s.empty() && !(t > run->gate_edges_s.back()))
        return m.Error(ep, FormatNumber(t) + " s does not come after the previous edge");
      run->gate_edges_s.push_back(t);
    }
  } else {
    VB_RETURN_IF_ERROR(forbid("gate_edges_s", "only samples runs take gate edges"));
  }

  if (run->kind != RunKind::kPeriodic) {
    for (const char* key : {"pwm_Hz", "on_time_s", "readings"})
      VB_RETURN_IF_ERROR(forbid(key, "only periodic runs take it"));
    return Status::Ok();
  }
  VB_RETURN_IF_ERROR(GetNumber(m, j, "pwm_Hz", path + ".pwm_Hz", &run->pwm_Hz));
  if (!(run->pwm_Hz > 0.0) || run->pwm_Hz > 1e6)
    return m.Error(path + ".pwm_Hz", FormatNumber(run->pwm_Hz) + " Hz is outside (0, 1e6] Hz");
  const double period_s = 1.0 / run->pwm_Hz;
  VB_RETURN_IF_ERROR(GetNumber(m, j, "on_time_s", path + ".on_time_s", &run->on_time_s));
  if (!(run->on_time_s > 0.0) || run->on_time_s > period_s * (1.0 + 1e-9)) {
    return m.Error(path + ".on_time_s", FormatNumber(run->on_time_s) + " s is outside (0, " + FormatNumber(period_s) +
                                            "] s, the PWM period");
  }
  run->on_time_s = std::min(run->on_time_s, period_s);
  const auto it = j.find("readings");
  if (it == j.end()) return m.Error(path + ".readings", "missing");
  if (!it->is_array()) return m.Error(path + ".readings", "must be an array, found " + JsonTypeName(*it));
  if (it->empty()) return m.Error(path + ".readings", "must not be empty");
  for (std::size_t k = 0; k < it->size(); ++k) {
    const std::string rp = path + ".readings[" + std::to_string(k) + "]";
    const json& r = (*it)[k];
    if (!r.is_object()) return m.Error(rp, "must be an object, found " + JsonTypeName(r));
    VB_RETURN_IF_ERROR(WarnUnknownKeys(m, r, rp, {"t_after_edge_s", "i_A", "sd_A", "repeats"}, warnings));
    double t = 0.0, i = 0.0, sd = 0.0, n = 1.0;
    VB_RETURN_IF_ERROR(GetNumber(m, r, "t_after_edge_s", rp + ".t_after_edge_s", &t));
    if (t < 0.0 || !(t < period_s)) {
      return m.Error(rp + ".t_after_edge_s", FormatNumber(t) + " s is outside [0, " + FormatNumber(period_s) +
                                                 ") s, the PWM period");
    }
    VB_RETURN_IF_ERROR(GetNumber(m, r, "i_A", rp + ".i_A", &i));
    if (std::abs(i) > 1e3) return m.Error(rp + ".i_A", FormatNumber(i) + " A is outside [-1000, 1000] A");
    VB_RETURN_IF_ERROR(GetBounded(m, r, "sd_A", rp + ".sd_A", 0.0, 1e3, "A", &sd));
    VB_RETURN_IF_ERROR(GetBounded(m, r, "repeats", rp + ".repeats", 1.0, 1e9, "repeats", &n));
    if (n != std::floor(n)) return m.Error(rp + ".repeats", FormatNumber(n) + " is not a whole number");
    run->t_s.push_back(t);
    run->i_A.push_back(i);
    run->i_sd_A.push_back(sd);
    run->repeats.push_back(static_cast<int>(n));
  }
  return Status::Ok();
}

Status ParseSensor(const ManifestContext& m, const json& root, SensorChain* sc, std::vector<std::string>* warnings) {
  const auto it = root.find("sensor");
  if (it == root.end()) return Status::Ok();
  if (!it->is_object()) return m.Error("sensor", "must be an object, found " + JsonTypeName(*it));
  const json& j = *it;
  VB_RETURN_IF_ERROR(WarnUnknownKeys(m, j, "sensor",
                                     {"shunt_ohm", "shunt_in_switch_path", "amplifier_gain", "adc_lsb_V", "adc_lsb_A",
                                      "noise_A", "offset_A", "averaged"},
                                     warnings));
  VB_RETURN_IF_ERROR(GetBounded(m, j, "shunt_ohm", "sensor.shunt_ohm", 1e-6, 1e6, "ohm", &sc->shunt_ohm));
  VB_RETURN_IF_ERROR(GetBool(m, j, "shunt_in_switch_path", "sensor.shunt_in_switch_path", &sc->shunt_in_switch_path));
  if (sc->shunt_in_switch_path && !std::isfinite(sc->shunt_ohm))
    return m.Error("sensor.shunt_in_switch_path", "needs sensor.shunt_ohm");
  VB_RETURN_IF_ERROR(GetBounded(m, j, "amplifier_gain", "sensor.amplifier_gain", 1e-6, 1e9, "V/V", &sc->amplifier_gain));
  VB_RETURN_IF_ERROR(GetBounded(m, j, "adc_lsb_V", "sensor.adc_lsb_V", 1e-12, 10.0, "V", &sc->adc_lsb_V));
  VB_RETURN_IF_ERROR(GetBounded(m, j, "adc_lsb_A", "sensor.adc_lsb_A", 1e-15, 10.0, "A", &sc->adc_lsb_A));
  VB_RETURN_IF_ERROR(GetBounded(m, j, "noise_A", "sensor.noise_A", 0.0, 10.0, "A", &sc->noise_A));
  VB_RETURN_IF_ERROR(GetBounded(m, j, "offset_A", "sensor.offset_A", -10.0, 10.0, "A", &sc->offset_A));
  double averaged = 1.0;
  VB_RETURN_IF_ERROR(GetBounded(m, j, "averaged", "sensor.averaged", 1.0, 1e9, "readings", &averaged));
  if (averaged != std::floor(averaged)) return m.Error("sensor.averaged", FormatNumber(averaged) + " is not a whole number");
  sc->averaged = static_cast<int>(averaged);
  if (std::isfinite(sc->adc_lsb_V) && !std::isfinite(sc->adc_lsb_A)) {
    if (!std::isfinite(sc->shunt_ohm) || !std::isfinite(sc->amplifier_gain))
      return m.Error("sensor.adc_lsb_V", "needs sensor.shunt_ohm and sensor.amplifier_gain to convert to amperes");
    sc->adc_lsb_A = sc->adc_lsb_V / (sc->shunt_ohm * sc->amplifier_gain);
  }
  return Status::Ok();
}

Status ParseDriver(const ManifestContext& m, const json& root, model::DriverParams* d, std::vector<std::string>* warnings) {
  const auto it = root.find("driver");
  if (it == root.end()) return Status::Ok();
  if (!it->is_object()) return m.Error("driver", "must be an object, found " + JsonTypeName(*it));
  for (const auto& item : it->items()) {
    const std::string path = "driver." + item.key();
    if (item.key() == "kind") {
      if (!item.value().is_string()) return m.Error(path, "must be a string, found " + JsonTypeName(item.value()));
      auto kind = model::ParseDriverKind(item.value().get<std::string>());
      if (!kind.ok()) return m.Error(path, kind.status().message());
      d->kind = *kind;
      continue;
    }
    if (!item.value().is_number()) return m.Error(path, "must be a number, found " + JsonTypeName(item.value()));
    auto st = model::SetDriverParam(d, item.key(), item.value().get<double>());
    if (!st.ok()) return m.Error(path, st.message());
  }
  (void)warnings;
  auto st = model::Validate(*d);
  if (!st.ok()) return m.Error("driver", st.message());
  return Status::Ok();
}

Status ParseManifest(const ManifestContext& m, const FileSource& dir, std::string_view text,
                     const std::vector<std::string>& known_models, Dataset* ds) {
  json root;
  try {
    root = json::parse(text);
  } catch (const json::exception& e) {
    std::string what = e.what();
    if (!what.empty() && what.front() == '[') {  // drop "[json.exception.parse_error.101] "
      const size_t close = what.find("] ");
      if (close != std::string::npos) what.erase(0, close + 2);
    }
    return m.Error("", "not valid JSON: " + what);
  }
  if (!root.is_object()) return m.Error("", "must be a JSON object, found " + JsonTypeName(root));
  std::optional<std::string> s;
  VB_RETURN_IF_ERROR(GetString(m, root, "format", "format", true, &s));
  if (*s != kFormatValveRuns1 && *s != kFormatValveRuns2) {
    return m.Error("format", Quote(*s) + " is not " + std::string(kFormatValveRuns1) + " or " +
                                 std::string(kFormatValveRuns2));
  }
  ds->format = *s;
  const bool v2 = ds->format == kFormatValveRuns2;
  if (v2) {
    VB_RETURN_IF_ERROR(WarnUnknownKeys(m, root, "", {"format", "model", "description", "runs", "device", "sensor", "driver"},
                                       &ds->warnings));
    VB_RETURN_IF_ERROR(GetString(m, root, "device", "device", false, &s));
    ds->device = s.value_or("");
    VB_RETURN_IF_ERROR(ParseSensor(m, root, &ds->sensor, &ds->warnings));
    VB_RETURN_IF_ERROR(ParseDriver(m, root, &ds->driver, &ds->warnings));
  } else {
    VB_RETURN_IF_ERROR(WarnUnknownKeys(m, root, "", {"format", "model", "description", "runs"}, &ds->warnings));
  }

  VB_RETURN_IF_ERROR(GetString(m, root, "model", "model", true, &s));
  const bool model_file = v2 && s->size() > 5 && s->substr(s->size() - 5) == ".json" &&
                          std::find(known_models.begin(), known_models.end(), *s) == known_models.end();
  if (model_file) {
    VB_RETURN_IF_ERROR(CheckRunFile(m, dir, *s, "model"));
    ds->model_file = dir.Where(*s);
  } else if (std::find(known_models.begin(), known_models.end(), *s) == known_models.end()) {
    std::string known;
    for (const auto& k : known_models) known += (known.empty() ? "" : ", ") + k;
    return m.Error("model", Quote(*s) + " is not a known model (known: " + (known.empty() ? "none" : known) + ")" +
                                (v2 ? " nor a model file (NAME.json in the dataset directory)" : ""));
  }
  ds->model = *s;

  VB_RETURN_IF_ERROR(GetString(m, root, "description", "description", false, &s));
  ds->description = s.value_or("");

  const auto runs = root.find("runs");
  if (runs == root.end()) return m.Error("runs", "missing");
  if (!runs->is_array()) return m.Error("runs", "must be an array, found " + JsonTypeName(*runs));
  if (runs->empty()) return m.Error("runs", "must not be empty");

  std::unordered_map<std::string, size_t> index_of_id;
  ds->runs.resize(runs->size());
  for (size_t k = 0; k < runs->size(); ++k) {
    const std::string path = "runs[" + std::to_string(k) + "]";
    RunData& run = ds->runs[k];
    if (v2) {
      VB_RETURN_IF_ERROR(ParseRunV2(m, dir, (*runs)[k], path, &run, &ds->warnings));
    } else {
      VB_RETURN_IF_ERROR(ParseRun(m, dir, (*runs)[k], path, &run, &ds->warnings));
    }
    const auto [it, inserted] = index_of_id.emplace(run.id, k);
    if (!inserted) {
      return m.Error(path + ".id", Quote(run.id) + " is also the id of runs[" + std::to_string(it->second) + "]");
    }
    if (k > 0 && std::isfinite(run.t_start_s) && run.t_start_s < ds->runs[k - 1].t_start_s) {
      const RunData& prev = ds->runs[k - 1];
      return m.Error(path + ".t_start_s", "run " + Quote(run.id) + " starts at " + FormatNumber(run.t_start_s) +
                                              " s, before runs[" + std::to_string(k - 1) + "] " + Quote(prev.id) +
                                              " at " + FormatNumber(prev.t_start_s) +
                                              " s; runs must be listed in time order");
    }
  }
  return Status::Ok();
}

// The current at a waveform's start: the mean of its first n samples.
double StartCurrent(const RunData& run, std::size_t n) {
  n = std::min(n, run.i_A.size());
  double sum = 0.0;
  for (std::size_t k = 0; k < n; ++k) sum += run.i_A[k];
  return n > 0 ? sum / static_cast<double>(n) : 0.0;
}

}  // namespace

std::vector<std::string> DefaultKnownModels() { return {model::kDefaultPreset}; }

namespace {

// The dataset named `name` (errors start with it) from `dir`'s files: the manifest, then every run's file.
StatusOr<Dataset> LoadFrom(const std::string& name, const FileSource& dir, const std::vector<std::string>& known_models,
                           Dataset ds) {
  const ManifestContext m{name + "/manifest.json"};
  if (const std::string problem = dir.Problem("manifest.json"); !problem.empty()) return m.Error("", problem);
  std::string text;
  VB_RETURN_IF_ERROR(dir.Read("manifest.json", m.display, &text));
  VB_RETURN_IF_ERROR(ParseManifest(m, dir, text, known_models, &ds));

  for (std::size_t k = 0; k < ds.runs.size(); ++k) {
    RunData& run = ds.runs[k];
    if (run.kind == RunKind::kPeriodic) continue;
    const std::string display = name + "/" + run.file;
    VB_RETURN_IF_ERROR(dir.Read(run.file, display, &text));
    VB_RETURN_IF_ERROR(ParseCsv(text, display, &run, &ds.warnings));
    if (run.kind == RunKind::kWaveform && run.from_rest) {
      // A waveform is replayed from rest unless it says otherwise: one that plainly does not start there
      // would be compared with the wrong model response. Judged on the samples before the gate first turns
      // on (at switch-on the terminal current may jump even from rest, e.g. through an eddy-current path):
      // with the coil undriven, a current well above the noise means it was still carrying one.
      std::size_t idle = 0;
      while (idle < run.gate.size() && run.gate[idle] == 0) ++idle;
      idle = std::min<std::size_t>(idle, 20);
      const double first = StartCurrent(run, idle) - ds.sensor.offset_A;
      const double noise = std::max(SecondDifferenceSigma(run.i_A), std::isfinite(ds.sensor.noise_A) ? ds.sensor.noise_A : 0.0);
      double peak = 0.0;
      for (double i : run.i_A) peak = std::max(peak, std::abs(i - ds.sensor.offset_A));
      if (idle >= 3 && std::abs(first) > std::max(6.0 * noise, 0.02 * peak)) {
        const std::string what = "run " + Quote(run.id) + " starts at i_A = " + FormatNumber(first) +
                                 " A, not at rest (noise about " + FormatNumber(noise) + " A)";
        if (ds.format == kFormatValveRuns2) {
          return m.Error("runs[" + std::to_string(k) + "].from_rest",
                         what + "; declare \"from_rest\": false, or trim the file to start at rest");
        }
        ds.warnings.push_back(m.display + ": runs[" + std::to_string(k) + "]: " + what +
                              "; valve-runs/1 replays every run from rest");
      }
    }
  }
  return ds;
}

}  // namespace

StatusOr<Dataset> LoadDataset(const std::string& directory, const std::vector<std::string>& known_models) {
  const fs::path dir(directory);
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    return Status::InvalidArgument(directory + ": " +
                                   (fs::exists(dir, ec) ? "is not a directory" : "dataset directory does not exist"));
  }
  Dataset ds;
  ds.directory = directory;
  return LoadFrom(DatasetName(directory), DirectorySource(dir), known_models, std::move(ds));
}

StatusOr<Dataset> LoadDatasetFromFiles(const std::string& name, const std::map<std::string, std::string>& files,
                                       const std::vector<std::string>& known_models) {
  if (name.empty()) return Status::InvalidArgument("dataset: the name must not be empty");
  return LoadFrom(name, MemorySource(files), known_models, Dataset{});
}

double SecondDifferenceSigma(const std::vector<double>& i) {
  if (i.size() < 3) return 0.0;
  double s = 0.0;
  for (std::size_t k = 2; k < i.size(); ++k) {
    const double d2 = i[k] - 2.0 * i[k - 1] + i[k - 2];
    s += d2 * d2;
  }
  return std::sqrt(s / static_cast<double>(i.size() - 2) / 6.0);
}

double SecondDifferenceSigma(const std::vector<double>& i, const std::vector<int8_t>& gate, double sample_period_s) {
  if (i.size() < 3 || gate.size() != i.size() || !(sample_period_s > 0.0) || !std::isfinite(sample_period_s))
    return SecondDifferenceSigma(i);
  const auto guard = static_cast<std::ptrdiff_t>(std::max(2.0, std::ceil(kNoiseEdgeGuard_s / sample_period_s)));
  const auto n = static_cast<std::ptrdiff_t>(i.size());
  // near[k]: sample k lies within the guard of an edge (an edge between samples e and e + 1).
  std::vector<bool> near(i.size(), false);
  for (std::ptrdiff_t e = 0; e + 1 < n; ++e) {
    if (gate[static_cast<std::size_t>(e)] == gate[static_cast<std::size_t>(e + 1)]) continue;
    for (std::ptrdiff_t k = std::max<std::ptrdiff_t>(0, e - guard); k <= std::min(n - 1, e + 1 + guard); ++k)
      near[static_cast<std::size_t>(k)] = true;
  }
  double s = 0.0;
  std::size_t used = 0;
  for (std::size_t k = 2; k < i.size(); ++k) {
    if (near[k] || near[k - 1] || near[k - 2]) continue;
    const double d2 = i[k] - 2.0 * i[k - 1] + i[k - 2];
    s += d2 * d2;
    ++used;
  }
  if (2 * used < i.size() - 2) return SecondDifferenceSigma(i);
  return std::sqrt(s / static_cast<double>(used) / 6.0);
}

std::string_view RunKindName(RunKind k) {
  switch (k) {
    case RunKind::kWaveform: return "waveform";
    case RunKind::kSamples: return "samples";
    case RunKind::kPeriodic: return "periodic";
  }
  return "?";
}

std::vector<double> DeclaredStandardErrors(const Dataset& ds, const RunData& run) {
  const SensorChain& sc = ds.sensor;
  const bool any = !run.i_sd_A.empty() || std::isfinite(sc.adc_lsb_A) || std::isfinite(sc.noise_A);
  if (!any) return {};
  std::vector<double> se(run.i_A.size());
  for (std::size_t k = 0; k < se.size(); ++k) {
    const double n = run.repeats.empty() ? 1.0 : static_cast<double>(run.repeats[k]);
    const double sd = run.i_sd_A.empty() ? 0.0 : run.i_sd_A[k];
    double v = sd * sd / n;
    if (std::isfinite(sc.adc_lsb_A)) {
      // Rounding to the ADC step: uniform, LSB^2/12. Repeats that all read the same step carry no dither, so
      // their mean keeps the whole rounding error; spread repeats average it down.
      const double q2 = sc.adc_lsb_A * sc.adc_lsb_A / 12.0;
      v += sd > 0.0 ? q2 / n : q2;
    }
    if (std::isfinite(sc.noise_A)) v += sc.noise_A * sc.noise_A / (n * static_cast<double>(sc.averaged));
    se[k] = std::sqrt(v);
  }
  return se;
}

}  // namespace vb::gap
