#include "runs/spool.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include <boost/crc.hpp>
#include <spdlog/spdlog.h>

#include "db/text.h"

namespace vb::runs {

using db::Cat;

namespace spool_format {
std::uint32_t Crc32(std::string_view data) {
  boost::crc_32_type crc;  // the zlib / IEEE 802.3 polynomial
  crc.process_bytes(data.data(), data.size());
  return crc.checksum();
}
}  // namespace spool_format

namespace {

using spool_format::RecordType;

double NowUnixS() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

std::string Errno(const std::string& what, const std::string& path) {
  return Cat(what, " ", path, ": ", std::strerror(errno));
}

// ---- POSIX ----

class PosixFile final : public SpoolFile {
 public:
  PosixFile(int fd, std::string path) : fd_(fd), path_(std::move(path)) {}
  ~PosixFile() override { ::close(fd_); }
  Status Append(std::string_view data) override {
    while (!data.empty()) {
      const ssize_t n = ::write(fd_, data.data(), data.size());
      if (n < 0) {
        if (errno == EINTR) continue;
        return Status::ResourceExhausted(Errno("cannot write", path_));
      }
      data.remove_prefix(static_cast<std::size_t>(n));
    }
    return Status::Ok();
  }
  Status Sync() override {
    if (::fdatasync(fd_) != 0) return Status::ResourceExhausted(Errno("cannot fsync", path_));
    return Status::Ok();
  }

 private:
  int fd_;
  std::string path_;
};

class PosixEnv final : public SpoolEnv {
 public:
  Status CreateDir(const std::string& dir) override {
    std::error_code ec;
    std::filesystem::create_directories(dir, ec);
    if (ec) return Status::FailedPrecondition(Cat("cannot create the spool directory ", dir, ": ", ec.message()));
    return Status::Ok();
  }
  StatusOr<std::vector<std::string>> ListDir(const std::string& dir) override {
    std::vector<std::string> names;
    std::error_code ec;
    for (const auto& e : std::filesystem::directory_iterator(dir, ec)) names.push_back(e.path().filename().string());
    if (ec) return Status::FailedPrecondition(Cat("cannot list the spool directory ", dir, ": ", ec.message()));
    std::sort(names.begin(), names.end());
    return names;
  }
  StatusOr<std::unique_ptr<SpoolFile>> NewFile(const std::string& path) override {
    const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_APPEND | O_CLOEXEC, 0640);
    if (fd < 0) return Status::ResourceExhausted(Errno("cannot create", path));
    return std::unique_ptr<SpoolFile>(new PosixFile(fd, path));
  }
  Status ReadAt(const std::string& path, std::uint64_t offset, std::size_t n, std::string* out) override {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) return Status::NotFound(Errno("cannot open", path));
    out->resize(n);
    std::size_t got = 0;
    while (got < n) {
      const ssize_t r = ::pread(fd, out->data() + got, n - got, static_cast<off_t>(offset + got));
      if (r < 0 && errno == EINTR) continue;
      if (r < 0) {
        Status st = Status::DataLoss(Errno("cannot read", path));
        ::close(fd);
        return st;
      }
      if (r == 0) break;
      got += static_cast<std::size_t>(r);
    }
    ::close(fd);
    if (got < n) return Status::OutOfRange(Cat(path, ": ends at ", offset + got));
    return Status::Ok();
  }
  Status Remove(const std::string& path) override {
    if (::unlink(path.c_str()) != 0 && errno != ENOENT) return Status::Internal(Errno("cannot remove", path));
    return Status::Ok();
  }
  Status SyncDir(const std::string& dir) override {
    const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
    if (fd < 0) return Status::ResourceExhausted(Errno("cannot open", dir));
    const int r = ::fsync(fd);
    Status st = r == 0 ? Status::Ok() : Status::ResourceExhausted(Errno("cannot fsync", dir));
    ::close(fd);
    return st;
  }
  void FreePrefix(const std::string& path, std::uint64_t length) override {
    length -= length % 4096;
    if (length == 0) return;
    const int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
    if (fd < 0) return;
    (void)::fallocate(fd, FALLOC_FL_PUNCH_HOLE | FALLOC_FL_KEEP_SIZE, 0, static_cast<off_t>(length));
    ::close(fd);
  }
  Status WriteSmallFile(const std::string& path, std::string_view contents) override {
    const std::string tmp = path + ".tmp";
    const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0640);
    if (fd < 0) return Status::ResourceExhausted(Errno("cannot create", tmp));
    const ssize_t n = ::write(fd, contents.data(), contents.size());
    ::close(fd);
    if (n != static_cast<ssize_t>(contents.size())) return Status::ResourceExhausted(Errno("cannot write", tmp));
    if (::rename(tmp.c_str(), path.c_str()) != 0) return Status::ResourceExhausted(Errno("cannot rename", tmp));
    return Status::Ok();
  }
  StatusOr<std::string> ReadSmallFile(const std::string& path) override {
    std::FILE* f = std::fopen(path.c_str(), "rb");
    if (f == nullptr) return Status::NotFound(Errno("cannot open", path));
    std::string s(256, '\0');
    s.resize(std::fread(s.data(), 1, s.size(), f));
    std::fclose(f);
    return s;
  }
};

