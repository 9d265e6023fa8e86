// The valve-runs/1 importer: a valid dataset with every field, CRLF and BOM files, optional and unknown
// columns, every manifest and CSV error with its exact message (file, line, column), load speed, and the
// practice datasets in ../shared/gapbench/practice (skipped when that folder is missing).
#include "gap/dataset.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

namespace vb::gap {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// gtest only (the test targets do not link gmock).
::testing::AssertionResult Contains(const std::string& text, const std::string& part) {
  if (text.find(part) != std::string::npos) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "'" << text << "' does not contain '" << part << "'";
}

constexpr const char* kCsvA = "t_s,gate,i_A\n0,0,0\n2e-05,1,0.001\n4e-05,1,0.002\n";
constexpr const char* kCsvB = "t_s,gate,i_A\n0,1,0.5\n0.25,0,0.25\n0.5,0,0\n";

// Each test gets its own dataset directory <tmp>/vb_gap_<test>_<pid>/ds, so messages start with "ds/".
class DatasetTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = std::string(info->test_suite_name()) + "_" + info->name();
    for (char& c : name) {
      if (c == '/') c = '_';
    }
    root_ = fs::path(::testing::TempDir()) / ("vb_gap_" + name + "_" + std::to_string(::getpid()));
    fs::remove_all(root_);
    dir_ = root_ / "ds";
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(root_); }

  void Write(const std::string& rel, const std::string& content) {
    const fs::path p = dir_ / rel;
    fs::create_directories(p.parent_path());
    std::ofstream f(p, std::ios::binary);
    f << content;
    ASSERT_TRUE(f.good()) << p;
  }

  // Two runs: a (fit, 3 samples of 20 us) and b (holdout, 3 samples of 0.25 s, exact in binary).
  static json ValidManifest() {
    return json{{"format", "valve-runs/1"},
                {"model", "taghizadeh2009"},
                {"description", "two runs"},
                {"runs",
                 {{{"id", "a"}, {"file", "a.csv"}, {"supply_V", 24.0}, {"supply_pressure_Pa", 300000.0},
                   {"t_start_s", 1.0}, {"split", "fit"}},
                  {{"id", "b"}, {"file", "b.csv"}, {"supply_V", 15}, {"supply_pressure_Pa", 0},
                   {"t_start_s", 2.5}, {"split", "holdout"}}}}};
  }
  void WriteValid() {
    Write("manifest.json", ValidManifest().dump(1));
    Write("a.csv", kCsvA);
    Write("b.csv", kCsvB);
  }

  StatusOr<Dataset> Load() { return LoadDataset(dir_.string()); }

  // Loads and expects InvalidArgument with exactly `message`.
  void ExpectError(const std::string& message) {
    auto ds = Load();
    ASSERT_FALSE(ds.ok()) << "expected: " << message;
    EXPECT_EQ(ds.status().code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(ds.status().message(), message);
  }
  // The valid dataset with manifest edited by `edit`; expects `message`.
  template <typename Edit>
  void ExpectManifestError(Edit edit, const std::string& message) {
    WriteValid();
    json m = ValidManifest();
    edit(m);
    Write("manifest.json", m.dump());
    ExpectError(message);
  }
  // The valid dataset with b.csv replaced by `csv`; expects `message`.
  void ExpectCsvError(const std::string& csv, const std::string& message) {
    WriteValid();
    Write("b.csv", csv);
    ExpectError(message);
  }
  // The valid dataset with b.csv replaced by `csv`; expects it to load and returns run b.
  RunData LoadB(const std::string& csv) {
    WriteValid();
    Write("b.csv", csv);
    auto ds = Load();
    EXPECT_TRUE(ds.ok()) << ds.status().ToString();
    if (!ds.ok()) return {};
    return ds->runs[1];
  }

  fs::path root_, dir_;
};

// ---- valid datasets --------------------------------------------------------------------------------------

TEST_F(DatasetTest, LoadsEveryField) {
  WriteValid();
  auto ds = Load();
  ASSERT_TRUE(ds.ok()) << ds.status().ToString();
  EXPECT_EQ(ds->format, "valve-runs/1");
  EXPECT_EQ(ds->model, "taghizadeh2009");
  EXPECT_EQ(ds->description, "two runs");
  EXPECT_EQ(ds->directory, dir_.string());
  EXPECT_TRUE(ds->warnings.empty());
  ASSERT_EQ(ds->runs.size(), 2u);

  const RunData& a = ds->runs[0];
  EXPECT_EQ(a.id, "a");
  EXPECT_EQ(a.file, "a.csv");
  EXPECT_EQ(a.supply_V, 24.0);
  EXPECT_EQ(a.supply_pressure_Pa, 300000.0);
  EXPECT_EQ(a.t_start_s, 1.0);
  EXPECT_EQ(a.split, Split::kFit);
  EXPECT_NEAR(a.sample_period_s, 2e-5, 1e-15);
  EXPECT_EQ(a.t_s, (std::vector<double>{0, 2e-5, 4e-5}));
  EXPECT_EQ(a.gate, (std::vector<int8_t>{0, 1, 1}));
  EXPECT_EQ(a.i_A, (std::vector<double>{0, 0.001, 0.002}));
  EXPECT_TRUE(a.x_m.empty());
  EXPECT_TRUE(a.v_coil_V.empty());

  const RunData& b = ds->runs[1];
  EXPECT_EQ(b.id, "b");
  EXPECT_EQ(b.supply_V, 15.0);  // JSON integers are numbers too
  EXPECT_EQ(b.supply_pressure_Pa, 0.0);
  EXPECT_EQ(b.split, Split::kHoldout);
  EXPECT_EQ(b.sample_period_s, 0.25);
  EXPECT_EQ(b.gate, (std::vector<int8_t>{1, 0, 0}));
}

