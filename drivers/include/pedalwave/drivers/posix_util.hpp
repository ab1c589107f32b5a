// Small POSIX helpers shared by the drivers and the module emulator.
#pragma once

#include <fcntl.h>
#include <poll.h>

#include <cerrno>
#include <cstdint>
#include <ctime>

#include "pedalwave/interface/clock.hpp"

namespace pedalwave::drivers::detail {

using pedalwave::clock_ns;
using pedalwave::monotonic_ns;
using pedalwave::to_timespec;

inline bool set_nonblocking(int fd) noexcept {
  const int fl = fcntl(fd, F_GETFL, 0);
  return fl >= 0 && fcntl(fd, F_SETFL, fl | O_NONBLOCK) == 0;
}

// The receive loop of a cycle: until done() or the deadline (CLOCK_MONOTONIC [ns]), waits for `fd`
// to be readable and calls on_readable() each time it is (EINTR retried; another poll error ends it).
template <class Done, class OnReadable>
void poll_until(int fd, std::int64_t deadline_ns, Done done, OnReadable on_readable) noexcept {
  while (!done()) {
    const std::int64_t remaining = deadline_ns - monotonic_ns();
    if (remaining <= 0) return;
    pollfd p{fd, POLLIN, 0};
    const timespec ts = to_timespec(remaining);
    const int r = ::ppoll(&p, 1, &ts, nullptr);
    if (r < 0 && errno != EINTR) return;
    if (r > 0) on_readable();
  }
}

// CLOCK_REALTIME − CLOCK_MONOTONIC [ns]: maps the kernel's receive stamps (SO_TIMESTAMPNS,
// CLOCK_REALTIME) onto CLOCK_MONOTONIC. The offset changes only when the system clock is set
// (NTP slews both clocks alike), but a read of it is as uncertain as the time between its two
// clock reads: in the loaded vcan VM the master's and the drives' per-read offsets put one SYNC
// 30–120 µs apart in a tenth of the cycles — and a sample's time that far off is an impulse of
// k_d·β̇·δ = 15 N·m·s/rad × 2.5 rad/s × 0.1 ms, a residual kick of the threshold's size (the
// false actuator_torque / deflection_bias of issue 14). So the offset is kept: each read brackets
// the realtime read by two monotonic ones; a bracket narrower than any before replaces the kept
// value (its midpoint is within half its width of the truth), and one that moves it by more than
// step_ns is the clock being set and replaces it too. A wide bracket (the thread preempted
// between the reads: three tries) changes nothing.
class RealtimeOffset {
 public:
  using Clock = std::int64_t (*)(clockid_t) noexcept;
  explicit RealtimeOffset(std::int64_t max_bracket_ns = 50'000, Clock clock = &clock_ns,
                          std::int64_t step_ns = 1'000'000) noexcept
      : max_bracket_ns_(max_bracket_ns), step_ns_(step_ns), clock_(clock) {}

  std::int64_t get() noexcept {
    std::int64_t best_width = INT64_MAX, best = 0;
    for (int i = 0; i < 3; ++i) {
      const std::int64_t m0 = clock_(CLOCK_MONOTONIC);
      const std::int64_t r = clock_(CLOCK_REALTIME);
      const std::int64_t m1 = clock_(CLOCK_MONOTONIC);
      const std::int64_t width = m1 - m0;
      if (width < best_width) best_width = width, best = r - (m0 + width / 2);
      if (width <= max_bracket_ns_) break;
      ++retried_;
    }
    if (best_width > max_bracket_ns_) {
      ++loose_;
      if (!valid_) offset_ = best, width_ = best_width, valid_ = true;  // nothing better yet
      return offset_;
    }
    const std::int64_t moved = best - offset_;
    if (!valid_ || moved > step_ns_ || moved < -step_ns_) {
      if (valid_) ++steps_;
      offset_ = best, width_ = best_width, valid_ = true;
    } else if (best_width < width_) {
      offset_ = best, width_ = best_width;
    }
    return offset_;
  }
  // Tries whose bracket was wide (two reads in a row would have been off by more than
  // max_bracket_ns) [-]; calls without a tight bracket in three tries [-]; clock steps followed [-];
  // the kept value's bracket, its uncertainty's double [ns].
  std::uint64_t retried() const noexcept { return retried_; }
  std::uint64_t loose() const noexcept { return loose_; }
  std::uint64_t steps() const noexcept { return steps_; }
  std::int64_t width_ns() const noexcept { return width_; }

 private:
  std::int64_t max_bracket_ns_, step_ns_;
  Clock clock_;
  std::int64_t offset_ = 0, width_ = 0;
  bool valid_ = false;
  std::uint64_t retried_ = 0, loose_ = 0, steps_ = 0;
};

}  // namespace pedalwave::drivers::detail