// ---- Records ----

template <typename T>
void Put(std::string* out, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  out->append(b, sizeof(T));
}
void PutString(std::string* out, const std::string& s) {
  Put<std::uint32_t>(out, static_cast<std::uint32_t>(s.size()));
  out->append(s);
}

class Reader {
 public:
  explicit Reader(std::string_view in) : in_(in) {}
  template <typename T>
  bool Get(T* v) {
    if (in_.size() < sizeof(T)) return false;
    std::memcpy(v, in_.data(), sizeof(T));
    in_.remove_prefix(sizeof(T));
    return true;
  }
  bool GetString(std::string* s) {
    std::uint32_t n = 0;
    if (!Get(&n) || in_.size() < n) return false;
    s->assign(in_.data(), n);
    in_.remove_prefix(n);
    return true;
  }
  std::string_view rest() const { return in_; }
  void Skip(std::size_t n) { in_.remove_prefix(n); }

 private:
  std::string_view in_;
};

// A whole record (header and payload) from its payload: header = magic u32, type u8, payload length u32, written
// at (unix s) f64, CRC-32 u32 of type, length, time and payload.
void Frame(RecordType type, const std::string& payload, std::string* out) {
  out->clear();
  out->reserve(spool_format::kHeaderBytes + payload.size());
  Put<std::uint32_t>(out, spool_format::kMagic);
  Put<std::uint8_t>(out, static_cast<std::uint8_t>(type));
  Put<std::uint32_t>(out, static_cast<std::uint32_t>(payload.size()));
  Put<double>(out, NowUnixS());
  boost::crc_32_type crc;
  crc.process_bytes(out->data() + 4, out->size() - 4);
  crc.process_bytes(payload.data(), payload.size());
  Put<std::uint32_t>(out, crc.checksum());
  out->append(payload);
}

struct Header {
  RecordType type{};
  std::uint32_t length = 0;
  double at_unix_s = 0.0;
  std::uint32_t crc = 0;
};

bool ParseHeader(std::string_view h, Header* out) {
  Reader r(h);
  std::uint32_t magic = 0;
  std::uint8_t type = 0;
  if (!r.Get(&magic) || magic != spool_format::kMagic || !r.Get(&type) || !r.Get(&out->length) ||
      !r.Get(&out->at_unix_s) || !r.Get(&out->crc))
    return false;
  if (type < 1 || type > 3) return false;
  out->type = static_cast<RecordType>(type);
  return true;
}

bool CrcMatches(std::string_view record, const Header& h) {
  boost::crc_32_type crc;
  crc.process_bytes(record.data() + 4, 1 + 4 + 8);
  crc.process_bytes(record.data() + spool_format::kHeaderBytes, record.size() - spool_format::kHeaderBytes);
  return crc.checksum() == h.crc;
}

