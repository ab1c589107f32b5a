// The events of one run, as the end-of-run report tells them (non-real-time side only).
//
// The consumer hands every EventSample it drains to an EventLog: each is classified (a fault, a
// warning, a mode change or an operator-command outcome), given the reaction the runtime took
// (continue / hold / safe stop, from the RuntimeConfig's ReactionTable and, for the fault that
// stopped the run, from the FAULT transition that followed it), and kept in bounded memory: the
// first kHead and the last kTail events; the ones in between are counted, not kept.
//
// Joint numbering: EventSample::joint is a 0-based data field (−1 none). Every text produced here
// says "joint N" with N = joint + 1 (joint 1 = the first joint = CAN node / DYNAMIXEL id 1).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "pedalwave/interface/sample.hpp"
#include "pedalwave/interface/stages.hpp"

namespace pedalwave::runtime {

struct RunResult;

enum class EventKind : std::uint8_t {
  kFault = 0,  // a fault class became active (severity degrade / stop), or a reaction to one
  kWarning,    // a fault class became active with severity info / warning
  kMode,       // a mode transition (from != to)
  kOperator,   // the outcome of an operator command (accepted or rejected)
};
const char* to_string(EventKind k) noexcept;  // "fault", "warning", "mode", "operator"

// What the runtime did about an event; kNone for events nothing reacts to (routine mode changes,
// rejected commands).
enum class EventReaction : std::uint8_t { kNone = 0, kContinue, kHold, kSafeStop };
const char* to_string(EventReaction r) noexcept;  // "none", "continue", "hold", "safe_stop"

struct RunEvent {
  EventSample sample;
  EventKind kind = EventKind::kMode;
  EventReaction reaction = EventReaction::kNone;
  // Listed in the summary and the exit line: every fault, warning and operator outcome, and a
  // mode change into FAULT/SAFE_STOP that no listed event already explains (e-stop, a fault that
  // was already active). Routine transitions (CONFIGURED, READY, RUNNING, the end-of-run
  // SAFE_STOP) are only in the JSON report.
  bool listed = false;
};

EventKind classify(const EventSample& e) noexcept;
// The reaction the table gives the event's fault and severity (fault/warning events), hold for an
// accepted "stop walking", continue for other accepted commands, safe stop for FAULT/SAFE_STOP
// transitions, none otherwise.
EventReaction reaction_of(const EventSample& e, const ReactionTable& reactions) noexcept;

class EventLog {
 public:
  static constexpr std::size_t kHead = 224;  // first events kept [-]
  static constexpr std::size_t kTail = 32;   // last events kept [-]

  // Reserves everything once; add() then never allocates.
  EventLog();

  void add(const EventSample& e, const ReactionTable& reactions);
  // Forget everything (a new run).
  void clear() noexcept;

  // The kept events in order (the first kHead, then the last kTail).
  std::vector<RunEvent> events() const;
  std::uint64_t total() const noexcept { return total_; }
  std::uint64_t dropped() const noexcept { return total_ - head_.size() - tail_.size(); }
  // Time origin of the report [ns]: the READY transition ("loop started", the run start), else the
  // first event. Events before it (CONFIGURED) have a negative time.
  std::int64_t t0_ns() const noexcept { return t0_ns_; }
  double seconds(const EventSample& e) const noexcept {
    return static_cast<double>(e.t_ns - t0_ns_) / 1e9;  // [s], correctly rounded
  }

 private:
  RunEvent* last_evidence(FaultClass f, std::int16_t joint) noexcept;

  std::vector<RunEvent> head_;
  std::vector<RunEvent> tail_;  // ring of the last kTail once head_ is full
  std::size_t tail_next_ = 0;   // oldest slot of tail_ when it is full
  std::uint64_t total_ = 0;
  std::int64_t t0_ns_ = 0;
  bool have_t0_ = false, t0_is_start_ = false;
};

// One event, one line: "[t 4.512 s, cycle 4512] warning motor_friction joint 2 (value 0.031,
// threshold 0.03): <text> → continue".
std::string format_event(const RunEvent& e, const EventLog& log);
// The short form of the exit line: "warning motor_friction joint 2 (value 0.031, threshold 0.03)
// → continue", "operator stop walking at 248.1 s → gait frozen, holding".
std::string format_event_short(const RunEvent& e, const EventLog& log);
// "exit: cycle_limit, final mode SAFE_STOP, no stopping fault; 2 events: …; …" — never "no fault"
// when something happened; the listed events (a fault and the hold it caused in the same cycle as
// one), at most 8, then "… and K more".
std::string format_exit_line(const RunResult& r, const EventLog& log);

}  // namespace pedalwave::runtime
