#include "experiment/spec.h"

#include <google/protobuf/descriptor.h>
#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>

#include "common/edit_distance.h"
#include "common/format.h"
#include "control/open_loop_pwm.h"
#include "experiment/bounds.h"
#include "experiment/controllers.h"
#include "common/bench_kind.h"
#include "model/params.h"

namespace vb::experiment {

std::string BenchClassOf(const ExperimentSpec& spec) {
  const std::string& kind = spec.bench().kind();
  // An unknown kind is refused where the spec is built (BuildExperiment); here it is its own class.
  auto parsed = ParseBenchKind(kind);
  if (!parsed.ok()) return kind;
  const std::string& preset = spec.bench().model().preset();
  return BenchClass(*parsed, preset.empty() ? std::string_view(model::kDefaultPreset) : std::string_view(preset));
}

namespace pb = google::protobuf;
using valvebench::v1::ControllerSpec;

namespace {

// protobuf's "(LOC) NAME: Cannot find field." for a misspelt field, rewritten as "LOC.NAME: unknown field; did
// you mean 'X'?" with X the closest field of that message (docs/spec.md: specs reject unknown fields, so a
// typo never falls back to a default). Other messages pass through unchanged.
std::string ExplainUnknownField(const std::string& message) {
  static constexpr std::string_view kTail = ": Cannot find field.";
  const std::size_t tail = message.rfind(kTail);
  if (tail == std::string::npos) return message;
  std::string loc, name = message.substr(0, tail);
  if (!name.empty() && name.front() == '(') {
    const std::size_t close = name.find(") ");
    if (close == std::string::npos) return message;
    loc = name.substr(1, close - 1);
    name = name.substr(close + 2);
  }
  const pb::Descriptor* d = ExperimentSpec::descriptor();
  std::size_t start = 0;
  while (d != nullptr && start < loc.size()) {
    std::size_t end = loc.find('.', start);
    if (end == std::string::npos) end = loc.size();
    std::string part = loc.substr(start, end - start);
    if (const std::size_t bracket = part.find('['); bracket != std::string::npos) part.resize(bracket);
    const pb::FieldDescriptor* f = d->FindFieldByName(part);
    for (int k = 0; f == nullptr && k < d->field_count(); ++k)
      if (d->field(k)->json_name() == part) f = d->field(k);
    d = f != nullptr ? f->message_type() : nullptr;
    start = end + 1;
  }
  if (d == nullptr || d->options().map_entry()) return message;
  std::string best;
  std::size_t best_d = std::string::npos;
  std::string known;
  for (int k = 0; k < d->field_count(); ++k) {
    const std::string& candidate = d->field(k)->name();
    known += (k ? ", " : "") + candidate;
    if (const std::size_t dist = EditDistance(name, candidate, /*ignore_case=*/true); dist < best_d) {
      best_d = dist;
      best = candidate;
    }
  }
  const std::string path = loc.empty() ? name : loc + "." + name;
  if (!best.empty() && best_d <= std::max<std::size_t>(2, name.size() / 3))
    return path + ": unknown field; did you mean '" + best + "'?";
  return path + ": unknown field (known here: " + known + ")";
}

}  // namespace

StatusOr<ExperimentSpec> ParseSpecJson(std::string_view json) {
  ExperimentSpec spec;
  pb::util::JsonParseOptions opts;
  opts.ignore_unknown_fields = false;
  auto st = pb::util::JsonStringToMessage(pb::StringPiece(json.data(), json.size()), &spec, opts);
  if (!st.ok()) return Status::InvalidArgument(ExplainUnknownField(std::string(st.message())));
  return spec;
}

StatusOr<ExperimentSpec> LoadSpecFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) return Status::NotFound(path + ": cannot open the spec file");
  std::stringstream ss;
  ss << in.rdbuf();
  auto spec = ParseSpecJson(ss.str());
  if (!spec.ok()) return spec.status().WithContext(path);
  return spec;
}

std::string SpecToJson(const ExperimentSpec& spec, bool pretty) {
  std::string out;
  pb::util::JsonPrintOptions opts;
  opts.add_whitespace = pretty;
  opts.preserve_proto_field_names = true;
  (void)pb::util::MessageToJsonString(spec, &out, opts);
  return out;
}

