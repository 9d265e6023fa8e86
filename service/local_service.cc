#include "service/local_service.h"

#include <pwd.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <random>

#include "db/open_store.h"
#include "hw/emulated_bench.h"
#include "runs/admit.h"
#include "service/hosting.h"

namespace vb::server {

namespace {

constexpr double kRelayPeriod_s = 0.02;  // a cancel through the store lands within this
constexpr int kProgressEveryRelays = 10;  // progress into the store every 200 ms

std::string RandomHex(int bytes) {
  std::random_device rd;
  static const char* kHex = "0123456789abcdef";
  std::string out;
  for (int k = 0; k < bytes; ++k) {
    const unsigned v = rd() & 0xFFu;
    out.push_back(kHex[v >> 4]);
    out.push_back(kHex[v & 0xF]);
  }
  return out;
}

// $USER, else the account's name from the password database (a cron job or `env -i` has no $USER), else "local".
std::string DefaultUser() {
  const char* user = std::getenv("USER");
  if (user != nullptr && *user != '\0') return user;
  struct passwd pw {};
  struct passwd* found = nullptr;
  std::array<char, 4096> buf{};
  if (getpwuid_r(getuid(), &pw, buf.data(), buf.size(), &found) == 0 && found != nullptr &&
      found->pw_name != nullptr && *found->pw_name != '\0') {
    return found->pw_name;
  }
  return "local";
}

}  // namespace

StatusOr<std::unique_ptr<LocalService>> LocalService::Start(LocalServiceOptions options) {
  std::unique_ptr<LocalService> s(new LocalService(std::move(options)));
  VB_RETURN_IF_ERROR(s->Init().WithContext(s->Where()));
  return s;
}

std::string LocalService::Describe(const std::string& store) {
  return store.empty() ? "in-memory store (--no-store)" : "local store " + db::DisplayLocation(store);
}

Status LocalService::Init() {
  if (options_.benches.empty()) {
    runs::BenchSetup b = runs::LocalEmulatorSetup();
    hw::EmulatedBenchOptions opts;  // what ListBenches shows of it: the default emulator's capabilities
    opts.name = b.name;
    b.caps = hw::EmulatedBench(opts).capabilities();
    b.preset = "the spec's";
    options_.benches.push_back(std::move(b));
  }
  if (options_.realtime)
    for (auto& b : options_.benches) b.paced = true;
  if (options_.user.empty()) options_.user = DefaultUser();

  // 1. The store. The private one is a SQLite file (every connection of the pool and the workers sees it; an
  // in-memory database would be one per connection) in a directory of its own.
  if (options_.store.empty()) {
    std::error_code ec;
    const auto dir = std::filesystem::temp_directory_path(ec) / ("valvebench-local-" + RandomHex(8));
    if (ec || !std::filesystem::create_directories(dir, ec) || ec)
      return Status::Unavailable("cannot create a private store directory under " +
                                 std::filesystem::temp_directory_path(ec).string() + ": " + ec.message());
    private_dir_ = dir.string();
    store_path_ = (dir / "runs.db").string();
  } else {
    store_path_ = options_.store;
    if (options_.must_exist && !db::IsPostgresLocation(store_path_) && !std::filesystem::exists(store_path_))
      return Status::FailedPrecondition("no local store at " + store_path_ + " (--db FILE or VALVEBENCH_DB)");
    if (!db::IsPostgresLocation(store_path_))
      if (const auto parent = std::filesystem::path(store_path_).parent_path(); !parent.empty()) {
        std::error_code ec;  // a first run on a fresh machine: ~/.local/share/valvebench/ may not exist yet
        std::filesystem::create_directories(parent, ec);
      }
  }

  // 2-4. The host (service/host.h): the store, its left-overs cancelled, the service with this process's user
  // as admin (by a token only this process knows), and with execute the workers and the relay.
  token_ = RandomHex(32);
  google::protobuf::RepeatedPtrField<valvebench::v1::TokenConfig> tokens;
  auto* t = tokens.Add();
  t->set_user(options_.user);
  t->set_role("admin");
  t->set_token_sha256(Sha256Hex(token_));
  auto auth = Authenticator::Create(tokens);
  if (!auth.ok()) return auth.status();
  settings_.auth = std::move(*auth);
  settings_.benches = options_.benches;
  runs::Limits limits;  // none but the trace budget: a quarter of this machine's memory (runs/admit.h)
  limits.max_trace_bytes_per_run = runs::LocalTraceBudgetBytes();
  settings_.admit_limits = limits;
  settings_.limits.set_max_runs_per_submission(static_cast<std::int32_t>(limits.max_runs_per_submission));
  HostOptions h;
  h.store = store_path_;
  h.settings = &settings_;
  h.recovery = options_.execute ? HostOptions::Recovery::kCancelLeftOvers : HostOptions::Recovery::kNone;
  h.keep_traces = options_.keep_traces;
  h.watch_period_s = kRelayPeriod_s;
  h.progress_every = kProgressEveryRelays;
  if (options_.keep_traces) {
    h.on_outcome = [this](runs::Outcome& o) {
      std::lock_guard<std::mutex> lock(kept_mu_);
      kept_[o.run_id] = std::move(o.trace);
    };
  }
  grpc::ServerBuilder builder;  // no listening port: InProcessChannel() only
  auto host = Host::Start(std::move(h), &builder);
  if (!host.ok()) return host.status();
  host_ = std::move(*host);
  if (options_.execute) host_->Run();
  return Status::Ok();
}

LocalService::~LocalService() {
  // A run still executing is cancelled (nobody would resume it), then the service stops; the private file goes
  // after the host's connections are closed.
  if (host_) host_->StopBenches(Host::StopMode::kCancel);
  host_.reset();
  if (!private_dir_.empty()) {
    std::error_code ec;
    std::filesystem::remove_all(private_dir_, ec);
  }
}

std::shared_ptr<grpc::Channel> LocalService::InProcessChannel() {
  grpc::ChannelArguments args = InProcessChannelArguments();
  return host_->server()->InProcessChannel(args);
}

std::optional<experiment::Trace> LocalService::KeptTrace(std::int64_t run_id) const {
  std::lock_guard<std::mutex> lock(kept_mu_);
  auto it = kept_.find(run_id);
  if (it == kept_.end()) return std::nullopt;
  return it->second;
}

}  // namespace vb::server