// The same dataset from files in memory (the web's upload): the same runs, and the same messages with the
// given name, for a missing manifest, a file the manifest names that is not there, an escape and a bad CSV.
TEST_F(DatasetTest, FilesInMemoryLoadAsTheDirectoryDoes) {
  WriteValid();
  auto disk = Load();
  ASSERT_TRUE(disk.ok()) << disk.status().ToString();
  std::map<std::string, std::string> files = {
      {"manifest.json", ValidManifest().dump(1)}, {"a.csv", kCsvA}, {"b.csv", kCsvB}};
  auto mem = LoadDatasetFromFiles("ds", files);
  ASSERT_TRUE(mem.ok()) << mem.status().ToString();
  EXPECT_TRUE(mem->directory.empty());
  ASSERT_EQ(mem->runs.size(), disk->runs.size());
  for (std::size_t k = 0; k < mem->runs.size(); ++k) {
    EXPECT_EQ(mem->runs[k].id, disk->runs[k].id);
    EXPECT_EQ(mem->runs[k].t_s, disk->runs[k].t_s);
    EXPECT_EQ(mem->runs[k].i_A, disk->runs[k].i_A);
    EXPECT_EQ(mem->runs[k].gate, disk->runs[k].gate);
    EXPECT_EQ(mem->runs[k].supply_V, disk->runs[k].supply_V);
  }
  auto without = files;
  without.erase("manifest.json");
  EXPECT_EQ(LoadDatasetFromFiles("ds", without).status().message(), "ds/manifest.json: does not exist");
  without = files;
  without.erase("b.csv");
  EXPECT_EQ(LoadDatasetFromFiles("ds", without).status().message(),
            "ds/manifest.json: runs[1].file: 'b.csv' does not exist");
  json m = ValidManifest();
  m["runs"][1]["file"] = "../ds/b.csv";
  auto escape = files;
  escape["manifest.json"] = m.dump();
  EXPECT_EQ(LoadDatasetFromFiles("ds", escape).status().message(),
            "ds/manifest.json: runs[1].file: '../ds/b.csv' is outside the dataset directory");
  auto bad_csv = files;
  bad_csv["b.csv"] = "t_s,gate,i_A\n0,1,0.5\n0.25,0,x\n";
  Write("b.csv", bad_csv["b.csv"]);
  auto disk_bad = Load();
  ASSERT_FALSE(disk_bad.ok());
  EXPECT_EQ(LoadDatasetFromFiles("ds", bad_csv).status().message(), disk_bad.status().message());
}

// valve-runs/1 bounds its conditions like valve-runs/2: no absurd supply, pressure or start time.
TEST_F(DatasetTest, ConditionsBeyondAnyBenchAreRefusedNamingTheField) {
  ExpectManifestError([](json& m) { m["runs"][1]["supply_V"] = 1e308; },
                      "ds/manifest.json: runs[1].supply_V: 1e+308 V is outside (0, 10000] V");
  ExpectManifestError([](json& m) { m["runs"][1]["supply_pressure_Pa"] = 1e300; },
                      "ds/manifest.json: runs[1].supply_pressure_Pa: 1e+300 Pa is outside [0, 1e+08] Pa");
  ExpectManifestError([](json& m) { m["runs"][1]["t_start_s"] = 1e12; },
                      "ds/manifest.json: runs[1].t_start_s: 1e+12 s is outside [0, 1e+09] s");
}

// A run file over the size limit is refused from its size, before it is read: a 600 MiB sparse file takes no
// disk and would take seconds and 600 MiB of memory to read.
TEST_F(DatasetTest, AFileOverTheSizeLimitIsRefusedBeforeItIsRead) {
  WriteValid();
  fs::resize_file(dir_ / "b.csv", std::uintmax_t{600} << 20);
  ExpectError("ds/b.csv: 600 MiB exceeds the 512 MiB a dataset file may have; split the run into several runs "
              "(files)");
}

TEST_F(DatasetTest, OptionalFieldsAndEqualStartTimes) {
  WriteValid();
  json m = ValidManifest();
  m.erase("description");
  m["runs"][0].erase("split");
  m["runs"][1]["t_start_s"] = 1.0;  // non-decreasing is enough
  Write("manifest.json", m.dump());
  auto ds = Load();
  ASSERT_TRUE(ds.ok()) << ds.status().ToString();
  EXPECT_EQ(ds->description, "");
  EXPECT_EQ(ds->runs[0].split, Split::kNone);
  EXPECT_EQ(ds->runs[1].split, Split::kHoldout);
}