// ---------------------------------------------------------------------------------------------------------
// Field paths, through protobuf reflection.
namespace {

struct PathToken {
  std::string name;
  bool has_index = false;
  int index = 0;
  bool has_key = false;
  std::string key;
};

StatusOr<std::vector<PathToken>> ParsePath(std::string_view path) {
  std::vector<PathToken> out;
  size_t pos = 0;
  while (pos <= path.size()) {
    size_t dot = path.find('.', pos);
    std::string_view part = path.substr(pos, dot == std::string_view::npos ? std::string_view::npos : dot - pos);
    PathToken tok;
    size_t br = part.find('[');
    tok.name = std::string(part.substr(0, br));
    if (br != std::string_view::npos) {
      if (part.back() != ']') return Status::InvalidArgument("field path '" + std::string(path) + "': missing ']'");
      std::string inner(part.substr(br + 1, part.size() - br - 2));
      if (!inner.empty() && inner.find_first_not_of("0123456789") == std::string::npos) {
        tok.has_index = true;
        // from_chars, not stoi: an index too large for int is an error, not an exception.
        const auto [end, ec] = std::from_chars(inner.data(), inner.data() + inner.size(), tok.index);
        if (ec != std::errc() || end != inner.data() + inner.size())
          return Status::InvalidArgument("field path '" + std::string(path) + "': index " + inner + " is too large");
      } else {
        tok.has_key = true;
        tok.key = inner;
      }
    }
    if (tok.name.empty()) return Status::InvalidArgument("field path '" + std::string(path) + "': empty component");
    out.push_back(tok);
    if (dot == std::string_view::npos) break;
    pos = dot + 1;
  }
  return out;
}

const pb::FieldDescriptor* FindField(const pb::Descriptor* d, const std::string& name) {
  const pb::FieldDescriptor* f = d->FindFieldByName(name);
  if (f == nullptr) f = d->FindFieldByCamelcaseName(name);
  if (f == nullptr) {
    for (int k = 0; k < d->field_count(); ++k)
      if (d->field(k)->json_name() == name) return d->field(k);
  }
  return f;
}


// Walks the path; when `set` is true creates what is missing and writes *value, else reads into *value.
Status WalkPath(pb::Message* msg, std::string_view path, double* value, bool set) {
  auto tokens = ParsePath(path);
  if (!tokens.ok()) return tokens.status();
  const std::string where = "field path '" + std::string(path) + "'";
  pb::Message* cur = msg;
  for (size_t t = 0; t < tokens->size(); ++t) {
    const PathToken& tok = (*tokens)[t];
    const bool last = t + 1 == tokens->size();
    const pb::Reflection* r = cur->GetReflection();
    const pb::FieldDescriptor* f = FindField(cur->GetDescriptor(), tok.name);
    if (f == nullptr)
      return Status::InvalidArgument(where + ": no field '" + tok.name + "' in " + cur->GetDescriptor()->name());
    if (f->is_map()) {
      if (!tok.has_key || !last) return Status::InvalidArgument(where + ": map field '" + tok.name + "' needs [key] last");
      const pb::Descriptor* entry = f->message_type();
      const pb::FieldDescriptor* kf = entry->FindFieldByName("key");
      const pb::FieldDescriptor* vf = entry->FindFieldByName("value");
      if (vf->cpp_type() != pb::FieldDescriptor::CPPTYPE_DOUBLE)
        return Status::InvalidArgument(where + ": map values are not numbers");
      for (int k = 0; k < r->FieldSize(*cur, f); ++k) {
        pb::Message* e = r->MutableRepeatedMessage(cur, f, k);
        if (e->GetReflection()->GetString(*e, kf) == tok.key) {
          if (set)
            e->GetReflection()->SetDouble(e, vf, *value);
          else
            *value = e->GetReflection()->GetDouble(*e, vf);
          return Status::Ok();
        }
      }
      if (!set) return Status::NotFound(where + ": no entry '" + tok.key + "'");
      pb::Message* e = r->AddMessage(cur, f);
      e->GetReflection()->SetString(e, kf, tok.key);
      e->GetReflection()->SetDouble(e, vf, *value);
      return Status::Ok();
    }
    if (f->is_repeated()) {
      if (!tok.has_index) return Status::InvalidArgument(where + ": repeated field '" + tok.name + "' needs [index]");
      if (tok.index >= r->FieldSize(*cur, f))
        return Status::InvalidArgument(where + ": index " + std::to_string(tok.index) + " out of range (size " +
                                       std::to_string(r->FieldSize(*cur, f)) + ")");
      if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) {
        if (last) return Status::InvalidArgument(where + ": ends at a message, not a number");
        cur = r->MutableRepeatedMessage(cur, f, tok.index);
        continue;
      }
      if (!last || f->cpp_type() != pb::FieldDescriptor::CPPTYPE_DOUBLE)
        return Status::InvalidArgument(where + ": only repeated double fields can be swept");
      if (set)
        r->SetRepeatedDouble(cur, f, tok.index, *value);
      else
        *value = r->GetRepeatedDouble(*cur, f, tok.index);
      return Status::Ok();
    }
    if (f->cpp_type() == pb::FieldDescriptor::CPPTYPE_MESSAGE) {
      if (last) return Status::InvalidArgument(where + ": ends at a message, not a number");
      if (!set && !r->HasField(*cur, f)) return Status::NotFound(where + ": '" + tok.name + "' is not set");
      cur = r->MutableMessage(cur, f);
      continue;
    }
    if (!last || !IsNumericField(f)) return Status::InvalidArgument(where + ": '" + tok.name + "' is not a number");
    if (set && f->cpp_type() != pb::FieldDescriptor::CPPTYPE_DOUBLE &&
        f->cpp_type() != pb::FieldDescriptor::CPPTYPE_FLOAT) {
      // An integer field takes whole values of its type only; a cast of anything else would be undefined.
      const bool is_signed = f->cpp_type() == pb::FieldDescriptor::CPPTYPE_INT32 ||
                             f->cpp_type() == pb::FieldDescriptor::CPPTYPE_INT64;
      const bool wide = f->cpp_type() == pb::FieldDescriptor::CPPTYPE_INT64 ||
                        f->cpp_type() == pb::FieldDescriptor::CPPTYPE_UINT64;
      const double lo = is_signed ? (wide ? -0x1p63 : -0x1p31) : 0.0;
      const double hi = is_signed ? (wide ? 0x1p63 : 0x1p31) : (wide ? 0x1p64 : 0x1p32);
      if (!(*value >= lo && *value < hi) || *value != std::floor(*value))
        return Status::InvalidArgument(where + ": " + FormatNumber(*value) + " is not a whole number in the range of " +
                                       f->type_name());
    }
    if (set) {
      const double v = *value;
      switch (f->cpp_type()) {
        case pb::FieldDescriptor::CPPTYPE_DOUBLE: r->SetDouble(cur, f, v); break;
        case pb::FieldDescriptor::CPPTYPE_FLOAT: r->SetFloat(cur, f, static_cast<float>(v)); break;
        case pb::FieldDescriptor::CPPTYPE_INT32: r->SetInt32(cur, f, static_cast<int32_t>(std::lround(v))); break;
        case pb::FieldDescriptor::CPPTYPE_UINT32: r->SetUInt32(cur, f, static_cast<uint32_t>(std::lround(v))); break;
        case pb::FieldDescriptor::CPPTYPE_INT64: r->SetInt64(cur, f, std::llround(v)); break;
        case pb::FieldDescriptor::CPPTYPE_UINT64: r->SetUInt64(cur, f, static_cast<uint64_t>(std::llround(v))); break;
        default: break;
      }
    } else {
      switch (f->cpp_type()) {
        case pb::FieldDescriptor::CPPTYPE_DOUBLE: *value = r->GetDouble(*cur, f); break;
        case pb::FieldDescriptor::CPPTYPE_FLOAT: *value = r->GetFloat(*cur, f); break;
        case pb::FieldDescriptor::CPPTYPE_INT32: *value = r->GetInt32(*cur, f); break;
        case pb::FieldDescriptor::CPPTYPE_UINT32: *value = r->GetUInt32(*cur, f); break;
        case pb::FieldDescriptor::CPPTYPE_INT64: *value = static_cast<double>(r->GetInt64(*cur, f)); break;
        case pb::FieldDescriptor::CPPTYPE_UINT64: *value = static_cast<double>(r->GetUInt64(*cur, f)); break;
        default: break;
      }
    }
    return Status::Ok();
  }
  return Status::InvalidArgument(where + ": empty");
}

}  // namespace

