// The one clock helper of the project: nanoseconds of a POSIX clock, CLOCK_MONOTONIC by default,
// and back to a timespec. Async-signal-safe and allocation-free (clock_gettime only).
#pragma once

#include <time.h>

#include <cstdint>

namespace pedalwave {

inline std::int64_t clock_ns(clockid_t id) noexcept {
  timespec ts{};
  clock_gettime(id, &ts);
  return static_cast<std::int64_t>(ts.tv_sec) * 1'000'000'000LL + ts.tv_nsec;
}
inline std::int64_t monotonic_ns() noexcept { return clock_ns(CLOCK_MONOTONIC); }
// The calling thread's CPU time [s] (what a computation costs, without the preemptions of a
// shared machine).
inline double thread_cpu_s() noexcept { return 1e-9 * static_cast<double>(clock_ns(CLOCK_THREAD_CPUTIME_ID)); }

// A time in ns as a timespec (negative times clamp to 0).
inline timespec to_timespec(std::int64_t ns) noexcept {
  if (ns < 0) ns = 0;
  timespec ts{};
  ts.tv_sec = static_cast<time_t>(ns / 1'000'000'000LL);
  ts.tv_nsec = static_cast<long>(ns % 1'000'000'000LL);
  return ts;
}

}  // namespace pedalwave
