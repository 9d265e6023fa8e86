#include "server/config.h"

#include <google/protobuf/util/json_util.h>

#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "experiment/spec.h"
#include "regress/compare.h"
#include "regress/cron.h"
#include "regress/suite.h"

namespace vb::server {

namespace {

StatusOr<std::string> ReadFile(const std::string& path, const std::string& field) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return Status::NotFound(field + ": cannot read '" + path + "'");
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string Resolve(const std::string& base_dir, const std::string& path) {
  if (path.empty() || std::filesystem::path(path).is_absolute() || base_dir.empty()) return path;
  return (std::filesystem::path(base_dir) / path).string();
}

// nights: every field checked now (a bad suite or baseline should stop the server at start, not at 02:00).
StatusOr<NightsSetup> NightsFromConfig(const valvebench::v1::NightsConfig& n, const std::string& base_dir) {
  NightsSetup out;
  if (n.cron().empty() && n.suite_file().empty() && n.baseline_file().empty() && n.timezone().empty()) return out;
  if (n.cron().empty()) return Status::InvalidArgument("nights.cron: must be set (5 fields, e.g. \"0 2 * * *\")");
  auto cron = regress::Cron::Parse(n.cron());
  if (!cron.ok()) return Status::InvalidArgument("nights.cron: " + cron.status().message());
  if (!n.timezone().empty() && n.timezone() != "UTC")
    return Status::InvalidArgument("nights.timezone: '" + n.timezone() + "' is not supported (only \"UTC\")");
  if (n.suite_file().empty()) return Status::InvalidArgument("nights.suite_file: must be set");
  if (n.baseline_file().empty()) return Status::InvalidArgument("nights.baseline_file: must be set");
  out.enabled = true;
  out.cron = n.cron();
  out.suite_path = Resolve(base_dir, n.suite_file());
  out.baseline_path = Resolve(base_dir, n.baseline_file());
  auto suite = regress::LoadSuite(out.suite_path);
  if (!suite.ok()) return suite.status().WithContext("nights.suite_file " + out.suite_path);
  auto baseline = LoadBaselineFile(out.baseline_path);
  if (!baseline.ok()) return baseline.status().WithContext("nights.baseline_file");
  return out;
}

}  // namespace

StatusOr<regress::Baseline> LoadBaselineFile(const std::string& path) {
  auto text = ReadFile(path, path);
  if (!text.ok()) return text.status();
  regress::Json j;
  try {
    j = regress::Json::parse(*text);
  } catch (const regress::Json::exception& e) {
    return Status::InvalidArgument(path + ": not JSON: " + e.what());
  }
  auto b = regress::BaselineFromJson(j);
  if (!b.ok()) return b.status().WithContext(path);
  return b;
}

std::string SpecBenchClass(const valvebench::v1::ExperimentSpec& spec) {
  const std::string kind = spec.bench().kind().empty() ? "emulated" : spec.bench().kind();
  if (kind != "emulated") return kind;
  const std::string preset = spec.bench().model().preset().empty() ? "taghizadeh2009" : spec.bench().model().preset();
  return kind + ":" + preset;
}

StatusOr<Settings> SettingsFromConfig(const valvebench::v1::ServerConfig& c, const std::string& base_dir) {
  Settings s;
  if (!c.listen_address().empty()) s.listen_address = c.listen_address();
  s.database_path = Resolve(base_dir, c.database_path().empty() ? "valvebench.db" : c.database_path());
  if (c.benches_size() == 0) return Status::InvalidArgument("benches: at least one bench must be configured");
  std::set<std::string> names;
  for (int k = 0; k < c.benches_size(); ++k) {
    const auto& b = c.benches(k);
    const std::string field = "benches[" + std::to_string(k) + "]";
    if (b.name().empty()) return Status::InvalidArgument(field + ".name: must not be empty");
    if (!names.insert(b.name()).second)
      return Status::InvalidArgument(field + ".name: '" + b.name() + "' appears twice");
    const std::string kind = b.kind().empty() ? "emulated" : b.kind();
    if (kind != "emulated")
      return Status::InvalidArgument(field + ".kind: '" + kind + "' is not available yet (known: emulated)");
    BenchSetup setup;
    setup.name = b.name();
    setup.kind = kind;
    setup.model = b.model();
    auto plant = experiment::BuildPlant(b.model());
    if (!plant.ok()) return plant.status().WithContext(field);
    auto driver = experiment::BuildDriver(b.driver());
    if (!driver.ok()) return driver.status().WithContext(field);
    setup.preset = plant->preset;
    setup.bench_class = kind + ":" + setup.preset;
    setup.emulated.name = b.name();
    setup.emulated.plant = *plant;
    setup.emulated.driver = *driver;
    if (b.max_supply_v() > 0.0) setup.emulated.max_supply_V = b.max_supply_v();
    if (b.max_current_a() > 0.0) setup.emulated.max_current_A = b.max_current_a();
    s.benches.push_back(std::move(setup));
  }
  auto auth = Authenticator::Create(c.tokens());
  if (!auth.ok()) return auth.status();
  if (c.tokens_size() == 0) return Status::InvalidArgument("tokens: at least one token must be configured");
  s.auth = std::move(auth.value());
  if (c.tls().cert_file().empty() != c.tls().key_file().empty())
    return Status::InvalidArgument("tls: give both cert_file and key_file, or neither");
  if (!c.tls().cert_file().empty()) {
    auto cert = ReadFile(Resolve(base_dir, c.tls().cert_file()), "tls.cert_file");
    if (!cert.ok()) return cert.status();
    auto key = ReadFile(Resolve(base_dir, c.tls().key_file()), "tls.key_file");
    if (!key.ok()) return key.status();
    s.tls_cert_pem = *cert;
    s.tls_key_pem = *key;
  }
  s.limits = c.limits();
  if (s.limits.max_spec_bytes() == 0) s.limits.set_max_spec_bytes(1 << 20);
  if (s.limits.max_duration_s() == 0.0) s.limits.set_max_duration_s(600.0);
  if (s.limits.max_record_rate_hz() == 0.0) s.limits.set_max_record_rate_hz(1e6);
  if (s.limits.max_queued_runs_per_user() == 0) s.limits.set_max_queued_runs_per_user(10000);
  if (s.limits.max_runs_per_submission() == 0) s.limits.set_max_runs_per_submission(10000);
  auto nights = NightsFromConfig(c.nights(), base_dir);
  if (!nights.ok()) return nights.status();
  s.nights = std::move(*nights);
  return s;
}

StatusOr<Settings> LoadSettings(const std::string& config_path) {
  auto text = ReadFile(config_path, "--config");
  if (!text.ok()) return text.status();
  valvebench::v1::ServerConfig c;
  google::protobuf::util::JsonParseOptions opts;
  auto st = google::protobuf::util::JsonStringToMessage(*text, &c, opts);
  if (!st.ok()) return Status::InvalidArgument(config_path + ": " + std::string(st.message()));
  auto s = SettingsFromConfig(c, std::filesystem::path(config_path).parent_path().string());
  if (!s.ok()) return s.status().WithContext(config_path);
  return s;
}

}  // namespace vb::server