Status SetFieldByPath(ExperimentSpec* spec, std::string_view path, double value) {
  return WalkPath(spec, path, &value, true);
}

StatusOr<double> GetFieldByPath(const ExperimentSpec& spec, std::string_view path) {
  ExperimentSpec copy = spec;  // WalkPath takes a mutable message; reading does not change it
  double v = 0.0;
  VB_RETURN_IF_ERROR(WalkPath(&copy, path, &v, false));
  return v;
}

StatusOr<std::vector<ExperimentSpec>> ExpandSweep(const ExperimentSpec& spec, size_t max_runs) {
  auto runs = ExpandRuns(spec, max_runs);
  if (!runs.ok()) return runs.status();
  std::vector<ExperimentSpec> out;
  out.reserve(runs->size());
  for (auto& r : *runs) out.push_back(std::move(r.spec));
  return out;
}

StatusOr<std::vector<RunPoint>> ExpandRuns(const ExperimentSpec& spec, size_t max_runs) {
  // Bounds first, and the count before any copy: 4294967295 repeats is a field-named error, not a bad_alloc.
  VB_RETURN_IF_ERROR(CheckSpecBounds(spec));
  if (const std::uint64_t count = CountRuns(spec); count > max_runs)
    return Status::ResourceExhausted("sweep: expands to " + std::to_string(count) + " runs, more than " +
                                     std::to_string(max_runs) + " runs");
  if (spec.variants_size() > 0) {
    std::vector<RunPoint> out;
    for (int v = 0; v < spec.variants_size(); ++v) {
      const ExperimentSpec& overlay = spec.variants(v);
      if (overlay.variants_size() > 0)
        return Status::InvalidArgument("variants[" + std::to_string(v) + "].variants: variants do not nest");
      ExperimentSpec merged = spec;
      merged.clear_variants();
      if (overlay.has_controller()) merged.clear_controller();  // a variant's law replaces the base law
      merged.MergeFrom(overlay);
      merged.set_name(spec.name() + "/" + (overlay.name().empty() ? std::to_string(v) : overlay.name()));
      auto runs = ExpandRuns(merged, max_runs - out.size());
      if (!runs.ok()) return runs.status().WithContext("variants[" + std::to_string(v) + "]");
      for (auto& r : *runs) out.push_back(std::move(r));
    }
    return out;
  }
  std::vector<std::pair<std::string, std::vector<double>>> axes;
  for (int a = 0; a < spec.sweep_size(); ++a) {
    const auto& ax = spec.sweep(a);
    const std::string field = "sweep[" + std::to_string(a) + "]";
    if (ax.field().empty()) return Status::InvalidArgument(field + ".field: must name a numeric spec field");
    std::vector<double> values(ax.values().begin(), ax.values().end());
    if (ax.has_grid()) {
      if (!values.empty()) return Status::InvalidArgument(field + ": give values or grid, not both");
      const auto& g = ax.grid();
      if (g.count() < 1) return Status::InvalidArgument(field + ".grid.count: must be >= 1");
      if (g.count() > max_runs) return Status::ResourceExhausted(field + ".grid.count: too many points");
      for (uint32_t k = 0; k < g.count(); ++k)
        values.push_back(g.count() == 1 ? g.start() : g.start() + (g.stop() - g.start()) * k / (g.count() - 1.0));
    }
    if (values.empty()) return Status::InvalidArgument(field + ": no values (give values or grid)");
    for (double v : values)
      if (!std::isfinite(v)) return Status::InvalidArgument(field + ".values: must be finite numbers");
    // The path must exist in the spec's type (catch typos before expanding).
    ExperimentSpec probe = spec;
    auto st = SetFieldByPath(&probe, ax.field(), values[0]);
    if (!st.ok()) return st.WithContext(field + ".field");
    // Every value within the swept field's bound (a grid is linear: its ends suffice).
    for (size_t k = 0; k < values.size(); ++k) {
      if (ax.has_grid() && k != 0 && k + 1 != values.size()) continue;
      st = SetFieldByPath(&probe, ax.field(), values[k]);
      if (st.ok()) st = CheckSpecBounds(probe);
      if (!st.ok())
        return st.WithContext(ax.has_grid() ? field + ".grid." + (k == 0 ? "start" : "stop")
                                            : field + ".values[" + std::to_string(k) + "]");
    }
    axes.emplace_back(ax.field(), std::move(values));
  }
  const uint32_t repeats = spec.repeats() == 0 ? 1 : spec.repeats();
  size_t total = repeats;
  for (const auto& ax : axes) {
    total *= ax.second.size();
    if (total > max_runs)
      return Status::ResourceExhausted("sweep: expands to more than " + std::to_string(max_runs) + " runs");
  }
  std::vector<RunPoint> out;
  out.reserve(total);
  std::vector<size_t> idx(axes.size(), 0);
  for (size_t n = 0; n < total / repeats; ++n) {
    ExperimentSpec point = spec;
    point.clear_sweep();
    point.set_repeats(1);
    RunKey key{spec.name(), {}, -1};
    for (size_t a = 0; a < axes.size(); ++a) {
      const double v = axes[a].second[idx[a]];
      VB_RETURN_IF_ERROR(SetFieldByPath(&point, axes[a].first, v));
      key.sweep.push_back({axes[a].first, v});
      point.add_tags("sweep:" + axes[a].first + "=" + FormatNumber(v));
    }
    for (uint32_t r = 0; r < repeats; ++r) {
      RunPoint run{point, key};
      if (repeats > 1) {
        run.key.repeat = static_cast<int>(r);
        run.spec.add_tags("repeat:" + std::to_string(r));
      }
      out.push_back(std::move(run));
    }
    for (size_t a = axes.size(); a-- > 0;) {  // odometer, last axis fastest
      if (++idx[a] < axes[a].second.size()) break;
      idx[a] = 0;
    }
  }
  return out;
}

