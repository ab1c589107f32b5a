// The narrow interfaces the cycle calls (read → observe → control → write → publish). Concrete
// observers and controllers live in their own layers; executables adapt them to these.
//
// Every method here is called on the real-time thread: it must not allocate, lock, log, block or
// throw. The methods are deliberately NOT noexcept: if one throws anyway, the runtime catches the
// exception at the loop boundary and turns it into FaultClass::kException → safe stop, instead of
// std::terminate().
#pragma once

#include <array>
#include <cstdint>

#include "pedalwave/interface/io.hpp"
#include "pedalwave/interface/sample.hpp"
#include "pedalwave/interface/telemetry_sink.hpp"

namespace pedalwave::runtime {

// What the observer concludes about one cycle. Evidence (value/threshold) goes into the event.
struct Verdict {
  FaultClass fault = FaultClass::kNone;  // primary (most severe) fault class this cycle
  Severity severity = Severity::kInfo;   // kWarning / kDegrade / kStop (kInfo = healthy)
  std::int16_t joint = -1;               // isolated joint, 0-based; −1 none / not isolated
  double value = 0.0;                    // evidence: residual or measured value [unit of the test]
  double threshold = 0.0;                // evidence: threshold crossed [same unit]
  std::uint32_t flags = 0;               // every active class, bit (1 << FaultClass) [-]
  const char* text = nullptr;            // static string (never freed), may be null
};

// What the runtime does about a verdict.
enum class Reaction : std::uint8_t {
  kBySeverity = 0,  // use the per-severity default of the ReactionTable
  kContinue,        // keep walking, publish the fault
  kHold,            // freeze the gait and hold (Controller::hold), until the operator resumes
  kSafeStop,        // FAULT → Driver::safe_stop() (torque off) → SAFE_STOP, loop ends
};
const char* to_string(Reaction r) noexcept;

struct ReactionTable {
  Reaction on_info = Reaction::kContinue;
  Reaction on_warning = Reaction::kContinue;
  Reaction on_degrade = Reaction::kHold;
  Reaction on_stop = Reaction::kSafeStop;
  // Per-class override (index = FaultClass); kBySeverity = use the severity default above.
  std::array<Reaction, static_cast<std::size_t>(FaultClass::kCount)> by_class{};

  Reaction operator()(const Verdict& v) const noexcept {
    const auto i = static_cast<std::size_t>(v.fault);
    if (v.fault != FaultClass::kNone && i < by_class.size() && by_class[i] != Reaction::kBySeverity)
      return by_class[i];
    switch (v.severity) {
      case Severity::kInfo: return on_info;
      case Severity::kWarning: return on_warning;
      case Severity::kDegrade: return on_degrade;
      case Severity::kStop: return on_stop;
    }
    return Reaction::kSafeStop;
  }
};

// Everything a controller sees in one cycle.
struct CycleIo {
  const drivers::Feedback& fb;  // this cycle's measurements
  drivers::Command& cmd;        // on entry: last cycle's command with joints/seq of this cycle
                                // and torque_off = false; the stage writes every joint it drives
  CycleSample& sample;          // the cycle's telemetry record (fill alpha_d, pi, body, …)
  double t;                     // controller time since RUNNING [s] (on the deadline grid)
  double dt;                    // time since the previous cycle's deadline [s] (> period after an
                                // overrun skipped periods)
};

class Observer {
 public:
  virtual ~Observer() = default;
  // Before the loop starts (not real-time): forget all state.
  virtual void reset() {}
  // Every cycle, in every mode the loop runs (READY and RUNNING). cmds holds the commands written
  // in the last Runtime::kCommandHistory cycles; cmds.last() is the previous cycle's (torque_off
  // before the first). With FeedbackTiming::kModule the feedback names, per joint, which of them
  // the module applied and when. Fills residual, tau_ext, body,
  // forward_speed of the sample; returns the verdict (healthy: fault = kNone, severity = kInfo).
  virtual Verdict observe(const drivers::Feedback& fb, const drivers::CommandHistory& cmds, double t,
                          double dt, CycleSample& sample) = 0;
};

class Controller {
 public:
  virtual ~Controller() = default;
  // READY → RUNNING, in the cycle, right before the first control() (which gets t = 0).
  virtual void start(const drivers::Feedback& fb) = 0;
  // RUNNING and walking: compute this cycle's command (gait + adaptive + PD, limits last).
  virtual void control(const CycleIo& io) = 0;
  // RUNNING and held (operator "stop walking" or a kHold reaction): freeze the gait at its current
  // phase and hold position. Called instead of control() until resume().
  virtual void hold(const CycleIo& io) = 0;
  // Held → walking again (operator "start walking"); the next control() continues from the
  // frozen phase or restarts it, the controller's choice.
  virtual void resume(const drivers::Feedback& /*fb*/) {}
  // Operator kSetGait; validates against the controller's configured bounds. false = rejected.
  virtual bool set_gait(const OperatorCommand& /*cmd*/) { return false; }
};

}  // namespace pedalwave::runtime