TEST_F(DatasetTest, CrlfLineEndings) {
  RunData b = LoadB("t_s,gate,i_A\r\n0,1,0.5\r\n0.25,0,0.25\r\n0.5,0,0\r\n");
  EXPECT_EQ(b.t_s, (std::vector<double>{0, 0.25, 0.5}));
  EXPECT_EQ(b.i_A, (std::vector<double>{0.5, 0.25, 0}));
  EXPECT_EQ(b.gate, (std::vector<int8_t>{1, 0, 0}));
  // Without the final line break, CRLF or LF.
  EXPECT_EQ(LoadB("t_s,gate,i_A\r\n0,1,0.5\r\n0.25,0,0.25\r\n0.5,0,0").i_A, (std::vector<double>{0.5, 0.25, 0}));
  EXPECT_EQ(LoadB("t_s,gate,i_A\n0,1,0.5\n0.25,0,0.25\n0.5,0,0").i_A, (std::vector<double>{0.5, 0.25, 0}));
  // CRLF manifest too.
  WriteValid();
  std::string manifest = ValidManifest().dump(1);
  std::string crlf;
  for (char c : manifest) crlf += c == '\n' ? std::string("\r\n") : std::string(1, c);
  Write("manifest.json", crlf);
  EXPECT_TRUE(Load().ok());
}

TEST_F(DatasetTest, Utf8ByteOrderMarkIsSkipped) {
  EXPECT_EQ(LoadB("\xEF\xBB\xBFt_s,gate,i_A\n0,1,0.5\n0.25,0,0.25\n").t_s, (std::vector<double>{0, 0.25}));
}

TEST_F(DatasetTest, OptionalColumnsInAnyOrder) {
  RunData b = LoadB("i_A,x_m,gate,v_coil_V,t_s\n0.5,0,1,24,0\n0.25,1e-4,0,-0.7,0.25\n0,2.5e-4,0,0,0.5\n");
  EXPECT_EQ(b.t_s, (std::vector<double>{0, 0.25, 0.5}));
  EXPECT_EQ(b.gate, (std::vector<int8_t>{1, 0, 0}));
  EXPECT_EQ(b.i_A, (std::vector<double>{0.5, 0.25, 0}));
  EXPECT_EQ(b.x_m, (std::vector<double>{0, 1e-4, 2.5e-4}));
  EXPECT_EQ(b.v_coil_V, (std::vector<double>{24, -0.7, 0}));
  // Only one of them.
  RunData x = LoadB("t_s,gate,i_A,x_m\n0,1,0.5,0\n0.25,0,0.25,1e-4\n");
  EXPECT_EQ(x.x_m, (std::vector<double>{0, 1e-4}));
  EXPECT_TRUE(x.v_coil_V.empty());
}

TEST_F(DatasetTest, GateAcceptsZeroAndOneInAnyNumberSpelling) {
  EXPECT_EQ(LoadB("t_s,gate,i_A\n0,0.0,0\n0.25,1.0,0\n0.5,1,0\n0.75,0,0\n1,1e0,0\n1.25,-0,0\n").gate,
            (std::vector<int8_t>{0, 1, 1, 0, 1, 0}));
}

TEST_F(DatasetTest, TimeTolerances) {
  // First sample within 1e-9 s of 0; steps within 1e-6 relative of the first.
  EXPECT_EQ(LoadB("t_s,gate,i_A\n1e-10,0,0\n0.25,0,0\n0.5000001,0,0\n0.75,0,0\n").t_s.size(), 4u);
  EXPECT_EQ(LoadB("t_s,gate,i_A\n-1e-10,0,0\n0.25,0,0\n").t_s.size(), 2u);
  // Number spellings from_chars reads.
  EXPECT_EQ(LoadB("t_s,gate,i_A\n0,0,.5\n0.25,0,1.\n0.5,0,1E-3\n").i_A, (std::vector<double>{0.5, 1.0, 1e-3}));
}

TEST_F(DatasetTest, UnknownColumnsAreIgnoredWithAWarning) {
  WriteValid();
  Write("b.csv", "t_s,temp_C,gate,i_A,note\n0,20,1,0.5,abc\n0.25,21,0,0.25,\n");
  auto ds = Load();
  ASSERT_TRUE(ds.ok()) << ds.status().ToString();
  EXPECT_EQ(ds->runs[1].i_A, (std::vector<double>{0.5, 0.25}));
  EXPECT_EQ(ds->runs[1].gate, (std::vector<int8_t>{1, 0}));
  EXPECT_EQ(ds->warnings,
            (std::vector<std::string>{
                "ds/b.csv: column 'temp_C' is not a valve-runs/1 column (t_s, gate, i_A, x_m, v_coil_V); ignored",
                "ds/b.csv: column 'note' is not a valve-runs/1 column (t_s, gate, i_A, x_m, v_coil_V); ignored"}));
}

