// The HDF5 and MAT writers, read back with the libraries' own readers (libhdf5, libmatio): every channel's
// values and unit, the spec, the conditions and the metrics come back as written. Python's h5py and
// scipy.io read benchctl's files in python/tests/test_export.py.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <matio.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "export/run_file.h"

namespace vb::exportfile {
namespace {

std::string TempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("vb_export_test_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

RunFile Sample(size_t n) {
  RunFile r;
  r.run_id = 42;
  r.name = "compare/pi";
  r.controller = "pi_current";
  r.bench = "emu-1";
  r.status = "done";
  r.t0_s = 0.0;
  r.sample_period_s = 2e-5;
  r.spec_json = R"({"name":"compare/pi","conditions":{"supply_V":24}})";
  std::vector<double> t(n), i(n), ref(n);
  for (size_t k = 0; k < n; ++k) {
    t[k] = static_cast<double>(k) * 2e-5;
    i[k] = 0.5 * (1 - std::exp(-t[k] / 0.009));
    ref[k] = 0.5;
  }
  r.channels = {{"t_s", ChannelUnit("t_s", r.controller), t},
                {"i_A", ChannelUnit("i_A", r.controller), i},
                {"ref", ChannelUnit("ref", r.controller), ref}};
  r.conditions = {{"supply_V", 24.0, "V"}, {"supply_pressure_Pa", 4e5, "Pa"}};
  r.metrics = {{"rmse", 0.0123, MetricUnit("rmse", r.controller)}, {"energy_J", 0.25, "J"}};
  return r;
}

TEST(ExportUnits, ChannelsAndMetricsCarryTheirSiUnit) {
  EXPECT_EQ(ChannelUnit("t_s", ""), "s");
  EXPECT_EQ(ChannelUnit("i_A", ""), "A");
  EXPECT_EQ(ChannelUnit("v_mps", ""), "m/s");
  EXPECT_EQ(ChannelUnit("flow_kg_per_s", ""), "kg/s");
  EXPECT_EQ(ChannelUnit("gate", ""), "1");
  EXPECT_EQ(ChannelUnit("ref", "pi_current"), "A");
  EXPECT_EQ(ChannelUnit("ref", "sliding_mode_position"), "m");
  EXPECT_EQ(ChannelUnit("ref", "open_loop_pwm"), "");
  EXPECT_EQ(MetricUnit("rmse", "cascade_pi_position"), "m");
  EXPECT_EQ(MetricUnit("iae", "fuzzy_current"), "A s");
  EXPECT_EQ(MetricUnit("mean_position_pct", ""), "%");
  EXPECT_EQ(MetricUnit("opening_delay_s", ""), "s");
  EXPECT_EQ(MetricUnit("effort_l2", ""), "V s^0.5");
}

TEST(ExportValidate, NamesTheField) {
  RunFile r = Sample(10);
  r.channels[1].values.pop_back();
  auto st = Validate(r);
  EXPECT_EQ(st.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(st.message().find("channels[1].values: 9 samples, but t_s has 10"), std::string::npos) << st.message();
  r = Sample(10);
  r.metrics[0].name = "1bad";
  st = Validate(r);
  EXPECT_NE(st.message().find("metrics[0].name: '1bad' is not an identifier"), std::string::npos) << st.message();
  r = Sample(10);
  r.channels[2].name = "i_A";
  EXPECT_NE(Validate(r).message().find("channels[2].name: 'i_A' appears twice"), std::string::npos);
}

std::string ReadStringAttr(hid_t obj, const char* name) {
  hid_t a = H5Aopen(obj, name, H5P_DEFAULT);
  hid_t t = H5Aget_type(a);
  char* p = nullptr;
  H5Aread(a, t, &p);
  std::string s = p ? p : "";
  H5free_memory(p);
  H5Tclose(t);
  H5Aclose(a);
  return s;
}

std::vector<double> ReadDataset(hid_t file, const std::string& path, std::string* unit) {
  hid_t d = H5Dopen2(file, path.c_str(), H5P_DEFAULT);
  EXPECT_GE(d, 0) << path;
  hid_t space = H5Dget_space(d);
  const hssize_t n = H5Sget_simple_extent_npoints(space);
  std::vector<double> v(static_cast<size_t>(n));
  if (n > 0) H5Dread(d, H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT, v.data());
  *unit = ReadStringAttr(d, "units");
  H5Sclose(space);
  H5Dclose(d);
  return v;
}

// 100001 samples: above the chunk size, so the compressed path is read back too.
TEST(ExportHdf5, ReadsBackChannelsUnitsSpecConditionsMetrics) {
  const RunFile r = Sample(100001);
  const std::string path = TempPath("run.h5");
  ASSERT_TRUE(WriteHdf5(r, path).ok());
  hid_t f = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(f, 0);
  EXPECT_EQ(ReadStringAttr(f, "format"), "valvebench-run/1");
  EXPECT_EQ(ReadStringAttr(f, "spec_json"), r.spec_json);
  EXPECT_EQ(ReadStringAttr(f, "controller"), "pi_current");
  for (const auto& c : r.channels) {
    std::string unit;
    EXPECT_EQ(ReadDataset(f, "/channels/" + c.name, &unit), c.values) << c.name;
    EXPECT_EQ(unit, c.unit) << c.name;
  }
  std::string unit;
  EXPECT_EQ(ReadDataset(f, "/conditions/supply_V", &unit), std::vector<double>{24.0});
  EXPECT_EQ(unit, "V");
  EXPECT_EQ(ReadDataset(f, "/metrics/rmse", &unit), std::vector<double>{0.0123});
  EXPECT_EQ(unit, "A");
  H5Fclose(f);
  const auto bytes = std::filesystem::file_size(path);
  EXPECT_LT(bytes, 3 * 100001 * 8) << "compressed";
  std::printf("HDF5: 3 channels x 100001 samples in %ju bytes (raw %d)\n", static_cast<std::uintmax_t>(bytes),
              3 * 100001 * 8);
  std::filesystem::remove(path);
}

TEST(ExportHdf5, UnwritablePathIsUnavailableNamingThePath) {
  auto st = WriteHdf5(Sample(3), "/nonexistent-dir/x.h5");
  EXPECT_EQ(st.code(), StatusCode::kUnavailable);
  EXPECT_NE(st.message().find("/nonexistent-dir/x.h5"), std::string::npos);
}

std::string MatText(matvar_t* v) {
  return v && v->class_type == MAT_C_CHAR ? std::string(static_cast<const char*>(v->data), v->nbytes) : "<not text>";
}

TEST(ExportMat, ReadsBackTheStruct) {
  const RunFile r = Sample(1000);
  const std::string path = TempPath("run.mat");
  ASSERT_TRUE(WriteMat(r, path).ok());
  mat_t* m = Mat_Open(path.c_str(), MAT_ACC_RDONLY);
  ASSERT_NE(m, nullptr);
  matvar_t* top = Mat_VarRead(m, "vbrun");
  ASSERT_NE(top, nullptr);
  EXPECT_EQ(top->class_type, MAT_C_STRUCT);
  EXPECT_EQ(MatText(Mat_VarGetStructFieldByName(top, "spec_json", 0)), r.spec_json);
  EXPECT_EQ(MatText(Mat_VarGetStructFieldByName(top, "name", 0)), "compare/pi");
  matvar_t* channels = Mat_VarGetStructFieldByName(top, "channels", 0);
  matvar_t* units = Mat_VarGetStructFieldByName(top, "units", 0);
  ASSERT_NE(channels, nullptr);
  for (const auto& c : r.channels) {
    matvar_t* v = Mat_VarGetStructFieldByName(channels, c.name.c_str(), 0);
    ASSERT_NE(v, nullptr) << c.name;
    ASSERT_EQ(v->dims[0], c.values.size());
    const double* d = static_cast<const double*>(v->data);
    EXPECT_EQ(std::vector<double>(d, d + v->dims[0]), c.values) << c.name;
    EXPECT_EQ(MatText(Mat_VarGetStructFieldByName(units, c.name.c_str(), 0)), c.unit) << c.name;
  }
  matvar_t* cond = Mat_VarGetStructFieldByName(top, "conditions", 0);
  EXPECT_EQ(*static_cast<const double*>(Mat_VarGetStructFieldByName(cond, "supply_pressure_Pa", 0)->data), 4e5);
  matvar_t* metrics = Mat_VarGetStructFieldByName(top, "metrics", 0);
  EXPECT_EQ(*static_cast<const double*>(Mat_VarGetStructFieldByName(metrics, "rmse", 0)->data), 0.0123);
  EXPECT_EQ(MatText(Mat_VarGetStructFieldByName(Mat_VarGetStructFieldByName(top, "metric_units", 0), "rmse", 0)), "A");
  Mat_VarFree(top);
  Mat_Close(m);
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace vb::exportfile