std::string ChunkPayload(const db::TraceChunk& c) {
  std::string p;
  p.reserve(64 + c.data.size() * sizeof(double));
  Put<std::int32_t>(&p, c.index);
  Put<double>(&p, c.t0_s);
  Put<double>(&p, c.sample_period_s);
  Put<std::int32_t>(&p, c.samples);
  Put<std::uint32_t>(&p, static_cast<std::uint32_t>(c.channels.size()));
  for (const auto& ch : c.channels) PutString(&p, ch);
  p.append(reinterpret_cast<const char*>(c.data.data()), c.data.size() * sizeof(double));
  return p;
}

bool DecodeChunk(std::string_view payload, db::TraceChunk* c) {
  Reader r(payload);
  std::uint32_t channels = 0;
  if (!r.Get(&c->index) || !r.Get(&c->t0_s) || !r.Get(&c->sample_period_s) || !r.Get(&c->samples) ||
      !r.Get(&channels) || c->samples < 0 || channels > 1024)
    return false;
  c->channels.resize(channels);
  for (auto& ch : c->channels)
    if (!r.GetString(&ch)) return false;
  const std::size_t n = static_cast<std::size_t>(channels) * static_cast<std::size_t>(c->samples);
  if (r.rest().size() != n * sizeof(double)) return false;
  c->data.resize(n);
  std::memcpy(c->data.data(), r.rest().data(), n * sizeof(double));
  return true;
}

std::string ResultPayload(const SpooledResult& res) {
  std::string p;
  Put<std::uint8_t>(&p, static_cast<std::uint8_t>(res.status));
  Put<double>(&p, res.progress);
  PutString(&p, res.reason);
  Put<std::uint32_t>(&p, static_cast<std::uint32_t>(res.metrics.size()));
  for (const auto& m : res.metrics) {
    PutString(&p, m.name);
    Put<double>(&p, m.value);
  }
  // The execution record after the metrics: a journal written before it ends at the metrics and still reads.
  if (res.execution) {
    const db::ExecutionRecord& e = *res.execution;
    Put<std::uint8_t>(&p, e.loop ? 2 : 1);
    Put<double>(&p, e.wall_s);
    Put<double>(&p, e.simulated_s);
    Put<std::int64_t>(&p, e.samples);
    Put<std::int64_t>(&p, e.control_ticks);
    Put<std::uint8_t>(&p, e.metrics_from_trajectory ? 1 : 0);
    if (e.loop) {
      Put<std::int64_t>(&p, e.loop->ticks);
      Put<std::int64_t>(&p, e.loop->overruns);
      Put<double>(&p, e.loop->jitter_p50_s);
      Put<double>(&p, e.loop->jitter_p99_s);
      Put<double>(&p, e.loop->jitter_max_s);
    }
    // The build after the loop (schema v7): a journal written before ends at the loop and still reads.
    if (!e.build.empty()) PutString(&p, e.build);
  }
  return p;
}

bool DecodeResult(std::string_view payload, SpooledResult* res) {
  Reader r(payload);
  std::uint8_t status = 0;
  std::uint32_t n = 0;
  if (!r.Get(&status) || !r.Get(&res->progress) || !r.GetString(&res->reason) || !r.Get(&n)) return false;
  res->status = static_cast<db::RunStatus>(status);
  res->metrics.resize(n);
  for (auto& m : res->metrics)
    if (!r.GetString(&m.name) || !r.Get(&m.value)) return false;
  res->execution.reset();
  if (r.rest().empty()) return true;  // no execution record (or a journal written before there was one)
  std::uint8_t kind = 0, from_trajectory = 0;
  db::ExecutionRecord e;
  if (!r.Get(&kind) || (kind != 1 && kind != 2) || !r.Get(&e.wall_s) || !r.Get(&e.simulated_s) ||
      !r.Get(&e.samples) || !r.Get(&e.control_ticks) || !r.Get(&from_trajectory))
    return false;
  e.metrics_from_trajectory = from_trajectory != 0;
  if (kind == 2) {
    db::LoopRecord l;
    if (!r.Get(&l.ticks) || !r.Get(&l.overruns) || !r.Get(&l.jitter_p50_s) || !r.Get(&l.jitter_p99_s) ||
        !r.Get(&l.jitter_max_s))
      return false;
    e.loop = l;
  }
  if (!r.rest().empty() && !r.GetString(&e.build)) return false;
  res->execution = e;
  return r.rest().empty();
}

