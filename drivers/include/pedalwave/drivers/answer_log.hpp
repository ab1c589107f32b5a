// Which SYNC an answer answered, and which command its module had applied, in full host cycle
// numbers (drivers/PROTOCOL.md §4.1). Shared by the CAN and the serial drivers.
//
// The wire carries both as short counters: the echo of the SYNC counter c, and the tag of the
// applied command (the c it was written with) — 4 bits on classic CAN, 8 on CAN FD and serial.
// The host's cycle k sends SYNC c = k mod 256. Mapping a counter to "the newest cycle with that
// counter" is right only while answers are younger than M cycles (M = 16 or 256). A module whose
// thread was held while the host ran on (the VM under load: 100+ ms) answers its backlog of SYNCs
// afterwards, all at once, each answer with the tag of the command it had applied just before:
// at 100 Hz a 170 ms backlog on classic CAN made the newest command with that tag, 16 cycles
// younger, look applied — several N·m of module-law torque in the observer's residual
// (BusWalkStalls.TheModulesThreadHeldWhileTheLoopRunsIsNoFault: actuator_torque 1.4–3.8 N·m).
//
//   CycleLog     the host's last 256 cycles: each SYNC's lower bound (no module can have sampled
//                before it) and the command written in it.
//   AnswerTrack  per module, the full cycle of its newest answer. Modules answer SYNCs in order
//                and handle frames in order, so an answer is the newest one's successor by the
//                echo's distance: one number while fewer than M cycles separate them. After a
//                longer silence several numbers fit (answers lost, or a held module's backlog),
//                and the track is UNSURE: its answers' values and sample times (the module clock
//                as it stands) are used, their SYNC (the clock's lower bound) and applied command
//                are not (Feedback::applied_seq = kUnknownSeq: the observer integrates no interval
//                with an unknown command) — until the module answers in step again: kInStep
//                cycles in a row with exactly one answer, the cycle's own, before the deadline
//                (a backlog arrives as a burst of several answers a cycle). It is then anchored
//                at the current cycle.
//   The applied command: commands go out after their cycle's SYNC, so a module answering SYNC k
//   has applied one written in a cycle before k: the newest cycle y < k with y ≡ tag (mod M).
// All O(1), allocation-free, noexcept.
#pragma once

#include <array>
#include <cstdint>

#include "pedalwave/interface/io.hpp"

namespace pedalwave::drivers {

class CycleLog {
 public:
  static constexpr std::uint64_t kSize = 256;  // cycles remembered [-]
  // Cycle `cycle`'s SYNC left: no module sampled before lower_ns [ns].
  void sync(std::uint64_t cycle, std::int64_t lower_ns) noexcept {
    entry(cycle) = {cycle, lower_ns, kNoCommandSeq, false};
  }
  // The command written in cycle `cycle` (tagged with its counter) is Command::seq `seq`.
  void command(std::uint64_t cycle, std::uint64_t seq) noexcept {
    Entry& e = entry(cycle);
    if (e.cycle == cycle) e.seq = seq, e.written = true;
  }
  // SYNC `cycle`'s lower bound [ns]; 0 = not in the log.
  std::int64_t sync_lower(std::uint64_t cycle) const noexcept {
    const Entry& e = entry(cycle);
    return e.cycle == cycle ? e.lower_ns : 0;
  }
  // Command::seq of the command applied by a module answering SYNC `answered` with tag `tag`
  // (mod `modulus`, a power of two ≤ 256); kUnknownSeq if that cycle wrote none or left the log.
  std::uint64_t applied(std::uint64_t answered, unsigned tag, unsigned modulus) const noexcept {
    if (answered < 2) return kUnknownSeq;
    const std::uint64_t top = answered - 1;
    const std::uint64_t back = (top - tag) & (modulus - 1u);
    if (back >= top) return kUnknownSeq;  // before the first cycle
    const std::uint64_t y = top - back;
    const Entry& e = entry(y);
    return e.cycle == y && e.written ? e.seq : kUnknownSeq;
  }

 private:
  struct Entry {
    std::uint64_t cycle = ~0ull;
    std::int64_t lower_ns = 0;
    std::uint64_t seq = kNoCommandSeq;
    bool written = false;
  };
  Entry& entry(std::uint64_t c) noexcept { return log_[c % kSize]; }
  const Entry& entry(std::uint64_t c) const noexcept { return log_[c % kSize]; }
  std::array<Entry, kSize> log_{};
};

class AnswerTrack {
 public:
  static constexpr int kInStep = 3;  // cycles answered in step that anchor an unsure track [-]
  // An answer echoing `echo` (mod `modulus`) received in host cycle `cycle`: the cycle of the
  // SYNC it answered (sure() says whether certainly); 0 = a repeated or backward echo (the
  // rolling counter classifies those; they are not used).
  std::uint64_t take(unsigned echo, unsigned modulus, std::uint64_t cycle) noexcept {
    const std::uint64_t mask = modulus - 1u;
    ++answers_;
    std::uint64_t x = 0;
    if (newest_ == 0) {
      x = cycle - ((cycle - echo) & mask);
      if (x == 0) return 0;
      if (x > modulus) sure_ = false;  // x − M fits as well
    } else {
      const std::uint64_t d = (echo - newest_) & mask;
      // Within half the counter's range of the newest answer, a distance past half is backward.
      if (d == 0 || (cycle - newest_ < modulus / 2 && d >= modulus / 2)) return 0;
      x = newest_ + d;
      if (x > cycle) return 0;  // a SYNC not sent yet: nothing it can be
    }
    if (x + modulus <= cycle) sure_ = false;  // x + M fits as well
    newest_ = x;
    return x;
  }
  bool sure() const noexcept { return sure_; }
  // End of host cycle `cycle`; in_step: the module's answer to this cycle's SYNC came before the
  // deadline. An unsure track is anchored after kInStep such cycles with one answer each.
  void end_cycle(std::uint64_t cycle, bool in_step) noexcept {
    if (!sure_) {
      in_step_ = in_step && answers_ == 1 ? in_step_ + 1 : 0;
      if (in_step_ >= kInStep) sure_ = true, newest_ = cycle, in_step_ = 0;
    }
    answers_ = 0;
  }

 private:
  std::uint64_t newest_ = 0;  // cycle of the newest answer's SYNC (0 = none yet) [-]
  bool sure_ = true;
  int in_step_ = 0;           // cycles in a row answered in step while unsure [-]
  int answers_ = 0;           // answers received this cycle [-]
};

}  // namespace pedalwave::drivers
