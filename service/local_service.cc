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

constexpr const char* kLeftOverReason = "left over from an interrupted local run";
constexpr auto kRelayPeriod = std::chrono::milliseconds(20);  // a cancel through the store lands within this
constexpr int kProgressEveryRelays = 10;                      // progress into the store every 200 ms

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

// Runs of these benches still queued from an invocation that was interrupted before it ran them.
Status CancelLeftOvers(db::Store* store, const std::vector<runs::BenchSetup>& benches) {
  db::RunFilter f;
  f.status = db::RunStatus::kQueued;
  f.limit = 1000;
  for (;;) {
    auto page = store->ListRuns(f);
    if (!page.ok()) return page.status();
    for (const auto& r : *page)
      for (const auto& b : benches)
        if (r.bench_kind == b.bench_class) {
          VB_RETURN_IF_ERROR(store->RequestCancel(r.id, kLeftOverReason).status());
          break;
        }
    if (static_cast<int>(page->size()) < f.limit) return Status::Ok();
    f.after_id = page->back().id;
  }
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
  pool_ = std::make_unique<StorePool>(store_path_);
  {
    auto store = pool_->Acquire();  // opens (and migrates) the store: its errors come out here, once
    if (!store.ok()) return store.status();
    // 2. Nobody will claim what an interrupted invocation left queued on these benches.
    if (options_.execute) VB_RETURN_IF_ERROR(CancelLeftOvers(store->get(), options_.benches));
  }

  // 3. The service: this process's user as admin, by a token only this process knows.
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
  for (const auto& b : options_.benches) {
    workers_.push_back(std::make_unique<runs::Worker>(b, &registry_));
    workers_.back()->set_keep_traces(options_.keep_traces);
  }
  service_ = std::make_unique<BenchServiceImpl>(&settings_, pool_.get(), &registry_, &workers_);
  grpc::ServerBuilder builder;  // no listening port: InProcessChannel() only
  HostService(&builder, service_.get());
  server_ = builder.BuildAndStart();
  if (server_ == nullptr) return Status::Internal("the local service did not start");

  // 4. The benches' workers, and the relay to other processes on the same store.
  if (options_.execute) {
    for (auto& w : workers_) threads_.emplace_back([this, w = w.get()] { WorkerLoop(w); });
    threads_.emplace_back([this] { RelayLoop(); });
  }
  return Status::Ok();
}

LocalService::~LocalService() {
  stop_.store(true);
  for (auto& w : workers_)
    if (const std::int64_t id = w->current_run(); id != 0) registry_.Cancel(id);
  registry_.NotifyWork();
  for (auto& t : threads_) t.join();
  if (server_) server_->Shutdown(std::chrono::system_clock::now());
  server_.reset();
  service_.reset();
  pool_.reset();  // its connections close before the private file goes
  if (!private_dir_.empty()) {
    std::error_code ec;
    std::filesystem::remove_all(private_dir_, ec);
  }
}

std::shared_ptr<grpc::Channel> LocalService::InProcessChannel() {
  grpc::ChannelArguments args = InProcessChannelArguments();
  return server_->InProcessChannel(args);
}

std::optional<ExecutedRun> LocalService::Executed(std::int64_t run_id) const {
  std::lock_guard<std::mutex> lock(executed_mu_);
  auto it = executed_.find(run_id);
  if (it == executed_.end()) return std::nullopt;
  return it->second;
}

// Claims and executes runs for one bench until the service stops (what runs::Worker::Start does, with each
// outcome's summary and trace kept for Executed()).
void LocalService::WorkerLoop(runs::Worker* worker) {
  std::unique_ptr<db::Store> store;
  while (!stop_.load()) {
    if (store == nullptr) {
      auto opened = db::OpenStore(store_path_);
      if (!opened.ok()) {
        spdlog::error("{}: {}", Where(), opened.status().message());
        registry_.WaitForWork(200);
        continue;
      }
      store = std::move(opened).value();
    }
    auto done = worker->ClaimAndExecute(store.get());
    if (!done.ok()) {
      spdlog::error("{}: bench {}: {}", Where(), worker->setup().name, done.status().message());
      registry_.WaitForWork(200);
      continue;
    }
    if (!done->has_value()) {
      registry_.WaitForWork(200);
      continue;
    }
    runs::Outcome& o = **done;
    std::lock_guard<std::mutex> lock(executed_mu_);
    executed_[o.run_id] = {std::move(o.summary), std::move(o.trace)};
  }
}

// Another process on the same store (benchctl watch, cancel) sees this process's runs only through the store:
// a cancel requested there stops the run here, and the run's progress is written there.
void LocalService::RelayLoop() {
  std::unique_ptr<db::Store> store;
  for (std::uint64_t tick = 0; !stop_.load(); ++tick) {
    std::this_thread::sleep_for(kRelayPeriod);
    if (store == nullptr) {
      auto opened = db::OpenStore(store_path_);
      if (!opened.ok()) continue;  // nobody else can watch then; the runs themselves are unaffected
      store = std::move(opened).value();
    }
    for (auto& w : workers_) {
      const std::int64_t id = w->current_run();
      if (id == 0) continue;
      if (auto c = store->CancelRequested(id); c.ok() && *c) registry_.Cancel(id);
      double progress = 0.0;
      if (tick % kProgressEveryRelays == 0 && registry_.Progress(id, &progress))
        (void)w->WithExecutingLease([&](const db::Lease& lease) { return store->SetProgress(lease, progress); });
    }
  }
}

}  // namespace vb::server