// Reads one chunk record back and checks it: DataLoss naming the file and offset when it does not check out.
Status ReadChunk(SpoolEnv* env, const std::string& path, std::uint64_t offset, std::uint32_t size,
                 db::TraceChunk* chunk) {
  std::string rec;
  VB_RETURN_IF_ERROR(env->ReadAt(path, offset, size, &rec).WithContext("spool"));
  Header h;
  if (!ParseHeader(rec, &h) || h.type != RecordType::kChunk || h.length + spool_format::kHeaderBytes != size ||
      !CrcMatches(rec, h) || !DecodeChunk(std::string_view(rec).substr(spool_format::kHeaderBytes), chunk))
    return Status::DataLoss(Cat("spool ", path, ": the record at byte ", offset,
                                " does not check out (checksum mismatch): the disk corrupted it"));
  return Status::Ok();
}

// How the uploader takes a store's answer: as db::ClassifyWrite, but a full database disk (ResourceExhausted,
// SQLITE_FULL) is waited out like an unavailable store: the records stay in the spool until it has room again,
// rather than failing the run for the database's disk.
db::WriteFault UploadFault(const Status& st) {
  if (st.code() == StatusCode::kResourceExhausted) return db::WriteFault::kTransient;
  return db::ClassifyWrite(st);
}

// The store's answer to a chunk: AlreadyExists for this attempt means an earlier try (before a crash, or whose
// answer was lost) committed it.
Status UploadChunk(db::Store* store, const db::Lease& lease, const db::TraceChunk& chunk) {
  Status st = store->AppendTraceChunk(lease, chunk);
  if (st.code() == StatusCode::kAlreadyExists) return Status::Ok();
  return st;
}

// The result: progress (a warning if refused for good), then Finish; a Finish refused for good (bad data) is
// written again as a failure with the reason. `refused`: a chunk the store refused for good, which fails the run.
Status UploadResult(db::Store* store, const db::Lease& lease, SpooledResult* res, const Status& refused) {
  if (!refused.ok()) {
    res->status = db::RunStatus::kFailed;
    res->reason = "recording: " + refused.message();
    res->metrics.clear();
  }
  if (res->progress >= 0) {
    Status st = store->SetProgress(lease, res->progress);
    const auto fault = UploadFault(st);
    if (fault == db::WriteFault::kTransient || fault == db::WriteFault::kFenced) return st;
    if (!st.ok()) spdlog::warn("run {}: cannot record its progress: {}", lease.run_id, st.message());
  }
  Status st = store->Finish(lease, res->status, res->reason, res->metrics, res->execution);
  if (UploadFault(st) == db::WriteFault::kPermanent) {
    spdlog::error("run {}: cannot record the result: {}", lease.run_id, st.message());
    res->status = db::RunStatus::kFailed;
    res->reason = "cannot record the result: " + st.message();
    res->metrics.clear();
    res->execution.reset();  // it may be what the store refused
    st = store->Finish(lease, res->status, res->reason, {});
  }
  return st;
}

struct Parsed {
  bool has_begin = false;
  db::Lease lease;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> chunks;  // offset, size
  std::optional<SpooledResult> result;
  double last_at_unix_s = 0.0;
  std::uint64_t end = 0;  // where the good records end
};

