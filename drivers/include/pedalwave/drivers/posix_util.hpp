// Small POSIX helpers shared by the drivers and the module emulator.
#pragma once

#include <fcntl.h>

#include "pedalwave/interface/clock.hpp"

namespace pedalwave::drivers::detail {

using pedalwave::clock_ns;
using pedalwave::monotonic_ns;
using pedalwave::to_timespec;

inline bool set_nonblocking(int fd) noexcept {
  const int fl = fcntl(fd, F_GETFL, 0);
  return fl >= 0 && fcntl(fd, F_SETFL, fl | O_NONBLOCK) == 0;
}

}  // namespace pedalwave::drivers::detail
