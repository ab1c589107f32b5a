// Rolling-counter bookkeeping of one module, shared by the CAN and the serial drivers
// (drivers/PROTOCOL.md §4). Each cycle the host sends a counter c (SYNC); every feedback frame
// echoes the counter of the SYNC it answers. A frame is classified against the cycle's c and the
// last echo seen from the same module (signed distance d = echo − last, modulo M):
//   d == 0            → kDuplicate  (the same counter twice: repeated / re-sent frame)
//   d <  0            → kOutOfOrder (the module's counter went backwards)
//   d >  0, echo == c → kFresh      (first frame of this cycle: the only one whose data is used)
//   d >  0, echo != c → kLate       (answer to an older SYNC that arrived after its deadline)
// The history is forgotten after M/2 cycles without frames, so a module that was silent for long
// comes back as fresh. M = 16 on classic CAN (4-bit echo), 256 on CAN FD / serial.
#pragma once

#include <cstdint>

namespace pedalwave::drivers {

enum class FrameAge : std::uint8_t { kFresh, kDuplicate, kLate, kOutOfOrder };

struct RollingCounterState {
  std::uint8_t last = 0;         // last echo received from the module [-]
  bool have_last = false;        // `last` is meaningful
  bool fresh = false;            // a fresh frame arrived in the current cycle
  std::uint64_t last_cycle = 0;  // host cycle in which `last` was received [-]
};

// Start of a host cycle: no fresh frame yet.
inline void begin_cycle(RollingCounterState& s) noexcept { s.fresh = false; }

// Classify a frame carrying `echo` received in host cycle `cycle` whose SYNC counter is `current`.
// `modulus` is 16 or 256 (a power of two).
inline FrameAge classify_frame(RollingCounterState& s, unsigned echo, unsigned current,
                               std::uint64_t cycle, unsigned modulus) noexcept {
  const unsigned mask = modulus - 1u;
  echo &= mask;
  current &= mask;
  if (s.have_last && cycle - s.last_cycle >= modulus / 2) s.have_last = false;
  if (s.have_last) {
    int d = static_cast<int>((echo - s.last) & mask);
    if (d >= static_cast<int>(modulus / 2)) d -= static_cast<int>(modulus);
    if (d == 0) {
      s.last_cycle = cycle;
      return FrameAge::kDuplicate;
    }
    if (d < 0) {
      s.last = static_cast<std::uint8_t>(echo);
      s.last_cycle = cycle;
      return FrameAge::kOutOfOrder;
    }
  }
  s.last = static_cast<std::uint8_t>(echo);
  s.last_cycle = cycle;
  s.have_last = true;
  if (echo == current && !s.fresh) {
    s.fresh = true;
    return FrameAge::kFresh;
  }
  return echo == current ? FrameAge::kDuplicate : FrameAge::kLate;
}

}  // namespace pedalwave::drivers
