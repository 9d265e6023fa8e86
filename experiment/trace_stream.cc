#include "experiment/trace_stream.h"

namespace vb::experiment {

void TraceStream::Ring::Push(int v) {
  const std::uint64_t t = tail.load(std::memory_order_relaxed);
  slots[t % slots.size()] = v;
  tail.store(t + 1, std::memory_order_release);
}

bool TraceStream::Ring::Pop(int* v) {
  const std::uint64_t h = head.load(std::memory_order_relaxed);
  if (h == tail.load(std::memory_order_acquire)) return false;
  *v = slots[h % slots.size()];
  head.store(h + 1, std::memory_order_release);
  return true;
}

TraceStream::TraceStream(std::size_t block_samples, int blocks, double sample_period_s, BlockSink* sink)
    : sink_(sink) {
  if (blocks < 2) blocks = 2;
  full_.slots.assign(static_cast<std::size_t>(blocks), -1);
  free_.slots.assign(static_cast<std::size_t>(blocks), -1);
  first_sample_.assign(static_cast<std::size_t>(blocks), 0);
  for (int b = 0; b < blocks; ++b) {
    auto block = std::make_unique<Trace>();
    block->Reserve(block_samples);
    block->sample_period_s = sample_period_s;
    blocks_.push_back(std::move(block));
    if (b > 0) free_.Push(b);  // block 0 is first()
  }
  thread_ = std::thread([this] { Consume(); });
}

TraceStream::~TraceStream() {
  if (thread_.joinable()) (void)Close(nullptr);
}

Trace* TraceStream::first() { return blocks_[0].get(); }

Trace* TraceStream::Rotate(Trace* full) {
  int index = 0;
  while (blocks_[static_cast<std::size_t>(index)].get() != full) ++index;
  first_sample_[static_cast<std::size_t>(index)] = handed_samples_;
  handed_samples_ += full->size();
  full_.Push(index);
  full_signal_.fetch_add(1, std::memory_order_release);
  full_signal_.notify_one();
  int next = 0;
  while (!free_.Pop(&next)) {
    loop_waits_.fetch_add(1, std::memory_order_relaxed);
    const std::uint32_t seen = free_signal_.load(std::memory_order_acquire);
    if (free_.Pop(&next)) break;
    free_signal_.wait(seen, std::memory_order_acquire);
  }
  Trace* block = blocks_[static_cast<std::size_t>(next)].get();
  block->Clear();
  return block;
}

Status TraceStream::Close(Trace* last) {
  if (!thread_.joinable()) return error_;
  if (last != nullptr && last->size() > 0) {
    int index = 0;
    while (blocks_[static_cast<std::size_t>(index)].get() != last) ++index;
    first_sample_[static_cast<std::size_t>(index)] = handed_samples_;
    handed_samples_ += last->size();
    full_.Push(index);
  }
  closing_.store(true, std::memory_order_release);
  full_signal_.fetch_add(1, std::memory_order_release);
  full_signal_.notify_one();
  thread_.join();
  return error_;
}

void TraceStream::Consume() {
  auto deliver = [this](int index) {
    const Trace& block = *blocks_[static_cast<std::size_t>(index)];
    if (error_.ok()) {
      error_ = sink_->OnBlock(block, first_sample_[static_cast<std::size_t>(index)]);
      if (!error_.ok()) failed_.store(true, std::memory_order_release);
    }
    free_.Push(index);
    free_signal_.fetch_add(1, std::memory_order_release);
    free_signal_.notify_one();
  };
  while (true) {
    const std::uint32_t seen = full_signal_.load(std::memory_order_acquire);
    int index = 0;
    if (full_.Pop(&index)) {
      deliver(index);
      continue;
    }
    if (closing_.load(std::memory_order_acquire)) {
      // Close() pushed its last block before it set the flag: drain and stop.
      while (full_.Pop(&index)) deliver(index);
      return;
    }
    full_signal_.wait(seen, std::memory_order_acquire);
  }
}

}  // namespace vb::experiment
