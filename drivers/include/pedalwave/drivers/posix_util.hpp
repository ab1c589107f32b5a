// Small POSIX helpers shared by the drivers and the module emulator.
#pragma once

#include <fcntl.h>
#include <poll.h>

#include <cerrno>
#include <cstdint>

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

}  // namespace pedalwave::drivers::detail
