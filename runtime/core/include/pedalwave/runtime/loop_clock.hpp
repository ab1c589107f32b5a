// The loop's time base: absolute deadlines on CLOCK_MONOTONIC (real-time mode) or a counter that
// advances by exactly one period per cycle (lockstep mode, for tests and simulation: no sleeping,
// bit-reproducible). Both modes run the same loop code; only now() and sleep_until() differ.
#pragma once

#include <cstdint>

#include "pedalwave/interface/clock.hpp"

namespace pedalwave::runtime {

enum class ClockMode : std::uint8_t {
  kRealtime = 0,  // CLOCK_MONOTONIC, clock_nanosleep(TIMER_ABSTIME)
  kLockstep,      // counter; sleep_until() jumps the counter to the deadline
};

// Monotonic time [ns] (CLOCK_MONOTONIC): the project's one clock helper (interface/clock.hpp).
using pedalwave::monotonic_ns;

// Where the next deadline goes after a cycle that ended at end_ns, given the deadline the cycle
// woke for. The nominal next deadline is deadline_ns + period_ns. If the cycle ended after it
// (an overrun), whole periods are skipped so that the next deadline is the first grid point
// strictly after end_ns: never accumulate, never burst to catch up.
struct NextDeadline {
  std::int64_t deadline_ns = 0;  // next absolute deadline [ns]
  std::uint32_t skipped = 0;     // periods skipped (0 = on time) [-]
  bool overrun = false;          // the cycle ended after the nominal next deadline
};
NextDeadline next_deadline(std::int64_t deadline_ns, std::int64_t period_ns,
                           std::int64_t end_ns) noexcept;

class LoopClock {
 public:
  // start_ns: first deadline. For lockstep the counter starts there; for real time pass
  // monotonic_ns() + some margin.
  LoopClock(ClockMode mode, std::int64_t start_ns) noexcept
      : mode_(mode), counter_ns_(start_ns) {}

  ClockMode mode() const noexcept { return mode_; }

  // Current time [ns]: CLOCK_MONOTONIC, or the lockstep counter.
  std::int64_t now() const noexcept { return mode_ == ClockMode::kLockstep ? counter_ns_ : monotonic_ns(); }

  // Blocks until deadline_ns (absolute). Returns false if interrupted by a signal before the
  // deadline (the caller checks its stop flag and calls again). Lockstep: the counter jumps to
  // max(counter, deadline_ns) and it returns true at once.
  bool sleep_until(std::int64_t deadline_ns) noexcept;

  // Lockstep only: move the counter forward by ns, as if a stage had computed for that long
  // (used by tests and simulations to exercise overruns deterministically). No-op in real time.
  void advance(std::int64_t ns) noexcept {
    if (mode_ == ClockMode::kLockstep && ns > 0) counter_ns_ += ns;
  }

 private:
  ClockMode mode_;
  std::int64_t counter_ns_;  // lockstep time [ns]
};

}  // namespace pedalwave::runtime