TEST_F(DatasetTest, UnknownManifestKeysAreIgnoredWithAWarning) {
  WriteValid();
  json m = ValidManifest();
  m["operator"] = "kim";
  m["runs"][1]["splt"] = "fit";
  Write("manifest.json", m.dump());
  auto ds = Load();
  ASSERT_TRUE(ds.ok()) << ds.status().ToString();
  EXPECT_EQ(ds->warnings, (std::vector<std::string>{"ds/manifest.json: unknown key 'operator' ignored",
                                                    "ds/manifest.json: runs[1]: unknown key 'splt' ignored"}));
}

TEST_F(DatasetTest, FilesInSubdirectories) {
  WriteValid();
  Write("runs/b.csv", kCsvB);
  json m = ValidManifest();
  m["runs"][1]["file"] = "runs/../runs/b.csv";  // ".." that stays inside is fine
  Write("manifest.json", m.dump());
  auto ds = Load();
  ASSERT_TRUE(ds.ok()) << ds.status().ToString();
  EXPECT_EQ(ds->runs[1].file, "runs/../runs/b.csv");
}

TEST_F(DatasetTest, DatasetNameIgnoresATrailingSlash) {
  WriteValid();
  Write("b.csv", "t_s,gate,i_A\n0,0,x\n");
  auto ds = LoadDataset(dir_.string() + "/");
  ASSERT_FALSE(ds.ok());
  EXPECT_EQ(ds.status().message(), "ds/b.csv:2: column i_A: 'x' is not a number");
}

TEST_F(DatasetTest, KnownModelsComeFromTheCaller) {
  WriteValid();
  json m = ValidManifest();
  m["model"] = "lunge2013";
  Write("manifest.json", m.dump());
  auto ok = LoadDataset(dir_.string(), {"taghizadeh2009", "lunge2013"});
  ASSERT_TRUE(ok.ok()) << ok.status().ToString();
  EXPECT_EQ(ok->model, "lunge2013");
  auto bad = LoadDataset(dir_.string(), {"ts98_coil", "other"});
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().message(), "ds/manifest.json: model: 'lunge2013' is not a known model (known: ts98_coil, other)");
  EXPECT_EQ(LoadDataset(dir_.string(), {}).status().message(),
            "ds/manifest.json: model: 'lunge2013' is not a known model (known: none)");
}

// ---- directory and manifest errors -----------------------------------------------------------------------

