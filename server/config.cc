#include "server/config.h"
#include "server/health_check.h"
#include "service/prune_rules.h"

#include <fmt/format.h>
#include <google/protobuf/util/json_util.h>

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include "common/format.h"
#include "experiment/spec.h"
#include "regress/compare.h"
#include "regress/cron.h"
#include "regress/suite.h"
#include "db/open_store.h"

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

// A file named in the config could not be used: for a relative path, say what it was relative to, since a
// config copied elsewhere (or its files left behind) fails exactly here.
Status WithPathNote(const Status& st, const std::string& base_dir, const std::string& given) {
  if (st.ok() || given.empty() || std::filesystem::path(given).is_absolute()) return st;
  std::error_code ec;
  const std::string dir = base_dir.empty() ? std::filesystem::current_path(ec).string() : base_dir;
  const std::string note = " ('" + given + "' is relative to the config file's directory, " + dir +
                           "; copy the file along with the config, or give an absolute path)";
  switch (st.code()) {
    case StatusCode::kNotFound: return Status::NotFound(st.message() + note);
    case StatusCode::kInvalidArgument: return Status::InvalidArgument(st.message() + note);
    default: return st.WithContext(note.substr(2, note.size() - 3));
  }
}

StatusOr<hw::SafetyLimits> SafetyFromConfig(const valvebench::v1::SafetyConfig& c, double max_current_A, bool hardware,
                                            const std::string& field) {
  hw::SafetyLimits l;
  l.max_current_A = max_current_A;
  if (c.max_duty() != 0.0) l.max_duty = c.max_duty();
  l.max_on_time_s = c.max_on_time_s();
  l.max_coil_temp_C = c.max_coil_temp_c();
  l.coil_R_ohm = c.coil_r_ohm();
  l.thermal_resistance_K_per_W = c.thermal_resistance_k_per_w();
  l.thermal_time_constant_s = c.thermal_time_constant_s();
  if (c.ambient_c() != 0.0) l.ambient_C = c.ambient_c();
  l.watchdog_s = c.watchdog_s() > 0.0 ? c.watchdog_s() : (hardware ? 1.0 : 0.0);
  Status st = l.Validate();
  if (!st.ok()) return st.WithContext(field);
  return l;
}

std::string Hex4(unsigned v) {
  return fmt::format("{:04x}", v & 0xFFFF);
}

// A hid or u3 bench: its declared capabilities (what submissions are checked against; the device's own
// identity narrows them when it is opened) and interlocks.
Status HardwareSetup(const valvebench::v1::BenchConfig& b, const std::string& field, BenchSetup* setup) {
  auto positive = [&](double v, const char* name) -> Status {
    if (v < 0.0) return Status::InvalidArgument(field + "." + name + ": must be >= 0, got " + std::to_string(v));
    return Status::Ok();
  };
  VB_RETURN_IF_ERROR(positive(b.max_supply_v(), "max_supply_V"));
  VB_RETURN_IF_ERROR(positive(b.max_current_a(), "max_current_A"));
  VB_RETURN_IF_ERROR(positive(b.max_sample_rate_hz(), "max_sample_rate_Hz"));
  VB_RETURN_IF_ERROR(positive(b.max_control_rate_hz(), "max_control_rate_Hz"));
  VB_RETURN_IF_ERROR(positive(b.amps_per_volt(), "amps_per_volt"));
  if (b.has_model()) return Status::InvalidArgument(field + ".model: only emulated benches have a model");
  const bool hid = setup->kind == BenchKind::kHid;
  if (b.vendor_id() > 0xFFFF || b.product_id() > 0xFFFF)
    return Status::InvalidArgument(field + ".vendor_id/product_id: must fit 16 bits");
  if (!hid && (b.vendor_id() != 0 || b.product_id() != 0))
    return Status::InvalidArgument(field + ".vendor_id/product_id: a u3 is always 0cd5:0003");
  if (!hid && !b.serial().empty() && b.serial().find_first_not_of("0123456789") != std::string::npos)
    return Status::InvalidArgument(field + ".serial: a U3 serial number is decimal, got '" + b.serial() + "'");
  hw::Capabilities& c = setup->caps;
  c.kind = BenchKindName(setup->kind);
  c.driver = "low_side_flyback";
  c.max_supply_V = b.max_supply_v() > 0.0 ? b.max_supply_v() : 24.0;
  c.max_current_A = b.max_current_a() > 0.0 ? b.max_current_a() : 2.0;
  c.max_sample_rate_Hz = b.max_sample_rate_hz() > 0.0 ? b.max_sample_rate_hz() : (hid ? 20'000.0 : 10'000.0);
  c.max_control_rate_Hz = b.max_control_rate_hz() > 0.0 ? b.max_control_rate_hz() : 1'000.0;
  c.min_carrier_Hz = hid ? 10.0 : 1e6 / 256.0 / 65536.0;
  c.max_carrier_Hz = hid ? 100e3 : 48e6 / 256.0;
  c.serial = b.serial();
  setup->bench_class = BenchClass(setup->kind, "");
  setup->device = hid ? "hid " + Hex4(b.vendor_id() ? b.vendor_id() : 0x2E8A) + ":" +
                            Hex4(b.product_id() ? b.product_id() : 0x10C0) +
                            (b.serial().empty() ? "" : " serial " + b.serial())
                      : "u3 0cd5:0003" + (b.serial().empty() ? std::string() : " serial " + b.serial());
  auto safety = SafetyFromConfig(b.safety(), c.max_current_A, /*hardware=*/true, field);
  if (!safety.ok()) return safety.status();
  setup->safety = *safety;
  return Status::Ok();
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
  if (!suite.ok())
    return WithPathNote(suite.status().WithContext("nights.suite_file " + out.suite_path), base_dir, n.suite_file());
  auto baseline = LoadBaselineFile(out.baseline_path);
  if (!baseline.ok())
    return WithPathNote(baseline.status().WithContext("nights.baseline_file"), base_dir, n.baseline_file());
  return out;
}

