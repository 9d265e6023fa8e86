// MATLAB level-5 writer (libmatio): the layout is in run_file.h.
#include <matio.h>

#include <memory>

#include "export/run_file.h"

namespace vb::exportfile {
namespace {

struct VarFree {
  void operator()(matvar_t* v) const { Mat_VarFree(v); }
};
using Var = std::unique_ptr<matvar_t, VarFree>;

Var Number(double v) {
  size_t dims[2] = {1, 1};
  return Var(Mat_VarCreate(nullptr, MAT_C_DOUBLE, MAT_T_DOUBLE, 2, dims, &v, 0));  // matio copies the data
}

Var Text(const std::string& s) {
  size_t dims[2] = {1, s.size()};
  return Var(Mat_VarCreate(nullptr, MAT_C_CHAR, MAT_T_UTF8, 2, dims, const_cast<char*>(s.data()), 0));
}

Var Column(const std::vector<double>& values) {
  size_t dims[2] = {values.size(), 1};
  return Var(Mat_VarCreate(nullptr, MAT_C_DOUBLE, MAT_T_DOUBLE, 2, dims, const_cast<double*>(values.data()), 0));
}

// A 1x1 struct with the given field names (no fields yet set).
Var Struct(const char* name, const std::vector<std::string>& fields) {
  std::vector<const char*> names;
  for (const auto& f : fields) names.push_back(f.c_str());
  size_t dims[2] = {1, 1};
  return Var(
      Mat_VarCreateStruct(name, 2, dims, names.empty() ? nullptr : names.data(), static_cast<unsigned>(names.size())));
}

// Sets a field; the struct takes ownership of the value.
bool Set(matvar_t* s, const std::string& field, Var value) {
  if (!value) return false;
  if (Mat_VarSetStructFieldByName(s, field.c_str(), 0, value.get()) != nullptr) return false;
  value.release();
  return true;
}

Var ValuesStruct(const std::vector<Value>& values, bool units) {
  std::vector<std::string> names;
  for (const auto& v : values) names.push_back(v.name);
  Var s = Struct(nullptr, names);
  if (!s) return s;
  for (const auto& v : values)
    if (!Set(s.get(), v.name, units ? Text(v.unit) : Number(v.value))) return nullptr;
  return s;
}

}  // namespace

Status WriteMat(const RunFile& run, const std::string& path) {
  if (auto st = Validate(run); !st.ok()) return st;
  std::unique_ptr<mat_t, int (*)(mat_t*)> mat(Mat_CreateVer(path.c_str(), nullptr, MAT_FT_MAT5), &Mat_Close);
  if (!mat) return Status::Unavailable(path + ": cannot create the MAT file");

  std::vector<std::string> channel_names;
  for (const auto& c : run.channels) channel_names.push_back(c.name);
  Var channels = Struct(nullptr, channel_names);
  Var channel_units = Struct(nullptr, channel_names);
  bool ok = channels && channel_units;
  for (const auto& c : run.channels) {
    ok = ok && Set(channels.get(), c.name, Column(c.values)) && Set(channel_units.get(), c.name, Text(c.unit));
  }
  const std::vector<std::string> fields = {"run_id", "name",       "controller", "bench",           "status",
                                           "reason", "spec_json",  "t0_s",       "sample_period_s", "channels",
                                           "units",  "conditions", "metrics",    "metric_units"};
  Var top = Struct("vbrun", fields);
  ok = ok && top && Set(top.get(), "run_id", Number(static_cast<double>(run.run_id))) &&
       Set(top.get(), "name", Text(run.name)) && Set(top.get(), "controller", Text(run.controller)) &&
       Set(top.get(), "bench", Text(run.bench)) && Set(top.get(), "status", Text(run.status)) &&
       Set(top.get(), "reason", Text(run.reason)) && Set(top.get(), "spec_json", Text(run.spec_json)) &&
       Set(top.get(), "t0_s", Number(run.t0_s)) && Set(top.get(), "sample_period_s", Number(run.sample_period_s)) &&
       Set(top.get(), "channels", std::move(channels)) && Set(top.get(), "units", std::move(channel_units)) &&
       Set(top.get(), "conditions", ValuesStruct(run.conditions, false)) &&
       Set(top.get(), "metrics", ValuesStruct(run.metrics, false)) &&
       Set(top.get(), "metric_units", ValuesStruct(run.metrics, true));
  if (!ok) return Status::Internal(path + ": cannot build the MAT variable");
  if (Mat_VarWrite(mat.get(), top.get(), MAT_COMPRESSION_ZLIB) != 0)
    return Status::Unavailable(path + ": MAT write failed");
  return Status::Ok();
}

}  // namespace vb::exportfile