// ---------------------------------------------------------------------------------------------------------

StatusOr<model::PlantParams> BuildPlant(const valvebench::v1::ModelSpec& ms,
                                        const valvebench::v1::Perturbation* perturbation) {
  auto plant = model::Preset(ms.preset().empty() ? model::kDefaultPreset : ms.preset());
  if (!plant.ok()) return plant.status().WithContext("bench.model.preset");
  // Overrides in a fixed (sorted) order so the result never depends on map iteration order.
  std::vector<std::pair<std::string, double>> overrides(ms.params().begin(), ms.params().end());
  std::sort(overrides.begin(), overrides.end());
  for (const auto& [name, value] : overrides) {
    auto st = model::SetParam(&plant.value(), name, value);
    if (!st.ok()) return st.WithContext("bench.model.params[" + name + "]");
  }
  plant->inductance_stroke_m.assign(ms.inductance_table().stroke_m().begin(), ms.inductance_table().stroke_m().end());
  plant->inductance_L_H.assign(ms.inductance_table().l_h().begin(), ms.inductance_table().l_h().end());
  // Effects: named additions (model/effects.h), and param:NAME, a nominal parameter that is simply off
  // ({"value": v} or {"factor": f}).
  for (int k = 0; k < ms.effects_size(); ++k) {
    const auto& fx = ms.effects(k);
    const std::string field = "bench.model.effects[" + std::to_string(k) + "]";
    std::vector<std::pair<std::string, double>> params(fx.params().begin(), fx.params().end());
    std::sort(params.begin(), params.end());
    if (fx.name() == "none") continue;
    if (fx.name().rfind("param:", 0) == 0) {
      const std::string name = fx.name().substr(6);
      auto current = model::GetParam(*plant, name);
      if (!current.ok()) return current.status().WithContext(field + ".name");
      if (params.size() != 1 || (params[0].first != "value" && params[0].first != "factor"))
        return Status::InvalidArgument(field + ".params: param:" + name + " takes exactly one of value, factor");
      const double v = params[0].first == "value" ? params[0].second : *current * params[0].second;
      auto st = model::SetParam(&plant.value(), name, v);
      if (!st.ok()) return st.WithContext(field);
      continue;
    }
    auto st = model::AddEffect(&plant->effects, fx.name(), params);
    if (!st.ok()) return st.InField(field);
  }
  if (perturbation != nullptr) {
    std::vector<std::pair<std::string, double>> scales(perturbation->param_scale().begin(),
                                                       perturbation->param_scale().end());
    std::sort(scales.begin(), scales.end());
    for (const auto& [name, scale] : scales) {
      const std::string field = "perturbation.param_scale[" + name + "]";
      if (!(scale > 0.0) || !std::isfinite(scale)) return Status::InvalidArgument(field + ": must be > 0");
      auto v = model::GetParam(*plant, name);
      if (!v.ok()) return v.status().WithContext(field);
      auto st = model::SetParam(&plant.value(), name, *v * scale);
      if (!st.ok()) return st.WithContext(field);
    }
  }
  auto st = model::Validate(*plant);
  if (!st.ok()) return st.WithContext("bench.model");
  return plant;
}