TEST_F(DatasetTest, DirectoryErrors) {
  const std::string missing = (root_ / "nope").string();
  auto ds = LoadDataset(missing);
  ASSERT_FALSE(ds.ok());
  EXPECT_EQ(ds.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(ds.status().message(), missing + ": dataset directory does not exist");
  Write("a.csv", kCsvA);
  EXPECT_EQ(LoadDataset((dir_ / "a.csv").string()).status().message(), (dir_ / "a.csv").string() + ": is not a directory");
  ExpectError("ds/manifest.json: does not exist");
}

TEST_F(DatasetTest, ManifestNotJson) {
  Write("manifest.json", "{\"format\": \"valve-runs/1\",\n \"runs\": [}");
  auto ds = Load();
  ASSERT_FALSE(ds.ok());
  EXPECT_EQ(ds.status().code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Contains(ds.status().message(), "ds/manifest.json: not valid JSON: parse error at line 2, column 11"));
  Write("manifest.json", "");
  EXPECT_TRUE(Contains(Load().status().message(), "ds/manifest.json: not valid JSON: parse error at line 1"));
  Write("manifest.json", "[1, 2]");
  ExpectError("ds/manifest.json: must be a JSON object, found an array");
}

TEST_F(DatasetTest, ManifestTopLevelErrors) {
  ExpectManifestError([](json& m) { m.erase("format"); }, "ds/manifest.json: format: missing");
  ExpectManifestError([](json& m) { m["format"] = 1; }, "ds/manifest.json: format: must be a string, found a number");
  ExpectManifestError([](json& m) { m["format"] = "valve-runs/3"; },
                      "ds/manifest.json: format: 'valve-runs/3' is not valve-runs/1 or valve-runs/2");
  ExpectManifestError([](json& m) { m.erase("model"); }, "ds/manifest.json: model: missing");
  ExpectManifestError([](json& m) { m["model"] = "foo"; },
                      "ds/manifest.json: model: 'foo' is not a known model (known: taghizadeh2009)");
  ExpectManifestError([](json& m) { m["description"] = 5; },
                      "ds/manifest.json: description: must be a string, found a number");
  ExpectManifestError([](json& m) { m.erase("runs"); }, "ds/manifest.json: runs: missing");
  ExpectManifestError([](json& m) { m["runs"] = json::object(); },
                      "ds/manifest.json: runs: must be an array, found an object");
  ExpectManifestError([](json& m) { m["runs"] = json::array(); }, "ds/manifest.json: runs: must not be empty");
  ExpectManifestError([](json& m) { m["runs"][1] = 3; }, "ds/manifest.json: runs[1]: must be an object, found a number");
}

TEST_F(DatasetTest, RunIdErrors) {
  ExpectManifestError([](json& m) { m["runs"][1].erase("id"); }, "ds/manifest.json: runs[1].id: missing");
  ExpectManifestError([](json& m) { m["runs"][1]["id"] = 7; },
                      "ds/manifest.json: runs[1].id: must be a string, found a number");
  ExpectManifestError([](json& m) { m["runs"][1]["id"] = ""; }, "ds/manifest.json: runs[1].id: must not be empty");
  ExpectManifestError([](json& m) { m["runs"][1]["id"] = "a"; },
                      "ds/manifest.json: runs[1].id: 'a' is also the id of runs[0]");
}

TEST_F(DatasetTest, RunFileErrors) {
  ExpectManifestError([](json& m) { m["runs"][1].erase("file"); }, "ds/manifest.json: runs[1].file: missing");
  ExpectManifestError([](json& m) { m["runs"][1]["file"] = ""; }, "ds/manifest.json: runs[1].file: must not be empty");
  ExpectManifestError([](json& m) { m["runs"][1]["file"] = "x.csv"; },
                      "ds/manifest.json: runs[1].file: 'x.csv' does not exist");
  // Escapes are rejected even when the target exists.
  const std::string abs = (dir_ / "b.csv").string();
  ExpectManifestError([&](json& m) { m["runs"][1]["file"] = abs; },
                      "ds/manifest.json: runs[1].file: '" + abs.substr(0, 40) + (abs.size() > 40 ? "..." : "") +
                          "' is an absolute path; files must be inside the dataset directory");
  ExpectManifestError([](json& m) { m["runs"][1]["file"] = "../ds/b.csv"; },
                      "ds/manifest.json: runs[1].file: '../ds/b.csv' is outside the dataset directory");
  ExpectManifestError([](json& m) { m["runs"][1]["file"] = "sub/../../ds/b.csv"; },
                      "ds/manifest.json: runs[1].file: 'sub/../../ds/b.csv' is outside the dataset directory");
  fs::create_directories(dir_ / "sub");
  ExpectManifestError([](json& m) { m["runs"][1]["file"] = "sub"; },
                      "ds/manifest.json: runs[1].file: 'sub' is not a regular file");
}

TEST_F(DatasetTest, RunNumberErrors) {
  ExpectManifestError([](json& m) { m["runs"][1].erase("supply_V"); }, "ds/manifest.json: runs[1].supply_V: missing");
  ExpectManifestError([](json& m) { m["runs"][1]["supply_V"] = "24"; },
                      "ds/manifest.json: runs[1].supply_V: must be a number, found a string");
  ExpectManifestError([](json& m) { m["runs"][1]["supply_V"] = true; },
                      "ds/manifest.json: runs[1].supply_V: must be a number, found a boolean");
  ExpectManifestError([](json& m) { m["runs"][1]["supply_V"] = 0; }, "ds/manifest.json: runs[1].supply_V: 0 must be > 0");
  ExpectManifestError([](json& m) { m["runs"][1]["supply_V"] = -12.5; },
                      "ds/manifest.json: runs[1].supply_V: -12.5 must be > 0");
  ExpectManifestError([](json& m) { m["runs"][1].erase("supply_pressure_Pa"); },
                      "ds/manifest.json: runs[1].supply_pressure_Pa: missing");
  ExpectManifestError([](json& m) { m["runs"][1]["supply_pressure_Pa"] = -1; },
                      "ds/manifest.json: runs[1].supply_pressure_Pa: -1 must be >= 0");
  ExpectManifestError([](json& m) { m["runs"][1]["supply_pressure_Pa"] = nullptr; },
                      "ds/manifest.json: runs[1].supply_pressure_Pa: must be a number, found null");
  ExpectManifestError([](json& m) { m["runs"][1].erase("t_start_s"); }, "ds/manifest.json: runs[1].t_start_s: missing");
  ExpectManifestError([](json& m) { m["runs"][1]["t_start_s"] = -0.5; },
                      "ds/manifest.json: runs[1].t_start_s: -0.5 must be >= 0");
}

TEST_F(DatasetTest, NonFiniteManifestNumbersAreRejected) {
  // JSON has no inf or nan; an overflowing literal is reported by the JSON parser.
  WriteValid();
  std::string text = ValidManifest().dump();
  text.replace(text.find("24.0"), 4, "1e999");
  Write("manifest.json", text);
  auto ds = Load();
  ASSERT_FALSE(ds.ok());
  EXPECT_EQ(ds.status().code(), StatusCode::kInvalidArgument);
  EXPECT_TRUE(Contains(ds.status().message(), "ds/manifest.json: not valid JSON: number overflow parsing '1e999'"));
}

TEST_F(DatasetTest, RunSplitErrors) {
  ExpectManifestError([](json& m) { m["runs"][1]["split"] = "train"; },
                      "ds/manifest.json: runs[1].split: 'train' is not fit or holdout");
  ExpectManifestError([](json& m) { m["runs"][1]["split"] = "Fit"; },
                      "ds/manifest.json: runs[1].split: 'Fit' is not fit or holdout");
  ExpectManifestError([](json& m) { m["runs"][1]["split"] = nullptr; },
                      "ds/manifest.json: runs[1].split: must be a string, found null");
}

TEST_F(DatasetTest, RunsOutOfTimeOrder) {
  ExpectManifestError([](json& m) { m["runs"][1]["t_start_s"] = 0.5; },
                      "ds/manifest.json: runs[1].t_start_s: run 'b' starts at 0.5 s, before runs[0] 'a' at 1 s; runs "
                      "must be listed in time order");
}

// ---- CSV errors ------------------------------------------------------------------------------------------

TEST_F(DatasetTest, CsvHeaderErrors) {
  ExpectCsvError("", "ds/b.csv: empty file; expected a header row such as t_s,gate,i_A");
  ExpectCsvError("\n0,0,0\n", "ds/b.csv:1: empty line; expected a header row such as t_s,gate,i_A");
  ExpectCsvError("t_s,gate\n0,0\n0.25,1\n", "ds/b.csv:1: missing required column i_A (header 't_s,gate')");
  ExpectCsvError("gate,i_A\n0,0\n", "ds/b.csv:1: missing required column t_s (header 'gate,i_A')");
  ExpectCsvError("t_s,i_A,I_A\n0,0,0\n", "ds/b.csv:1: missing required column gate (header 't_s,i_A,I_A')");
  ExpectCsvError("t_s,gate,i_A,gate\n0,0,0,0\n", "ds/b.csv:1: column gate appears twice in the header");
  ExpectCsvError("t_s,gate,i_A,\n0,0,0,\n", "ds/b.csv:1: column 4 of the header has an empty name");
  ExpectCsvError("t_s;gate;i_A\n0;0;0\n",
                 "ds/b.csv:1: missing required column t_s (header 't_s;gate;i_A')");
}

TEST_F(DatasetTest, CsvLineErrors) {
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n\n0.5,0,0\n",
                 "ds/b.csv:3: empty line (empty lines are only allowed as the final newline)");
  ExpectCsvError("t_s,gate,i_A\r\n0,0,0\r\n0.25,0,0\r\n\r\n0.75,0,0\r\n",
                 "ds/b.csv:4: empty line (empty lines are only allowed as the final newline)");
  ExpectCsvError(std::string(kCsvB) + "\n", "ds/b.csv:5: empty line (empty lines are only allowed as the final newline)");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0.25,1\n0.5,0,0\n", "ds/b.csv:3: 2 fields, but the header has 3");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0.25,1,0,7\n", "ds/b.csv:3: 4 fields, but the header has 3");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0.25,1,0,\n", "ds/b.csv:3: 4 fields, but the header has 3");
  ExpectCsvError("t_s,gate,i_A,note\n0,0,0,x\n0.25,1,0\n", "ds/b.csv:3: 3 fields, but the header has 4");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\nx,1,0,7\n", "ds/b.csv:3: 4 fields, but the header has 3");  // before values
}