// Reads a journal's records up to the first that is torn or does not check out (a crash mid-write).
Parsed ParseJournal(SpoolEnv* env, const std::string& path) {
  Parsed p;
  std::uint64_t off = 0;
  std::string head, rec;
  while (true) {
    if (!env->ReadAt(path, off, spool_format::kHeaderBytes, &head).ok()) break;
    Header h;
    if (!ParseHeader(head, &h)) break;
    const std::uint64_t size = spool_format::kHeaderBytes + std::uint64_t{h.length};
    if (!env->ReadAt(path, off, size, &rec).ok() || !CrcMatches(rec, h)) break;
    const std::string_view payload = std::string_view(rec).substr(spool_format::kHeaderBytes);
    if (h.type == RecordType::kBegin) {
      Reader r(payload);
      if (!r.Get(&p.lease.run_id) || !r.Get(&p.lease.fence)) break;
      p.has_begin = true;
    } else if (h.type == RecordType::kChunk) {
      p.chunks.emplace_back(off, static_cast<std::uint32_t>(size));
    } else {
      SpooledResult res;
      if (!DecodeResult(payload, &res)) break;
      p.result = std::move(res);
    }
    p.last_at_unix_s = std::max(p.last_at_unix_s, h.at_unix_s);
    off += size;
    p.end = off;
  }
  return p;
}

bool EndsWith(const std::string& s, std::string_view tail) {
  return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
}

}  // namespace

SpoolEnv* SpoolEnv::Default() {
  static PosixEnv env;
  return &env;
}

// ---- Journal ----

Journal::Journal(Spool* spool, db::Lease lease, std::string path, std::unique_ptr<SpoolFile> file)
    : spool_(spool), lease_(lease), path_(std::move(path)), file_(std::move(file)) {}

Status Journal::AppendChunk(const db::TraceChunk& chunk) {
  if (!broken_.ok()) return broken_;
  Frame(RecordType::kChunk, ChunkPayload(chunk), &buf_);
  const std::uint64_t pending = spool_->pending_bytes_.load();
  if (pending + buf_.size() > spool_->options_.max_bytes) {
    broken_ = Status::ResourceExhausted(Cat("spool ", spool_->options_.dir, " is full: ", pending,
                                            " bytes not yet uploaded, the bound (max_bytes) is ",
                                            spool_->options_.max_bytes));
    return broken_;
  }
  Status st = file_->Append(buf_);
  if (st.ok() && spool_->options_.sync) st = file_->Sync();
  if (!st.ok()) {
    broken_ = Status::ResourceExhausted(Cat("spool: ", st.message()));
    return broken_;
  }
  spool_->pending_bytes_ += buf_.size();
  {
    std::lock_guard<std::mutex> lock(mu_);
    chunks_.push_back({size_, static_cast<std::uint32_t>(buf_.size())});
    ++written_;
  }
  size_ += buf_.size();
  spool_->Notify();
  return Status::Ok();
}

Status Journal::AppendResult(const SpooledResult& result) {
  Status st = broken_;
  if (st.ok()) {
    Frame(RecordType::kResult, ResultPayload(result), &buf_);
    st = file_->Append(buf_);
    if (st.ok() && spool_->options_.sync) st = file_->Sync();
    if (st.ok()) size_ += buf_.size();
    else broken_ = st;
  }
  // Marked before the uploader can see the result, so its landing always clears the mark.
  if (spool_->registry_ != nullptr) spool_->registry_->SetResultWaiting(lease_.run_id, NowUnixS());
  {
    std::lock_guard<std::mutex> lock(mu_);
    result_ = result;
  }
  spool_->Notify();
  return st;
}

Journal::State Journal::WaitForResult(double timeout_s, const std::atomic<bool>* stop) {
  const auto until = std::chrono::steady_clock::now() +
                     std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                         std::chrono::duration<double>(std::max(0.0, timeout_s)));
  std::unique_lock<std::mutex> lock(mu_);
  while (state_ == State::kUploading) {
    if (stop != nullptr && stop->load()) return State::kStopped;
    if (std::chrono::steady_clock::now() >= until) break;
    cv_.wait_for(lock, std::chrono::milliseconds(20));
  }
  return state_;
}

