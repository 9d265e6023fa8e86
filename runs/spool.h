// The host's local spool (issue 39; docs/lab.md, "The spool"): a run's trace chunks and its result go to a
// journal on the host's own disk first, and a separate uploader thread moves them to the store, in order,
// retrying while the store is unavailable. The control loop then waits on the local disk at most (through the
// trace stream's few blocks), never on the database.
//
//   - One journal per attempt (run id and fence), `run-<id>-f<fence>.journal` in the spool directory: a begin
//     record (the lease), the chunks in index order, the result (status, reason, metrics, progress).
//   - Every record is framed and checksummed: magic, type, payload length, the time it was written, CRC-32 of
//     the type, time and payload (Boost.CRC, the zlib polynomial). A torn or corrupt tail (a crash mid-write)
//     ends the journal there; a corrupt record the uploader meets fails the run with the reason ("recording:
//     spool ... checksum mismatch"), never silently.
//   - fsync policy: each record is fsync'ed before the stream's consumer returns (SpoolOptions::sync). A chunk
//     holds 16384 samples (0.33 s at 50 kHz, 0.8 s at 20 kHz) and the stream has 3 spare blocks, so an fsync of
//     a few ms never reaches the loop, and a power cut loses at most the record being written. A process crash
//     alone loses nothing written (the page cache survives it); the fsync is for the machine going down.
//   - Bounded: at most SpoolOptions::max_bytes of records not yet uploaded; past that, or when the disk refuses a
//     write (full, I/O error), the append fails, the trace stream stops and the run fails with the reason (the
//     bench in its safe state; Outcome::bench_fault: the host, not the run, is at fault). Uploaded chunks are
//     freed from the file at once (fallocate PUNCH_HOLE, best effort), the file removed when its result landed.
//   - Nothing twice, nothing lost: a chunk the store already holds for the attempt (AlreadyExists) and a Finish
//     that finds the run already in its state are success (db/store.h), so a record uploaded before a crash
//     and again after it is written once. A fenced (stale) refusal drops the journal: the run is another
//     attempt's.
//   - At start, before any worker claims, DrainLeftovers uploads every journal an earlier process left with a
//     result, drops the ones without (attempts interrupted mid-run: RecoverAfterCrash re-queues them), and
//     says when that process was last alive (the `alive` file the uploader rewrites every second and at Stop,
//     and the journals' last records), so `interrupted` carries the stop's time, not the restart's.
//
// SpoolEnv is the seam to the file system (after LevelDB's Env): the tests inject a full disk or an I/O error.
#pragma once

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "common/status.h"
#include "db/store.h"
#include "runs/monitor.h"
#include "runs/store_faults.h"

namespace vb::runs {

class SpoolFile {
 public:
  virtual ~SpoolFile() = default;
  virtual Status Append(std::string_view data) = 0;
  virtual Status Sync() = 0;
};

class SpoolEnv {
 public:
  virtual ~SpoolEnv() = default;
  virtual Status CreateDir(const std::string& dir) = 0;
  // The names (not paths) of the directory's entries.
  virtual StatusOr<std::vector<std::string>> ListDir(const std::string& dir) = 0;
  // A new file (it must not exist), for appending.
  virtual StatusOr<std::unique_ptr<SpoolFile>> NewFile(const std::string& path) = 0;
  // Exactly n bytes at offset into *out; OutOfRange when the file is shorter.
  virtual Status ReadAt(const std::string& path, std::uint64_t offset, std::size_t n, std::string* out) = 0;
  virtual Status Remove(const std::string& path) = 0;
  virtual Status SyncDir(const std::string& dir) = 0;
  // Gives [0, length) of the file back to the file system (best effort: a file system that cannot just keeps it).
  virtual void FreePrefix(const std::string& path, std::uint64_t length) = 0;
  // A small file replaced atomically (written beside, then renamed over).
  virtual Status WriteSmallFile(const std::string& path, std::string_view contents) = 0;
  virtual StatusOr<std::string> ReadSmallFile(const std::string& path) = 0;

  static SpoolEnv* Default();  // POSIX
};

// A run's final state as the uploader writes it: SetProgress(progress) first when progress >= 0, then Finish.
struct SpooledResult {
  db::RunStatus status = db::RunStatus::kFailed;
  std::string reason;
  std::vector<db::Metric> metrics;
  double progress = -1.0;
  std::optional<db::ExecutionRecord> execution;  // written by the same Finish (journals before it have none)
};

struct SpoolOptions {
  std::string dir;
  std::uint64_t max_bytes = std::uint64_t{1} << 30;  // records not yet uploaded, all journals together
  bool sync = true;                                  // fsync every record (see above)
  SpoolEnv* env = nullptr;                           // nullptr: SpoolEnv::Default()
  double max_wait_s = 1.0;                           // the uploader's longest backoff while the store fails
};

class Spool;

// One attempt's journal. AppendChunk on the trace stream's thread; the rest on the worker's.
class Journal {
 public:
  enum class State { kUploading, kLanded, kFenced, kStopped };