TEST_F(DatasetTest, CsvValueErrors) {
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0.25,1,0\n0.5,1,abc\n", "ds/b.csv:4: column i_A: 'abc' is not a number");
  ExpectCsvError("t_s,gate,i_A\n0,0,\n", "ds/b.csv:2: column i_A: '' is not a number");
  ExpectCsvError("t_s,gate,i_A\n0, 1,0\n", "ds/b.csv:2: column gate: ' 1' is not a number");
  ExpectCsvError("t_s,gate,i_A\n0,0,0.5A\n", "ds/b.csv:2: column i_A: '0.5A' is not a number");
  ExpectCsvError("t_s,gate,i_A\n0,0,+1\n", "ds/b.csv:2: column i_A: '+1' is not a number");
  ExpectCsvError("t_s,gate,i_A\n0,0,0x1\n", "ds/b.csv:2: column i_A: '0x1' is not a number");
  ExpectCsvError("t_s,gate,i_A\nabc,x,0\n", "ds/b.csv:2: column t_s: 'abc' is not a number");  // left to right
  ExpectCsvError("t_s,gate,i_A\n0,0,\"0.5\"\n", "ds/b.csv:2: column i_A: '\"0.5\"' is not a number");
  ExpectCsvError("t_s,gate,i_A\nx,0,0\n", "ds/b.csv:2: column t_s: 'x' is not a number");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0.25,1,nan\n", "ds/b.csv:3: column i_A: 'nan' is not a finite number");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0.25,1,-inf\n", "ds/b.csv:3: column i_A: '-inf' is not a finite number");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0.25,1,1e999\n", "ds/b.csv:3: column i_A: '1e999' is not a finite number");
  ExpectCsvError("t_s,gate,i_A,x_m\n0,0,0,0\n0.25,1,0,?\n", "ds/b.csv:3: column x_m: '?' is not a number");
  ExpectCsvError("t_s,gate,i_A,v_coil_V\n0,0,0,0\n0.25,1,0,24V\n", "ds/b.csv:3: column v_coil_V: '24V' is not a number");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0.25,0.5,0\n", "ds/b.csv:3: column gate: '0.5' is not 0 or 1");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0.25,2,0\n", "ds/b.csv:3: column gate: '2' is not 0 or 1");
  ExpectCsvError("t_s,gate,i_A\n0,-1,0\n", "ds/b.csv:2: column gate: '-1' is not 0 or 1");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\r\r\n", "ds/b.csv:2: column i_A: '0\\r' is not a number");
  ExpectCsvError("t_s,gate,i_A\n0,0," + std::string(60, '9') + "x\n",
                 "ds/b.csv:2: column i_A: '" + std::string(40, '9') + "...' is not a number");
}