SpooledResult Journal::landed() const {
  std::lock_guard<std::mutex> lock(mu_);
  return landed_;
}

Status Journal::fenced_status() const {
  std::lock_guard<std::mutex> lock(mu_);
  return fenced_;
}

std::int64_t Journal::chunks_written() const {
  std::lock_guard<std::mutex> lock(mu_);
  return written_;
}

void Journal::Abandon() {
  {
    std::unique_lock<std::mutex> lock(mu_);
    abandoned_ = true;
    cv_.wait(lock, [&] { return !busy_; });
    for (const Entry& e : chunks_) spool_->pending_bytes_ -= e.size;
    chunks_.clear();
    result_.reset();
  }
  spool_->Forget(this);
}

// ---- Spool ----

Spool::Spool(SpoolOptions options, StoreOpener open_store)
    : options_(std::move(options)),
      env_(options_.env != nullptr ? options_.env : SpoolEnv::Default()),
      open_store_(std::move(open_store)) {}

Spool::~Spool() { Stop(); }

Status Spool::Open() {
  if (options_.dir.empty()) return Status::InvalidArgument("spool_dir: empty");
  VB_RETURN_IF_ERROR(env_->CreateDir(options_.dir));
  // Writable? (A read-only or full disk is said at start, not at the first run.)
  VB_RETURN_IF_ERROR(env_->WriteSmallFile(options_.dir + "/probe", "ok\n").WithContext("spool_dir"));
  return env_->Remove(options_.dir + "/probe");
}

void Spool::Notify() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    ++work_;
  }
  cv_.notify_all();
}

StatusOr<std::shared_ptr<Journal>> Spool::Begin(const db::Lease& lease) {
  const std::string path = Cat(options_.dir, "/run-", lease.run_id, "-f", lease.fence, ".journal");
  (void)env_->Remove(path);  // an earlier process's journal of this very attempt was drained or dropped at start
  auto file = env_->NewFile(path);
  if (!file.ok()) return Status::ResourceExhausted(Cat("spool: ", file.status().message()));
  std::string payload, rec;
  Put<std::int64_t>(&payload, lease.run_id);
  Put<std::int64_t>(&payload, lease.fence);
  Frame(RecordType::kBegin, payload, &rec);
  Status st = (*file)->Append(rec);
  if (st.ok() && options_.sync) st = (*file)->Sync();
  if (st.ok() && options_.sync) st = env_->SyncDir(options_.dir);
  if (!st.ok()) {
    (void)env_->Remove(path);
    return Status::ResourceExhausted(Cat("spool: ", st.message()));
  }
  std::shared_ptr<Journal> j(new Journal(this, lease, path, std::move(*file)));
  j->size_ = rec.size();
  {
    std::lock_guard<std::mutex> lock(mu_);
    journals_.push_back(j);
  }
  return j;
}

void Spool::Forget(Journal* j) {
  if (registry_ != nullptr) registry_->ClearResultWaiting(j->lease_.run_id);
  {
    std::lock_guard<std::mutex> lock(mu_);
    journals_.erase(std::remove_if(journals_.begin(), journals_.end(),
                                   [&](const std::shared_ptr<Journal>& x) { return x.get() == j; }),
                    journals_.end());
  }
  (void)env_->Remove(j->path_);
}

std::vector<db::Lease> Spool::Uploading() const {
  std::vector<db::Lease> out;
  std::lock_guard<std::mutex> lock(mu_);
  for (const auto& j : journals_) {
    std::lock_guard<std::mutex> jl(j->mu_);
    if (j->state_ == Journal::State::kUploading && !j->abandoned_) out.push_back(j->lease_);
  }
  return out;
}

