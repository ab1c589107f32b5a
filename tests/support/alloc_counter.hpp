// Counts heap allocations made by the calling thread, to prove that a hot path allocates nothing
// (the global operator new/delete are replaced in alloc_counter.cpp; malloc via Eigen's
// aligned allocator goes through its own hook, see eigen_no_malloc).
#pragma once

#include <cstdint>

namespace pedalwave::test {

// Allocations (operator new of any form) performed by this thread since it started.
std::uint64_t thread_allocations() noexcept;

// RAII scope: counts allocations made by this thread while alive.
class AllocationScope {
 public:
  AllocationScope() noexcept : start_(thread_allocations()) {}
  std::uint64_t count() const noexcept { return thread_allocations() - start_; }

 private:
  std::uint64_t start_;
};

}  // namespace pedalwave::test