TEST_F(DatasetTest, CsvTimeErrors) {
  ExpectCsvError("t_s,gate,i_A\n0.1,0,0\n0.35,0,0\n",
                 "ds/b.csv:2: column t_s: the first sample is at 0.1 s; a run starts at t_s = 0");
  ExpectCsvError("t_s,gate,i_A\n1e-8,0,0\n0.25,0,0\n",
                 "ds/b.csv:2: column t_s: the first sample is at 1e-08 s; a run starts at t_s = 0");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0,0,0\n", "ds/b.csv:3: column t_s: time does not increase (0 s after 0 s)");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n-0.25,0,0\n",
                 "ds/b.csv:3: column t_s: time does not increase (-0.25 s after 0 s)");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0.25,0,0\n0.5,0,0\n1,0,0\n1.25,0,0\n",
                 "ds/b.csv:5: column t_s: step 0.5 s (from 0.5 to 1 s) differs from the first step 0.25 s; "
                 "sampling must be uniform");
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0.25,0,0\n0.5,0,0\n0.5,0,0\n",
                 "ds/b.csv:5: column t_s: step 0 s (from 0.5 to 0.5 s) differs from the first step 0.25 s; "
                 "sampling must be uniform");
  // Steps are computed, so they are shown to 9 significant digits (not 0.25000029999999995).
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n0.25,0,0\n0.5000003,0,0\n",
                 "ds/b.csv:4: column t_s: step 0.2500003 s (from 0.25 to 0.5000003 s) differs from the first step "
                 "0.25 s; sampling must be uniform");
}

TEST_F(DatasetTest, CsvTooFewSamples) {
  ExpectCsvError("t_s,gate,i_A\n0,0,0\n", "ds/b.csv: 1 sample; a run needs at least 2");
  ExpectCsvError("t_s,gate,i_A\n", "ds/b.csv: 0 samples; a run needs at least 2");
  ExpectCsvError("t_s,gate,i_A", "ds/b.csv: 0 samples; a run needs at least 2");
}

TEST_F(DatasetTest, ErrorsNameTheFirstBadRunAndLine) {
  WriteValid();
  Write("a.csv", "t_s,gate,i_A\n0,0,0\n2e-05,1,oops\n");
  Write("b.csv", "t_s,gate,i_A\n0,0,bad\n");
  ExpectError("ds/a.csv:3: column i_A: 'oops' is not a number");
  Write("a.csv", "t_s,gate,i_A\n0,0,0\n2e-05,1,x\n4e-05,1,0,0\n");
  ExpectError("ds/a.csv:3: column i_A: 'x' is not a number");
}

// ---- speed -----------------------------------------------------------------------------------------------

// Writes a 12-run dataset of 6000 samples each (the practice size) and loads it.
TEST_F(DatasetTest, LoadsTwelveRunsOfSixThousandRowsQuickly) {
  json m = ValidManifest();
  m["runs"] = json::array();
  for (int r = 0; r < 12; ++r) {
    const std::string id = "run" + std::to_string(r);
    m["runs"].push_back({{"id", id}, {"file", id + ".csv"}, {"supply_V", 24.0}, {"supply_pressure_Pa", 3e5},
                         {"t_start_s", 0.5 * r}, {"split", r % 3 == 0 ? "holdout" : "fit"}});
    std::string csv = "t_s,gate,i_A\n";
    char line[64];
    for (int k = 0; k < 6000; ++k) {
      std::snprintf(line, sizeof line, "%.5f,%d,%.6g\n", k * 2e-5, (k / 100) % 2, 0.000732601 * (k % 4096));
      csv += line;
    }
    Write(id + ".csv", csv);
  }
  Write("manifest.json", m.dump(1));
  const auto t0 = std::chrono::steady_clock::now();
  auto ds = Load();
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  ASSERT_TRUE(ds.ok()) << ds.status().ToString();
  ASSERT_EQ(ds->runs.size(), 12u);
  for (const RunData& run : ds->runs) {
    EXPECT_EQ(run.t_s.size(), 6000u);
    EXPECT_NEAR(run.sample_period_s, 2e-5, 1e-12);
  }
  std::printf("12 runs x 6000 rows loaded in %.1f ms\n", ms);
  RecordProperty("load_ms", std::to_string(ms));
  EXPECT_LT(ms, 1000.0);  // a gross bound (sanitizer and debug builds); an -O2 build takes a few ms
}

// ---- the noise from second differences ------------------------------------------------------------------

