// Counts global allocations so a test can assert that a real-time path (a law's Step()) never allocates.
// Include from exactly one source file of a test binary: it replaces the global operator new/delete.
// noinline keeps GCC's -Wmismatched-new-delete analysis quiet.
#pragma once

#include <atomic>
#include <cstdlib>
#include <new>

namespace vb::testing {
inline std::atomic<long> g_allocations{0};
}  // namespace vb::testing

[[gnu::noinline]] void* operator new(std::size_t n) {
  vb::testing::g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n == 0 ? 1 : n)) return p;
  throw std::bad_alloc();
}
[[gnu::noinline]] void operator delete(void* p) noexcept { std::free(p); }
[[gnu::noinline]] void operator delete(void* p, std::size_t) noexcept { std::free(p); }
