// A late answer is still a sample (drivers/PROTOCOL.md §1.1, §4). A module's answer to an older
// SYNC, received after that cycle's deadline, carries the module's own sample time: it says
// exactly when the values were measured, so they are as good as a fresh sample — only older.
// A joint without a fresh answer this cycle therefore gets the newest late one (kStatusLate, its
// own sample time) instead of nothing, provided it is newer than the last sample handed out.
// Only a module that sends nothing at all is missing. Shared by the CAN and the serial drivers.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "pedalwave/drivers/answer_log.hpp"
#include "pedalwave/interface/io.hpp"
#include "pedalwave/drivers/module_clock.hpp"
#include "pedalwave/drivers/wire.hpp"

namespace pedalwave::drivers {

struct LateSample {
  JointSample values{};                                  // the late answer's measurement
  std::uint8_t values_echo = 0;                          // SYNC counter it answered [-]
  std::uint64_t answered = 0;                            // … as a host cycle (AnswerTrack) [-]
  bool sure = false;                                     // … and whether that is certain
  bool have_values = false;
  wire::ModuleTiming timing{};                           // its timing record
  std::uint8_t timing_echo = 0;                          // SYNC counter of the record [-]
  bool have_timing = false;

  void clear() noexcept { have_values = have_timing = false; }
  // A late frame's values (later frames overwrite: answers arrive in bus order, newest last).
  void offer_values(std::uint8_t echo, std::uint64_t cycle, bool certain,
                    const JointSample& v) noexcept {
    values = v, values_echo = echo, have_values = true;
    answered = cycle, sure = certain;
  }
  void offer_timing(std::uint8_t echo, const wire::ModuleTiming& t) noexcept {
    timing = t, timing_echo = echo, have_timing = true;
  }
  // Values and the record of the same sample (on classic CAN they travel in two frames).
  bool complete() const noexcept { return have_values && have_timing && values_echo == timing_echo; }
};

// The module-clock sample times handed out for one joint must increase: a late answer older than
// the sample already handed out (a fresh one came in between) is not used.
struct HandedOut {
  std::uint32_t sample_us = 0;
  bool any = false;
  bool newer(std::uint32_t us) const noexcept {
    return !any || static_cast<std::int32_t>(us - sample_us) > 0;
  }
  void take(std::uint32_t us) noexcept { sample_us = us, any = true; }
};

// When the module applied its last command, on the host clock [ns]; 0 = unknown: the age
// saturated at kAgeMaxUs (applied 32.8 ms or more before the sample, e.g. across a stall of a
// 100 Hz loop), so the command's switch time inside the interval is not known (Feedback).
inline std::int64_t applied_host_ns(const wire::ModuleTiming& t, const ModuleClock& clk) noexcept {
  return t.applied_age_us >= wire::kAgeMaxUs ? 0 : clk.to_host(t.sample_us - t.applied_age_us);
}

// The command a module's record says it applied: Command::seq through the cycle log, for an
// answer to SYNC `answered` whose placement is `sure` (kUnknownSeq if not; kNoCommandSeq: none).
inline std::uint64_t applied_seq_of(const wire::ModuleTiming& t, const CycleLog& log,
                                    std::uint64_t answered, bool sure, unsigned modulus) noexcept {
  if (t.no_command) return kNoCommandSeq;
  return sure ? log.applied(answered, t.applied_tag, modulus) : kUnknownSeq;
}

// Joint j's sample in `out` from its timing record t (fresh or late) answering SYNC `answered`
// (AnswerTrack; `sure`: certainly that one): the sample time through the module clock — updated
// with that SYNC's lower bound (no module sampled before it) only when sure; else mapped as the
// clock stands — the command it applied last (tag → Command::seq, answer_log.hpp) and when.
// Notes the time handed out.
inline void hand_out(const wire::ModuleTiming& t, const CycleLog& log, std::uint64_t answered,
                     bool sure, unsigned modulus, ModuleClock& clk, HandedOut& handed,
                     Feedback& out, std::size_t j) noexcept {
  const std::int64_t lower = sure ? log.sync_lower(answered) : 0;
  if (lower != 0) out.sample_ns[j] = clk.update(t.sample_us, lower);
  else out.sample_ns[j] = clk.started() ? clk.to_host(t.sample_us) : 0;
  out.applied_ns[j] = clk.started() ? applied_host_ns(t, clk) : 0;
  out.applied_seq[j] = applied_seq_of(t, log, answered, lower != 0, modulus);
  handed.take(t.sample_us);
}

}  // namespace pedalwave::drivers
