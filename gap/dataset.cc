#include "common/format.h"
#include "gap/dataset.h"

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

// ---- CSV -------------------------------------------------------------------------------------------------

enum class Column { kT, kGate, kI, kX, kVCoil, kUnknown };

Column ColumnOf(std::string_view name) {
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
  const std::string needs_header = "; expected a header row such as t_s,gate,i_A";
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
    roles.push_back(ColumnOf(name));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  for (const char* required : {"t_s", "gate", "i_A"}) {
    if (std::find(names.begin(), names.end(), required) == names.end()) {
      return Status::InvalidArgument(display + ":1: missing required column " + required + " (header " +
                                     Quote(header) + ")");
    }
  }
  bool has_x = false, has_v = false;
  for (size_t c = 0; c < roles.size(); ++c) {
    if (roles[c] == Column::kX) has_x = true;
    if (roles[c] == Column::kVCoil) has_v = true;
    if (roles[c] == Column::kUnknown) {
      warnings->push_back(display + ": column " + Quote(names[c]) +
                          " is not a valve-runs/1 column (t_s, gate, i_A, x_m, v_coil_V); ignored");
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
        case Column::kUnknown: break;
      }
    }
    // Uniform sampling from t = 0, checked as the rows come so the first bad line is the one named.
    const size_t k = run->t_s.size() - 1;
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

Status CheckRunFile(const ManifestContext& m, const fs::path& dir, const std::string& file,
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
  std::error_code ec;
  const fs::file_status st = fs::status(dir / p, ec);
  if (!fs::exists(st)) return m.Error(path, Quote(file) + " does not exist");
  if (!fs::is_regular_file(st)) return m.Error(path, Quote(file) + " is not a regular file");
  return Status::Ok();
}

Status ParseRun(const ManifestContext& m, const fs::path& dir, const json& j, const std::string& path,
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
  VB_RETURN_IF_ERROR(GetNumber(m, j, "supply_pressure_Pa", path + ".supply_pressure_Pa", &run->supply_pressure_Pa));
  if (!(run->supply_pressure_Pa >= 0.0)) {
    return m.Error(path + ".supply_pressure_Pa", FormatNumber(run->supply_pressure_Pa) + " must be >= 0");
  }
  VB_RETURN_IF_ERROR(GetNumber(m, j, "t_start_s", path + ".t_start_s", &run->t_start_s));
  if (!(run->t_start_s >= 0.0)) return m.Error(path + ".t_start_s", FormatNumber(run->t_start_s) + " must be >= 0");

  VB_RETURN_IF_ERROR(GetString(m, j, "split", path + ".split", false, &s));
  run->split = s.value_or("");
  if (s && *s != "fit" && *s != "holdout") return m.Error(path + ".split", Quote(*s) + " is not fit or holdout");
  return Status::Ok();
}

Status ParseManifest(const ManifestContext& m, const fs::path& dir, std::string_view text,
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
  static constexpr std::array<std::string_view, 4> kKeys = {"format", "model", "description", "runs"};
  for (const auto& item : root.items()) {
    if (std::find(kKeys.begin(), kKeys.end(), item.key()) == kKeys.end()) {
      ds->warnings.push_back(m.display + ": unknown key " + Quote(item.key()) + " ignored");
    }
  }

  std::optional<std::string> s;
  VB_RETURN_IF_ERROR(GetString(m, root, "format", "format", true, &s));
  if (*s != kFormatValveRuns1) {
    return m.Error("format", Quote(*s) + " is not " + std::string(kFormatValveRuns1));
  }
  ds->format = *s;

  VB_RETURN_IF_ERROR(GetString(m, root, "model", "model", true, &s));
  if (std::find(known_models.begin(), known_models.end(), *s) == known_models.end()) {
    std::string known;
    for (const auto& k : known_models) known += (known.empty() ? "" : ", ") + k;
    return m.Error("model", Quote(*s) + " is not a known model (known: " + (known.empty() ? "none" : known) + ")");
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
    VB_RETURN_IF_ERROR(ParseRun(m, dir, (*runs)[k], path, &run, &ds->warnings));
    const auto [it, inserted] = index_of_id.emplace(run.id, k);
    if (!inserted) {
      return m.Error(path + ".id", Quote(run.id) + " is also the id of runs[" + std::to_string(it->second) + "]");
    }
    if (k > 0 && run.t_start_s < ds->runs[k - 1].t_start_s) {
      const RunData& prev = ds->runs[k - 1];
      return m.Error(path + ".t_start_s", "run " + Quote(run.id) + " starts at " + FormatNumber(run.t_start_s) +
                                              " s, before runs[" + std::to_string(k - 1) + "] " + Quote(prev.id) +
                                              " at " + FormatNumber(prev.t_start_s) +
                                              " s; runs must be listed in time order");
    }
  }
  return Status::Ok();
}

}  // namespace

std::vector<std::string> DefaultKnownModels() { return {"taghizadeh2009"}; }

StatusOr<Dataset> LoadDataset(const std::string& directory, const std::vector<std::string>& known_models) {
  const std::string name = DatasetName(directory);
  const fs::path dir(directory);
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) {
    return Status::InvalidArgument(directory + ": " +
                                   (fs::exists(dir, ec) ? "is not a directory" : "dataset directory does not exist"));
  }

  Dataset ds;
  ds.directory = directory;
  const ManifestContext m{name + "/manifest.json"};
  const fs::path manifest_path = dir / "manifest.json";
  if (!fs::is_regular_file(manifest_path, ec)) {
    return m.Error("", fs::exists(manifest_path, ec) ? "is not a regular file" : "does not exist");
  }
  std::string text;
  VB_RETURN_IF_ERROR(ReadFile(manifest_path, m.display, &text));
  VB_RETURN_IF_ERROR(ParseManifest(m, dir, text, known_models, &ds));

  for (RunData& run : ds.runs) {
    const std::string display = name + "/" + run.file;
    VB_RETURN_IF_ERROR(ReadFile(dir / run.file, display, &text));
    VB_RETURN_IF_ERROR(ParseCsv(text, display, &run, &ds.warnings));
  }
  return ds;
}

}  // namespace vb::gap