bool Spool::Step(db::Store* store, const std::shared_ptr<Journal>& j, Status* transient) {
  Journal::Entry e;
  bool is_chunk = false;
  SpooledResult res;
  Status refused;
  {
    std::lock_guard<std::mutex> lock(j->mu_);
    if (j->abandoned_ || j->state_ != Journal::State::kUploading) return false;
    if (!j->chunks_.empty()) {
      e = j->chunks_.front();
      is_chunk = true;
    } else if (j->result_.has_value()) {
      res = *j->result_;
    } else {
      return false;
    }
    refused = j->refused_;
    j->busy_ = true;
  }
  Status st;
  if (is_chunk) {
    db::TraceChunk chunk;
    st = ReadChunk(env_, j->path_, e.offset, e.size, &chunk);
    if (st.ok()) st = UploadChunk(store, j->lease_, chunk);
  } else {
    st = UploadResult(store, j->lease_, &res, refused);
  }
  const db::WriteFault fault = UploadFault(st);
  bool retire = false;
  {
    std::lock_guard<std::mutex> lock(j->mu_);
    j->busy_ = false;
    switch (fault) {
      case db::WriteFault::kTransient:
        *transient = st;
        break;
      case db::WriteFault::kNone:
        if (is_chunk) {
          j->chunks_.pop_front();
          pending_bytes_ -= e.size;
          j->uploaded_bytes_ = e.offset + e.size;
        } else {
          j->landed_ = res;
          j->state_ = Journal::State::kLanded;
          j->result_.reset();
          retire = true;
        }
        break;
      case db::WriteFault::kFenced:
        spdlog::warn("run {} (fence {}): the spool stops uploading it, the run is no longer this attempt's: {}",
                     j->lease_.run_id, j->lease_.fence, st.message());
        j->fenced_ = st;
        j->state_ = Journal::State::kFenced;
        for (const Journal::Entry& x : j->chunks_) pending_bytes_ -= x.size;
        j->chunks_.clear();
        retire = true;
        break;
      case db::WriteFault::kPermanent:
        // Only a chunk gets here (UploadResult turns a refused result into a failure): the trace cannot be
        // stored, so the run fails with the reason once its result comes.
        spdlog::error("run {}: trace chunk refused: {}", j->lease_.run_id, st.message());
        j->refused_ = st;
        for (const Journal::Entry& x : j->chunks_) pending_bytes_ -= x.size;
        j->chunks_.clear();
        if (!is_chunk) {  // a Finish refused twice for good (a bug): nothing more to try, said in the log
          spdlog::error("run {} (fence {}): its result cannot be written ({}); the spool drops it",
                        j->lease_.run_id, j->lease_.fence, st.message());
          j->landed_ = res;
          j->state_ = Journal::State::kLanded;
          retire = true;
        }
        break;
    }
  }
  j->cv_.notify_all();
  if (fault == db::WriteFault::kNone && is_chunk) env_->FreePrefix(j->path_, j->uploaded_bytes_);
  if (retire) Forget(j.get());
  return fault != db::WriteFault::kTransient;
}

void Spool::WriteAlive() {
  char text[64];
  std::snprintf(text, sizeof text, "%.3f\n", NowUnixS());
  (void)env_->WriteSmallFile(options_.dir + "/alive", text);
}

void Spool::Start() {
  WriteAlive();
  thread_ = std::thread([this] { Loop(); });
}

void Spool::Stop() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    if (stop_) return;
    stop_ = true;
  }
  cv_.notify_all();
  if (thread_.joinable()) {
    thread_.join();
    WriteAlive();
  }
}

