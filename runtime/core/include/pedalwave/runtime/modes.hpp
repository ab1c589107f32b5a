// The runtime's mode machine (DESIGN.md "Modes"):
//
//   UNCONFIGURED → CONFIGURED → (CALIBRATING) → READY → RUNNING → FAULT → SAFE_STOP
//
// Legal transitions (everything else is rejected with TransitionStatus::kIllegal, never thrown):
//   UNCONFIGURED → CONFIGURED
//   CONFIGURED   → CALIBRATING, READY, SAFE_STOP
//   CALIBRATING  → READY, FAULT, SAFE_STOP
//   READY        → CALIBRATING, RUNNING, FAULT, SAFE_STOP
//   RUNNING      → FAULT, SAFE_STOP (signal / e-stop / end of run); "stop walking" is a hold
//                  inside RUNNING, so every way out of RUNNING passes the safe stop
//   FAULT        → SAFE_STOP
//   SAFE_STOP    → (terminal: a new run needs a new Runtime)
// Same-mode "transitions" are kNoChange (not an error).
#pragma once

#include <cstdint>

#include "pedalwave/interface/sample.hpp"

namespace pedalwave::runtime {

enum class TransitionStatus : std::uint8_t { kOk = 0, kNoChange, kIllegal };
const char* to_string(TransitionStatus s) noexcept;

// True if from → to is in the table above.
bool transition_allowed(Mode from, Mode to) noexcept;

class ModeMachine {
 public:
  Mode mode() const noexcept { return mode_; }
  // Applies from → to if legal. Never throws, never allocates.
  TransitionStatus request(Mode to) noexcept {
    if (to == mode_) return TransitionStatus::kNoChange;
    if (!transition_allowed(mode_, to)) return TransitionStatus::kIllegal;
    mode_ = to;
    return TransitionStatus::kOk;
  }

 private:
  Mode mode_ = Mode::kUnconfigured;
};

}  // namespace pedalwave::runtime