  // Appends and (per the policy) fsyncs one chunk. An error (spool full, the disk refused) is final for the
  // journal: later appends fail the same way. The chunks written before it are still uploaded.
  Status AppendChunk(const db::TraceChunk& chunk);
  // The result: queued for the uploader after every chunk, and appended to the file so it survives a crash.
  // The returned status is the file's; whatever it says, the result is uploaded from memory while the process
  // lives.
  Status AppendResult(const SpooledResult& result);
  // Waits until the result landed or was refused as stale, up to timeout_s or `stop`; the state then.
  State WaitForResult(double timeout_s, const std::atomic<bool>* stop);
  // The result as the store took it (the uploader turns a refused trace or result into a failure with the
  // reason), once kLanded.
  SpooledResult landed() const;
  Status fenced_status() const;
  // Stops uploading it and removes the file (a run stopped by the shutdown, or whose spool failed: its result
  // goes to the store directly).
  void Abandon();
  const db::Lease& lease() const { return lease_; }
  std::int64_t chunks_written() const;

 private:
  friend class Spool;
  struct Entry {
    std::uint64_t offset = 0;
    std::uint32_t size = 0;  // the whole record, header included
  };
  Journal(Spool* spool, db::Lease lease, std::string path, std::unique_ptr<SpoolFile> file);

  Spool* spool_;
  const db::Lease lease_;
  const std::string path_;
  std::unique_ptr<SpoolFile> file_;  // appends: the stream's or worker's thread
  std::string buf_;
  std::uint64_t size_ = 0;
  Status broken_;  // the first append error

  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::deque<Entry> chunks_;            // written, not yet uploaded
  std::optional<SpooledResult> result_; // queued, not yet landed
  SpooledResult landed_;
  Status fenced_;
  Status refused_;                      // a chunk the store refused for good: the result becomes a failure
  State state_ = State::kUploading;
  bool abandoned_ = false;
  bool busy_ = false;                   // the uploader is writing one of its records now
  std::int64_t written_ = 0;
  std::uint64_t uploaded_bytes_ = 0;
};

using StoreOpener = std::function<StatusOr<std::unique_ptr<db::Store>>()>;

class Spool {
 public:
  // open_store gives the uploader its own connection (it is opened again after it fails).
  Spool(SpoolOptions options, StoreOpener open_store);
  ~Spool();
  Spool(const Spool&) = delete;
  Spool& operator=(const Spool&) = delete;

  // Creates the directory (and checks it can be written).
  Status Open();

  struct Leftovers {
    int results_landed = 0;    // journals whose result the store now has
    int stale = 0;             // journals the store refused as stale (the run is another attempt's)
    int dropped = 0;           // journals without a result (interrupted mid-run): removed
    double stopped_unix_s = 0; // when the earlier process was last alive (0: unknown)
  };
  // On the calling thread, before the uploader starts and before any claim: see the file's comment. A journal
  // whose upload still fails transiently when `retry` gives up stays, and the error is returned.
  StatusOr<Leftovers> DrainLeftovers(db::Store* store, const RetryPolicy& retry, FaultLog* faults);

  void Start();
  // Stops the uploader and writes the stop time; what is not uploaded stays on disk for the next start.
  void Stop();

  StatusOr<std::shared_ptr<Journal>> Begin(const db::Lease& lease);
  // Before Start(): where the runs whose result waits here are shown (Registry::SetResultWaiting).
  void set_registry(Registry* registry) { registry_ = registry; }

  // The attempts whose records are not all in the store yet (their hosts renew their leases: a run being
  // uploaded is not abandoned; docs/lab.md).
  std::vector<db::Lease> Uploading() const;
  std::uint64_t pending_bytes() const { return pending_bytes_.load(); }
  const std::string& dir() const { return options_.dir; }

 private:
  friend class Journal;
  void Loop();
  // One upload step for one journal; false when it has nothing to do right now.
  bool Step(db::Store* store, const std::shared_ptr<Journal>& j, Status* transient);
  void Notify();
  // Drops the journal from the uploader's list and removes its file.
  void Forget(Journal* j);
  void WriteAlive();

  SpoolOptions options_;
  SpoolEnv* env_;
  StoreOpener open_store_;
  Registry* registry_ = nullptr;
  std::atomic<std::uint64_t> pending_bytes_{0};
  mutable std::mutex mu_;
  std::condition_variable cv_;
  std::vector<std::shared_ptr<Journal>> journals_;
  std::uint64_t work_ = 0;  // bumped for every new record
  bool stop_ = false;
  std::atomic<bool> stop_flag_{false};
  std::thread thread_;
  FaultLog faults_{"spool uploader"};
};

// The record format, for tests and the drain.
namespace spool_format {
enum class RecordType : std::uint8_t { kBegin = 1, kChunk = 2, kResult = 3 };
inline constexpr std::uint32_t kMagic = 0x4A535256;  // "VRSJ" little-endian
inline constexpr std::size_t kHeaderBytes = 4 + 1 + 4 + 8 + 4;
std::uint32_t Crc32(std::string_view data);
}  // namespace spool_format

}  // namespace vb::runs
