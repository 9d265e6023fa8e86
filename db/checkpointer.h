// Background WAL checkpoints for one Store's connection.
//
// In WAL mode a commit appends pages to the WAL; a checkpoint later copies them into the database file and
// fsyncs both (synchronous=NORMAL). SQLite's automatic checkpoint runs inside the commit that crosses the
// threshold, so the committing thread (a worker storing a trace) pays for copying and flushing everything
// written before it: about 40 % of trace ingest time here. A Checkpointer takes that off the committing thread:
// a WAL hook on the Store's connection (which replaces the automatic checkpoint) wakes a thread with its own
// connection that runs PASSIVE checkpoints (they never block readers or writers). If the WAL outgrows a hard
// limit anyway (the disk cannot keep up, or long readers pin old frames), the committing thread waits for a
// checkpoint pass to finish: back-pressure, so the WAL stays bounded. docs/store.md has the measurements.
//
// Internal to db/. The Store owns one per connection to a file (none for in-memory databases).
#pragma once

#include <sqlite3.h>

#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

namespace vb::db {

class Checkpointer {
 public:
  struct Options {
    int request_every_pages = 1000;          // wake the thread each time the WAL grew by this many pages
    int wait_above_pages = 8000;             // the committing thread waits for a pass above this WAL size
    std::chrono::milliseconds max_wait{5000};  // ... for at most this long
  };

  // Opens a second connection to `path` and starts the thread; nullptr if either fails (the caller then keeps
  // SQLite's automatic checkpoints).
  static std::unique_ptr<Checkpointer> Start(const std::string& path, Options options);
  Checkpointer(const Checkpointer&) = delete;
  Checkpointer& operator=(const Checkpointer&) = delete;
  ~Checkpointer();  // stops and joins the thread, closes its connection (the caller Detach()ed first)

  // Installs the WAL hook on `db` (which turns off db's automatic checkpoints) / removes it. `db` must be
  // used by one thread at a time, as any Store connection is; Detach before closing it.
  void Attach(sqlite3* db);
  static void Detach(sqlite3* db);

  // Checkpoint passes finished so far (for tests).
  std::uint64_t passes() const;

 private:
  Checkpointer(sqlite3* db, Options options) : db_(db), options_(options) {}
  static int OnCommit(void* self, sqlite3* db, const char* name, int wal_pages);
  void Loop();
  std::uint64_t Request();               // returns the pass generation that will cover the request
  void WaitFor(std::uint64_t generation);

  sqlite3* db_;  // the thread's own connection
  const Options options_;
  int requested_at_pages_ = 0;  // WAL size at the last request; touched only by the committing thread

  mutable std::mutex mu_;
  std::condition_variable wake_;  // requested_ > completed_ or stop_
  std::condition_variable done_;  // completed_ advanced
  bool stop_ = false;
  std::uint64_t requested_ = 0;
  std::uint64_t completed_ = 0;
  std::uint64_t passes_ = 0;
  std::thread thread_;
};

}  // namespace vb::db