// retention: checked at start like nights, so a typo stops the server instead of silently never pruning.
StatusOr<RetentionSetup> RetentionFromConfig(const valvebench::v1::ServerConfig& c) {
  RetentionSetup out;
  if (!c.has_retention()) return out;
  const auto& r = c.retention();
  if (!std::isfinite(r.older_than_days()) || !(r.older_than_days() > 0.0))
    return Status::InvalidArgument("retention.older_than_days: must be a number of days > 0, got " +
                                   FormatExact(r.older_than_days()));
  if (r.older_than_days() > 1e6)
    return Status::InvalidArgument("retention.older_than_days: " + FormatExact(r.older_than_days()) +
                                   " days reaches before 1970");
  if (r.keep_last() < 0)
    return Status::InvalidArgument("retention.keep_last: must be >= 0, got " + std::to_string(r.keep_last()));
  if (!r.cron().empty()) {
    auto cron = regress::Cron::Parse(r.cron());
    if (!cron.ok()) return Status::InvalidArgument("retention.cron: " + cron.status().message());
    out.cron = r.cron();
  }
  out.enabled = true;
  out.older_than_days = r.older_than_days();
  out.keep_last = r.keep_last();
  return out;
}

// lab: checked at start; a heartbeat that cannot keep a lease alive would have every run re-queued under it.
StatusOr<LabSetup> LabFromConfig(const valvebench::v1::ServerConfig& c) {
  LabSetup out;
  if (!c.has_lab()) return out;
  const auto& l = c.lab();
  out.enabled = true;
  out.host = l.host();
  if (out.host.empty()) {
    char name[256] = {};
    if (gethostname(name, sizeof name - 1) != 0 || name[0] == '\0')
      return Status::InvalidArgument("lab.host: not set, and this machine's hostname cannot be read; set it");
    out.host = name;
  }
  if (out.host.size() > 200) return Status::InvalidArgument("lab.host: at most 200 characters");
  out.advertised_address = l.advertised_address();
  if (!std::isfinite(l.lease_ttl_s()) || l.lease_ttl_s() < 0)
    return Status::InvalidArgument("lab.lease_ttl_s: must be a number of seconds > 0, got " + FormatExact(l.lease_ttl_s()));
  if (l.lease_ttl_s() > 0) out.lease_ttl_s = l.lease_ttl_s();
  if (!std::isfinite(l.heartbeat_s()) || l.heartbeat_s() < 0)
    return Status::InvalidArgument("lab.heartbeat_s: must be a number of seconds > 0, got " + FormatExact(l.heartbeat_s()));
  out.heartbeat_s = l.heartbeat_s() > 0 ? l.heartbeat_s() : out.lease_ttl_s / 3.0;
  if (out.heartbeat_s * 2 > out.lease_ttl_s)
    return Status::InvalidArgument("lab.heartbeat_s: " + FormatExact(out.heartbeat_s) +
                                   " s is more than half of lab.lease_ttl_s (" + FormatExact(out.lease_ttl_s) +
                                   " s): one late heartbeat would let the leases lapse");
  if (!std::isfinite(l.aging_s()))
    return Status::InvalidArgument("lab.aging_s: must be finite (< 0: no aging), got " + FormatExact(l.aging_s()));
  out.aging_s = l.aging_s() < 0 ? 0.0 : l.aging_s() > 0 ? l.aging_s() : 60.0;
  return out;
}

}  // namespace



