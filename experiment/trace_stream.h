// A trace in blocks, from the control loop to a consumer thread (docs/store.md, "Traces while the run
// executes"). The loop records into one preallocated block; when it is full the loop hands it over and takes an
// empty one. Handing over is two atomics and a futex wake (std::atomic::notify_one): no allocation, no lock and
// no I/O in the loop. The consumer (a store writer) gets the blocks in order on its own thread. A run's memory
// is then `blocks` x `block_samples` samples whatever its length.
//
// When the consumer falls behind and no empty block is left, the loop waits for one (the consumer is the
// store: losing samples is worse than a late tick on an emulator; on hardware the store keeps up by a wide
// margin, docs/perf.md). Those waits are counted.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>
#include <vector>

#include "common/status.h"
#include "experiment/trace.h"

namespace vb::experiment {

class BlockSink {
 public:
  virtual ~BlockSink() = default;
  // On the stream's thread, in order. first_sample: the block's first sample's index in the whole trace. An
  // error stops the stream: later blocks are not delivered, and TraceStream::failed() turns true.
  virtual Status OnBlock(const Trace& block, std::uint64_t first_sample) = 0;
};

class TraceStream {
 public:
  // Allocates every block up front (std::bad_alloc escapes here, before any bench is touched).
  TraceStream(std::size_t block_samples, int blocks, double sample_period_s, BlockSink* sink);
  ~TraceStream();
  TraceStream(const TraceStream&) = delete;
  TraceStream& operator=(const TraceStream&) = delete;

  // Loop side. The block to record into, empty, with capacity block_samples.
  Trace* first();
  // Hands `full` (the block last returned) to the consumer; returns the next empty block.
  Trace* Rotate(Trace* full);
  // After the loop: hands over `last` (may be empty), waits until every block is consumed and stops the thread.
  // Returns the sink's first error (OK when every block was taken).
  Status Close(Trace* last);

  // True once the sink refused a block: the loop should stop (the run cannot be recorded).
  bool failed() const { return failed_.load(std::memory_order_acquire); }
  std::uint64_t loop_waits() const { return loop_waits_.load(std::memory_order_relaxed); }
  std::uint64_t samples_handed() const { return handed_samples_; }

 private:
  void Consume();

  // Single-producer single-consumer rings of block indices; capacity = number of blocks.
  struct Ring {
    std::vector<int> slots;
    std::atomic<std::uint64_t> head{0}, tail{0};  // push at tail, pop at head
    void Push(int v);
    bool Pop(int* v);
  };

  BlockSink* sink_;
  std::vector<std::unique_ptr<Trace>> blocks_;
  std::vector<std::uint64_t> first_sample_;
  Ring full_, free_;
  std::atomic<std::uint32_t> full_signal_{0}, free_signal_{0};
  std::atomic<bool> closing_{false}, failed_{false};
  std::atomic<std::uint64_t> loop_waits_{0};
  std::uint64_t handed_samples_ = 0;  // loop side
  Status error_;                      // consumer side; read after join
  std::thread thread_;
};

}  // namespace vb::experiment