// A switch-on at 50 kHz: the current's slope jumps by V / L at the gate edge and an eddy path adds a step there
// that decays in 20 us. Over 500 samples that one edge makes the all-samples estimate several times the noise the
// scope added; between the edges it is the noise (within the spread of 500 Gaussian draws, about 5 %). A PWM
// waveform sampled five times a period has no samples far from an edge, and falls back to all of them.
TEST(SecondDifferenceNoise, TheGateEdgeIsNotNoise) {
  const double dt_s = 20e-6, tau_s = 1.0e-3, final_A = 0.4, eddy_A = 0.1, sigma_A = 0.5e-3;
  std::mt19937 rng(4242);
  std::normal_distribution<double> noise(0.0, sigma_A);
  std::vector<double> i_A;
  std::vector<int8_t> gate;
  for (int k = 0; k < 500; ++k) {
    const double t_s = (k - 5) * dt_s;
    const bool on = k >= 5;
    gate.push_back(on ? 1 : 0);
    const double clean = on ? final_A * (1.0 - std::exp(-t_s / tau_s)) + eddy_A * std::exp(-t_s / 20e-6) : 0.0;
    i_A.push_back(clean + noise(rng));
  }
  const double all = SecondDifferenceSigma(i_A);
  const double between = SecondDifferenceSigma(i_A, gate, dt_s);
  EXPECT_GT(all, 3.0 * sigma_A) << "the edge should dominate the all-samples estimate";
  EXPECT_NEAR(between, sigma_A, 0.1 * sigma_A);
  // Without an edge the two agree.
  std::vector<double> flat(i_A.begin() + 100, i_A.end());
  EXPECT_DOUBLE_EQ(SecondDifferenceSigma(flat, std::vector<int8_t>(flat.size(), 1), dt_s), SecondDifferenceSigma(flat));
  // A gate that switches every 2-3 samples leaves no sample outside the guard: every sample is used.
  std::vector<int8_t> pwm(i_A.size());
  for (std::size_t k = 0; k < pwm.size(); ++k) pwm[k] = (k / 2) % 2 == 0 ? 1 : 0;
  EXPECT_DOUBLE_EQ(SecondDifferenceSigma(i_A, pwm, dt_s), all);
  // A sample period that is not one falls back as well.
  EXPECT_DOUBLE_EQ(SecondDifferenceSigma(i_A, gate, NAN), all);
}

// ---- the practice datasets -------------------------------------------------------------------------------

TEST(PracticeDatasets, AllLoad) {
#ifndef VB_SHARED_DIR
  GTEST_SKIP() << "VB_SHARED_DIR is not defined";
#else
  const fs::path practice = fs::path(VB_SHARED_DIR) / "gapbench" / "practice";
  if (!fs::is_directory(practice)) GTEST_SKIP() << practice << " is missing";
  double total_ms = 0.0;
  for (int p = 1; p <= 12; ++p) {
    const std::string name = (p < 10 ? "p0" : "p") + std::to_string(p);
    SCOPED_TRACE(name);
    const fs::path dir = practice / name;
    ASSERT_TRUE(fs::is_directory(dir)) << dir;
    std::ifstream mf(dir / "manifest.json");
    const json manifest = json::parse(mf);

    const auto t0 = std::chrono::steady_clock::now();
    auto ds = LoadDataset(dir.string());
    total_ms += std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    ASSERT_TRUE(ds.ok()) << ds.status().ToString();
    EXPECT_EQ(ds->format, "valve-runs/1");
    EXPECT_EQ(ds->model, "taghizadeh2009");
    EXPECT_TRUE(ds->warnings.empty());
    ASSERT_EQ(ds->runs.size(), manifest["runs"].size());
    for (size_t k = 0; k < ds->runs.size(); ++k) {
      const RunData& run = ds->runs[k];
      SCOPED_TRACE(run.id);
      EXPECT_EQ(run.id, manifest["runs"][k]["id"].get<std::string>());
      EXPECT_TRUE(run.split == Split::kFit || run.split == Split::kHoldout) << SplitName(run.split);
      EXPECT_GT(run.supply_V, 0.0);
      if (k > 0) {
        EXPECT_GE(run.t_start_s, ds->runs[k - 1].t_start_s);
      }
      EXPECT_NEAR(run.sample_period_s, 2e-5, 1e-12);
      ASSERT_GE(run.t_s.size(), 2u);
      EXPECT_EQ(run.gate.size(), run.t_s.size());
      EXPECT_EQ(run.i_A.size(), run.t_s.size());
      EXPECT_TRUE(run.x_m.empty());
      EXPECT_TRUE(run.v_coil_V.empty());
      size_t ones = 0;
      for (int8_t g : run.gate) {
        ASSERT_TRUE(g == 0 || g == 1) << int(g);
        ones += static_cast<size_t>(g);
      }
      EXPECT_GT(ones, 0u);  // every run switches the valve on
      for (double i : run.i_A) ASSERT_TRUE(i >= 0.0 && i <= 3.0) << i;  // the 0..3 A acquisition range
    }
  }
  std::printf("12 practice datasets loaded in %.1f ms\n", total_ms);
  RecordProperty("practice_load_ms", std::to_string(total_ms));
#endif
}

}  // namespace
}  // namespace vb::gap