void Spool::Loop() {
  std::unique_ptr<db::Store> store;
  double wait_s = 0.05;
  auto last_alive = std::chrono::steady_clock::now();
  std::uint64_t seen = 0;
  while (true) {
    std::vector<std::shared_ptr<Journal>> snapshot;
    {
      std::lock_guard<std::mutex> lock(mu_);
      if (stop_) break;
      seen = work_;
      snapshot = journals_;
    }
    if (std::chrono::steady_clock::now() - last_alive >= std::chrono::seconds(1)) {
      WriteAlive();
      last_alive = std::chrono::steady_clock::now();
    }
    Status transient;
    bool did = false;
    if (!snapshot.empty() && store == nullptr) {
      const auto began = FaultLog::Clock::now();
      auto opened = open_store_();
      if (opened.ok()) {
        store = std::move(*opened);
      } else {
        faults_.Failed(opened.status(), began);
        transient = opened.status();
      }
    }
    if (store != nullptr) {
      for (const auto& j : snapshot) {
        const auto began = FaultLog::Clock::now();
        // Each journal's records in order, one at a time across journals so no bench's upload waits for another's.
        if (Step(store.get(), j, &transient)) did = true;
        if (!transient.ok()) {
          faults_.Failed(transient, began);
          break;
        }
      }
    }
    std::unique_lock<std::mutex> lock(mu_);
    if (!transient.ok()) {
      cv_.wait_for(lock, std::chrono::duration<double>(wait_s), [&] { return stop_; });
      wait_s = std::min(options_.max_wait_s, wait_s * 2);
      continue;
    }
    wait_s = 0.05;
    if (did) {
      faults_.Recovered();
      continue;
    }
    cv_.wait_for(lock, std::chrono::seconds(1), [&] { return stop_ || work_ != seen; });
  }
}

StatusOr<Spool::Leftovers> Spool::DrainLeftovers(db::Store* store, const RetryPolicy& retry, FaultLog* faults) {
  Leftovers out;
  if (auto alive = env_->ReadSmallFile(options_.dir + "/alive"); alive.ok())
    out.stopped_unix_s = std::strtod(alive->c_str(), nullptr);
  auto names = env_->ListDir(options_.dir);
  if (!names.ok()) return names.status();
  for (const std::string& name : *names) {
    if (!EndsWith(name, ".journal")) continue;
    const std::string path = options_.dir + "/" + name;
    Parsed p = ParseJournal(env_, path);
    out.stopped_unix_s = std::max(out.stopped_unix_s, p.last_at_unix_s);
    if (!p.has_begin || !p.result.has_value()) {
      // Interrupted mid-run (or torn before its first record): RecoverAfterCrash re-queues the run, whose next
      // attempt writes its own trace from chunk 0.
      spdlog::info("spool: {} holds no result (the attempt was interrupted): dropped", name);
      ++out.dropped;
      VB_RETURN_IF_ERROR(env_->Remove(path));
      continue;
    }
    Status refused;
    Status st;
    for (const auto& [offset, size] : p.chunks) {
      db::TraceChunk chunk;
      st = ReadChunk(env_, path, offset, size, &chunk);
      if (st.ok()) st = RetryWrite([&] { return UploadChunk(store, p.lease, chunk); }, retry, faults);
      if (UploadFault(st) == db::WriteFault::kPermanent) {
        refused = st;
        st = Status::Ok();
        break;
      }
      if (!st.ok()) break;
    }
    if (st.ok()) {
      SpooledResult res = *p.result;
      st = RetryWrite([&] { return UploadResult(store, p.lease, &res, refused); }, retry, faults);
    }
    switch (UploadFault(st)) {
      case db::WriteFault::kTransient:
        return Status::Unavailable(Cat("spool: ", name, " not uploaded (its run's result waits in the spool): ",
                                       st.message()));
      case db::WriteFault::kFenced:
        spdlog::warn("spool: {}: the run is no longer this attempt's ({}): dropped", name, st.message());
        ++out.stale;
        break;
      default:
        spdlog::info("spool: {}: {} chunk(s) and the result of run {} uploaded", name, p.chunks.size(),
                     p.lease.run_id);
        ++out.results_landed;
        break;
    }
    VB_RETURN_IF_ERROR(env_->Remove(path));
  }
  return out;
}

}  // namespace vb::runs
