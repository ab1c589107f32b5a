#include "pedalwave/runtime/loop_clock.hpp"

#include <time.h>

#include <cerrno>

namespace pedalwave::runtime {

NextDeadline next_deadline(std::int64_t deadline_ns, std::int64_t period_ns,
                           std::int64_t end_ns) noexcept {
  NextDeadline n;
  n.deadline_ns = deadline_ns + period_ns;
  if (end_ns > n.deadline_ns) {
    // Periods that elapsed entirely past the nominal deadline, plus the one we are in.
    const std::int64_t late = end_ns - n.deadline_ns;
    const std::int64_t skip = late / period_ns + 1;
    n.deadline_ns += skip * period_ns;
    n.skipped = static_cast<std::uint32_t>(skip);
    n.overrun = true;
  }
  return n;
}

bool LoopClock::sleep_until(std::int64_t deadline_ns) noexcept {
  if (mode_ == ClockMode::kLockstep) {
    if (deadline_ns > counter_ns_) counter_ns_ = deadline_ns;
    return true;
  }
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(deadline_ns / 1'000'000'000);
  ts.tv_nsec = static_cast<long>(deadline_ns % 1'000'000'000);
  for (;;) {
    const int rc = clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
    if (rc == 0) return true;
    if (rc == EINTR) return false;  // a signal: let the caller look at its stop flag
    // EINVAL cannot happen for a valid timespec; fall back to returning (never spin forever).
    return true;
  }
}

}  // namespace pedalwave::runtime