// A host process's own state (the spool, the web sessions): "none" nothing; a path relative to the config; by
// default beside an SQLite database (`database_path + suffix`, "-<lab.host>" appended in a lab) or in systemd's
// $STATE_DIRECTORY (the first, when it lists several) for PostgreSQL, else nothing. One per process: the instance
// lock holds the store or the host identity these defaults derive from.
static std::string HostStatePath(const std::string& configured, const std::string& base_dir, const Settings& s,
                          const char* suffix, const char* state_name) {
  if (configured == "none") return "";
  if (!configured.empty()) return Resolve(base_dir, configured);
  if (!db::IsPostgresLocation(s.database_path))
    return s.database_path + suffix + (s.lab.enabled ? "-" + s.lab.host : std::string());
  const char* state = std::getenv("STATE_DIRECTORY");
  if (state == nullptr || *state == '\0') return "";
  const std::string first = state;
  return first.substr(0, first.find(':')) + "/" + state_name;
}

StatusOr<Settings> SettingsFromConfig(const valvebench::v1::ServerConfig& c, const std::string& base_dir) {
  Settings s;
  if (!c.listen_address().empty()) s.listen_address = c.listen_address();
  // A PostgreSQL connection string is taken as it is; a file path is relative to the config (docs/store.md).
  s.database_path = db::IsPostgresLocation(c.database_path())
                        ? c.database_path()
                        : Resolve(base_dir, c.database_path().empty() ? "valvebench.db" : c.database_path());
  if (c.benches_size() == 0) return Status::InvalidArgument("benches: at least one bench must be configured");
  std::set<std::string> names;
  for (int k = 0; k < c.benches_size(); ++k) {
    const auto& b = c.benches(k);
    const std::string field = "benches[" + std::to_string(k) + "]";
    if (b.name().empty()) return Status::InvalidArgument(field + ".name: must not be empty");
    if (!names.insert(b.name()).second)
      return Status::InvalidArgument(field + ".name: '" + b.name() + "' appears twice");
    auto kind = ParseBenchKind(b.kind(), field + ".kind");
    if (!kind.ok()) return kind.status();
    BenchSetup setup;
    setup.name = b.name();
    setup.kind = *kind;
    setup.config = b;
    if (*kind != BenchKind::kEmulated && !b.pace().empty())
      return Status::InvalidArgument(field + ".pace: only emulated benches are paced (hardware runs in real time)");
    if (*kind != BenchKind::kEmulated) {
      auto hw = HardwareSetup(b, field, &setup);
      if (!hw.ok()) return hw;
      VB_RETURN_IF_ERROR(DriftFromConfig(b, field, &setup));
      VB_RETURN_IF_ERROR(ValidateHealthCheck(b, setup.caps, field));
      s.benches.push_back(std::move(setup));
      continue;
    }
    setup.model = b.model();
    if (b.pace() == "realtime") {
      setup.paced = true;
    } else if (!b.pace().empty()) {
      return Status::InvalidArgument(field + ".pace: unknown pace '" + b.pace() +
                                     "' (\"realtime\": wall-clock speed, as hardware; \"\": as fast as it goes)");
    }
    auto plant = experiment::BuildPlant(b.model());
    if (!plant.ok()) return plant.status().WithContext(field);
    auto driver = experiment::BuildDriver(b.driver());
    if (!driver.ok()) return driver.status().WithContext(field);
    setup.preset = plant->preset;
    setup.bench_class = BenchClass(*kind, setup.preset);
    setup.emulated.name = b.name();
    setup.emulated.plant = *plant;
    setup.emulated.driver = *driver;
    if (b.max_supply_v() > 0.0) setup.emulated.max_supply_V = b.max_supply_v();
    if (b.max_current_a() > 0.0) setup.emulated.max_current_A = b.max_current_a();
    setup.caps = hw::EmulatedBench(setup.emulated).capabilities();
    auto safety = SafetyFromConfig(b.safety(), setup.caps.max_current_A, /*hardware=*/false, field);
    if (!safety.ok()) return safety.status();
    setup.safety = *safety;
    VB_RETURN_IF_ERROR(DriftFromConfig(b, field, &setup));
    VB_RETURN_IF_ERROR(ValidateHealthCheck(b, setup.caps, field));
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
    if (!cert.ok()) return WithPathNote(cert.status(), base_dir, c.tls().cert_file());
    auto key = ReadFile(Resolve(base_dir, c.tls().key_file()), "tls.key_file");
    if (!key.ok()) return WithPathNote(key.status(), base_dir, c.tls().key_file());
    s.tls_cert_pem = *cert;
    s.tls_key_pem = *key;
  }
  s.limits = c.limits();
  if (s.limits.max_spec_bytes() == 0) s.limits.set_max_spec_bytes(1 << 20);
  if (s.limits.max_duration_s() == 0.0) s.limits.set_max_duration_s(600.0);
  if (s.limits.max_record_rate_hz() == 0.0) s.limits.set_max_record_rate_hz(1e6);
  if (s.limits.max_queued_runs_per_user() == 0) s.limits.set_max_queued_runs_per_user(10000);
  if (s.limits.max_runs_per_submission() == 0) s.limits.set_max_runs_per_submission(10000);
  if (s.limits.max_trace_mb_per_run() == 0.0) s.limits.set_max_trace_mb_per_run(512.0);
  if (!(s.limits.max_trace_mb_per_run() > 0.0) || !std::isfinite(s.limits.max_trace_mb_per_run()))
    return Status::InvalidArgument("limits.max_trace_MB_per_run: must be > 0");
  if (!(s.limits.max_disk_mb_per_user() >= 0.0) || !std::isfinite(s.limits.max_disk_mb_per_user()))
    return Status::InvalidArgument("limits.max_disk_MB_per_user: must be >= 0 (0 = no limit)");
  auto nights = NightsFromConfig(c.nights(), base_dir);
  if (!nights.ok()) return nights.status();
  s.nights = std::move(*nights);
  auto retention = RetentionFromConfig(c);
  if (!retention.ok()) return retention.status();
  s.retention = std::move(*retention);
  auto lab = LabFromConfig(c);
  if (!lab.ok()) return lab.status();
  s.lab = std::move(*lab);
  if (s.lab.enabled) s.nights.lab_host = s.lab.host, s.nights.lab_lease_ttl_s = s.lab.lease_ttl_s;
  // The spool: one directory per host process (the instance lock holds the store or the host identity, so a
  // default derived from them is never shared by two processes).
  s.spool_dir = HostStatePath(c.spool_dir(), base_dir, s, ".spool", "spool");
  if (c.spool_max_mb() != 0.0) {
    if (!(c.spool_max_mb() >= 1.0) || !std::isfinite(c.spool_max_mb()) || c.spool_max_mb() > 1e9)
      return Status::InvalidArgument("spool_max_mb: must be 1 to 1e9 MB (0 = the default, 1024), got " +
                                     FormatExact(c.spool_max_mb()));
    s.spool_max_bytes = static_cast<std::uint64_t>(c.spool_max_mb() * 1e6);
  }
  if (c.has_web()) {
    const std::string& a = c.web().listen_address();
    const size_t colon = a.rfind(':');
    const std::string port = colon == std::string::npos ? "" : a.substr(colon + 1);
    if (colon == std::string::npos || colon == 0 || port.empty() ||
        port.find_first_not_of("0123456789") != std::string::npos || port.size() > 5 || std::stoi(port) > 65535)
      return Status::InvalidArgument("web.listen_address: must be host:port (e.g. \"127.0.0.1:8080\"), got '" + a +
                                     "'");
    s.web_listen_address = a;
    const auto& w = c.web();
    if (w.head_timeout_s() < 0 || !std::isfinite(w.head_timeout_s()) || w.head_timeout_s() > 3600)
      return Status::InvalidArgument("web.head_timeout_s: must be 0 (default 10) to 3600 s");
    if (w.max_connections_per_client() < 0) return Status::InvalidArgument("web.max_connections_per_client: must be >= 0");
    if (w.max_streams() < 0) return Status::InvalidArgument("web.max_streams: must be >= 0");
    if (w.max_streams_per_session() < 0) return Status::InvalidArgument("web.max_streams_per_session: must be >= 0");
    if (w.workers() < 0 || w.workers() > 1024) return Status::InvalidArgument("web.workers: must be 0 (default 64) to 1024");
    const int workers = w.workers() ? w.workers() : 64, streams = w.max_streams() ? w.max_streams() : 48;
    if (streams >= workers)
      return Status::InvalidArgument("web.max_streams: must stay below web.workers (" + std::to_string(workers) +
                                     "): the page's other requests need a worker");
    for (const auto& o : w.allowed_origins())
      if (!(o.rfind("http://", 0) == 0 || o.rfind("https://", 0) == 0) || o.back() == '/')
        return Status::InvalidArgument("web.allowed_origins: '" + o + "' is not scheme://host[:port]");
    s.web = w;
    // The sessions' file, like the spool one per host process (the defaults follow the instance lock's identity).
    s.web_sessions_file = HostStatePath(w.sessions_file(), base_dir, s, ".web-sessions", "web-sessions");
  }
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