StatusOr<model::DriverParams> BuildDriver(const valvebench::v1::DriverSpec& ds) {
  model::DriverParams d;
  auto kind = model::ParseDriverKind(ds.kind());
  if (!kind.ok()) return kind.status().WithContext("bench.driver.kind");
  d.kind = *kind;
  std::vector<std::pair<std::string, double>> params(ds.params().begin(), ds.params().end());
  std::sort(params.begin(), params.end());
  for (const auto& [name, value] : params) {
    auto st = model::SetDriverParam(&d, name, value);
    if (!st.ok()) return st.WithContext("bench.driver.params[" + name + "]");
  }
  auto st = model::Validate(d);
  if (!st.ok()) return st.WithContext("bench.driver");
  return d;
}

StatusOr<Experiment> BuildExperiment(const ExperimentSpec& spec) {
  Experiment e;
  e.spec = spec;
  if (spec.sweep_size() > 0 || spec.repeats() > 1 || spec.variants_size() > 0)
    return Status::InvalidArgument("sweep: expand variants, sweeps and repeats before building a single run");
  VB_RETURN_IF_ERROR(CheckSpecBounds(spec));
  if (!(spec.duration_s() > 0.0) || !std::isfinite(spec.duration_s()))
    return Status::InvalidArgument("duration_s: must be > 0, got " + FormatNumber(spec.duration_s()));
  e.duration_s = spec.duration_s();
  auto bench_kind = ParseBenchKind(spec.bench().kind(), "bench.kind");
  if (!bench_kind.ok()) return bench_kind.status();

  auto plant = BuildPlant(spec.bench().model(), spec.has_perturbation() ? &spec.perturbation() : nullptr);
  if (!plant.ok()) return plant.status();
  e.plant = *plant;
  auto driver = BuildDriver(spec.bench().driver());
  if (!driver.ok()) return driver.status();
  e.driver = *driver;

  const auto& pert = spec.perturbation();
  for (const auto& [field, value] : {std::pair<const char*, double>{"disturbance_V", pert.disturbance_v()},
                                     {"disturbance_force_N", pert.disturbance_force_n()},
                                     {"disturbance_Hz", pert.disturbance_hz()}})
    if (!std::isfinite(value)) return Status::InvalidArgument(std::string("perturbation.") + field + ": not finite");
  if (pert.disturbance_hz() < 0.0) return Status::InvalidArgument("perturbation.disturbance_Hz: must be >= 0");
  e.disturbance = model::Disturbance{pert.disturbance_v(), pert.disturbance_force_n(), pert.disturbance_hz()};
  if (e.disturbance.active() && *bench_kind != BenchKind::kEmulated)
    return Status::InvalidArgument("perturbation: disturbances can only be injected on an emulated bench");
  const auto& c = spec.conditions();
  e.run.supply_V = c.has_supply_v() ? c.supply_v() : kDefaultSupply_V;
  if (!(e.run.supply_V > 0.0) || !std::isfinite(e.run.supply_V))
    return Status::InvalidArgument("conditions.supply_V: must be > 0, got " + FormatNumber(c.supply_v()));
  if (!(c.supply_pressure_pa() >= 0.0) || !std::isfinite(c.supply_pressure_pa()))
    return Status::InvalidArgument("conditions.supply_pressure_Pa: must be >= 0 (gauge), got " +
                                   FormatNumber(c.supply_pressure_pa()));
  e.run.supply_pressure_Pa = c.supply_pressure_pa();
  const double rate = spec.recording().rate_hz() == 0.0 ? kDefaultRecordRate_Hz : spec.recording().rate_hz();
  if (!(rate > 0.0) || !std::isfinite(rate))
    return Status::InvalidArgument("recording.rate_Hz: must be > 0, got " + FormatNumber(rate));
  if (e.duration_s * rate > 50e6)
    return Status::ResourceExhausted("duration_s: " + FormatNumber(e.duration_s) + " s at recording.rate_Hz = " +
                                     FormatNumber(rate) + " Hz is " + FormatNumber(e.duration_s * rate) +
                                     " samples, more than 50 million; shorten the run or lower recording.rate_Hz");
  e.run.sample_rate_Hz = rate;
  e.run.realtime = spec.realtime();
  for (int k = 0; k < spec.recording().channels_size(); ++k) {
    const auto& names = Trace::ChannelNames();
    if (std::find(names.begin(), names.end(), spec.recording().channels(k)) == names.end())
      return Status::InvalidArgument("recording.channels[" + std::to_string(k) + "]: unknown channel '" +
                                     spec.recording().channels(k) + "'");
  }

  auto ref = ReferenceProfile::FromSpec(spec.reference(), spec.valve_command());
  if (!ref.ok()) return ref.status();
  e.reference = std::move(ref.value());

  auto ctl = BuildController(spec, e.plant, e.driver, e.run.supply_V);
  if (!ctl.ok()) return ctl.status();
  e.controller = std::move(ctl->controller);
  e.controlled = ctl->controlled;
  if (e.controlled != ControlledVariable::kNone && !e.reference.has_reference())
    return Status::InvalidArgument("reference: the " + std::string(e.controller->name()) +
                                   " controller needs a reference");
  e.average_window_s = ctl->pwm_period_s > 0.0 ? ctl->pwm_period_s : e.reference.command_period_s();
  if (e.average_window_s <= 0.0) e.average_window_s = 1.0 / rate;

  e.metric_start_s = spec.metric_window().start_s();
  e.metric_end_s = spec.metric_window().end_s() == 0.0 ? e.duration_s : spec.metric_window().end_s();
  if (e.metric_start_s < 0.0 || !(e.metric_end_s > e.metric_start_s) || e.metric_end_s > e.duration_s + 1e-12)
    return Status::InvalidArgument("metric_window: need 0 <= start_s < end_s <= duration_s");

  e.breakpoints_s = e.reference.Breakpoints(e.duration_s);
  for (double t : ctl->breakpoints_s)
    if (t >= 0.0 && t < e.duration_s) e.breakpoints_s.push_back(t);
  std::sort(e.breakpoints_s.begin(), e.breakpoints_s.end());
  e.breakpoints_s.erase(std::unique(e.breakpoints_s.begin(), e.breakpoints_s.end()), e.breakpoints_s.end());
  return e;
}

bool IsNumericField(const google::protobuf::FieldDescriptor* f) {
  switch (f->cpp_type()) {
    case google::protobuf::FieldDescriptor::CPPTYPE_DOUBLE:
    case google::protobuf::FieldDescriptor::CPPTYPE_FLOAT:
    case google::protobuf::FieldDescriptor::CPPTYPE_INT32:
    case google::protobuf::FieldDescriptor::CPPTYPE_UINT32:
    case google::protobuf::FieldDescriptor::CPPTYPE_INT64:
    case google::protobuf::FieldDescriptor::CPPTYPE_UINT64: return true;
    default: return false;
  }
}

}  // namespace vb::experiment
