#include "db/checkpointer.h"

#include <system_error>

namespace vb::db {

std::unique_ptr<Checkpointer> Checkpointer::Start(const std::string& path, Options options) {
  if (path.empty()) return nullptr;  // in-memory and temporary databases have no WAL
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_NOMUTEX, nullptr) != SQLITE_OK) {
    sqlite3_close_v2(db);
    return nullptr;
  }
  sqlite3_busy_timeout(db, 5000);
  // A checkpoint fsyncs the WAL before and the database after copying (as under the writer's own NORMAL).
  sqlite3_exec(db, "PRAGMA synchronous = NORMAL", nullptr, nullptr, nullptr);
  std::unique_ptr<Checkpointer> c(new Checkpointer(db, options));
  try {
    c->thread_ = std::thread([p = c.get()] { p->Loop(); });
  } catch (const std::system_error&) {
    return nullptr;  // no thread: the destructor only closes the connection
  }
  return c;
}

Checkpointer::~Checkpointer() {
  {
    std::lock_guard<std::mutex> lock(mu_);
    stop_ = true;
  }
  wake_.notify_all();
  done_.notify_all();
  if (thread_.joinable()) thread_.join();
  sqlite3_close_v2(db_);
}

void Checkpointer::Attach(sqlite3* db) { sqlite3_wal_hook(db, &Checkpointer::OnCommit, this); }

void Checkpointer::Detach(sqlite3* db) { sqlite3_wal_hook(db, nullptr, nullptr); }

std::uint64_t Checkpointer::passes() const {
  std::lock_guard<std::mutex> lock(mu_);
  return passes_;
}

int Checkpointer::OnCommit(void* self_ptr, sqlite3* /*db*/, const char* /*name*/, int wal_pages) {
  auto* self = static_cast<Checkpointer*>(self_ptr);
  // A WAL that is smaller than at the last request was restarted from its beginning: count afresh.
  if (wal_pages < self->requested_at_pages_) self->requested_at_pages_ = 0;
  if (wal_pages >= self->options_.wait_above_pages) {
    self->requested_at_pages_ = wal_pages;
    self->WaitFor(self->Request());
  } else if (wal_pages - self->requested_at_pages_ >= self->options_.request_every_pages) {
    self->requested_at_pages_ = wal_pages;
    self->Request();
  }
  return SQLITE_OK;
}

std::uint64_t Checkpointer::Request() {
  std::uint64_t generation;
  {
    std::lock_guard<std::mutex> lock(mu_);
    generation = ++requested_;
  }
  wake_.notify_one();
  return generation;
}

void Checkpointer::WaitFor(std::uint64_t generation) {
  std::unique_lock<std::mutex> lock(mu_);
  done_.wait_for(lock, options_.max_wait, [&] { return completed_ >= generation || stop_; });
}

void Checkpointer::Loop() {
  std::unique_lock<std::mutex> lock(mu_);
  while (true) {
    wake_.wait(lock, [&] { return stop_ || requested_ > completed_; });
    if (stop_) return;
    const std::uint64_t generation = requested_;  // this pass covers every request made so far
    lock.unlock();
    // PASSIVE: copies what no reader still needs, never waits for or blocks anybody. Errors (SQLITE_BUSY when
    // another connection is checkpointing, I/O errors) leave the WAL as it is; the next request tries again,
    // and the committing connection's next transaction reports any real I/O problem itself.
    sqlite3_wal_checkpoint_v2(db_, "main", SQLITE_CHECKPOINT_PASSIVE, nullptr, nullptr);
    lock.lock();
    completed_ = generation;
    ++passes_;
    done_.notify_all();
  }
}

}  // namespace vb::db
