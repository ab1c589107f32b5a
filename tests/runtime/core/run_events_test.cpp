// The run's event log as the end-of-run report tells it: classification, the reaction taken,
// bounded memory, 1-based joints in every text, and an exit line that never says "no fault" when
// something happened.
#include <gtest/gtest.h>

#include <cstring>
#include <string>

#include "pedalwave/runtime/run_events.hpp"
#include "pedalwave/runtime/runtime.hpp"

namespace {

using namespace pedalwave::runtime;

constexpr std::int64_t kS = 1'000'000'000;

EventSample ev(std::uint64_t seq, Mode from, Mode to, const char* text) {
  EventSample e;
  e.seq = seq;
  e.t_ns = 5 * kS + static_cast<std::int64_t>(seq) * 1'000'000;  // 1 kHz, loop started at 5 s
  e.from = from;
  e.to = to;
  std::strncpy(e.text.data(), text, e.text.size() - 1);
  return e;
}
EventSample fault(std::uint64_t seq, FaultClass f, Severity s, std::int16_t joint, double value,
                  double threshold, const char* text) {
  EventSample e = ev(seq, Mode::kRunning, Mode::kRunning, text);
  e.fault = f;
  e.severity = s;
  e.joint = joint;
  e.value = value;
  e.threshold = threshold;
  return e;
}

// The events of the field run of the issue: start-up, a latched warning, an operator stop walking,
// the end of the run at the cycle limit.
EventLog field_run(const ReactionTable& table) {
  EventLog log;
  EventSample configured = ev(0, Mode::kUnconfigured, Mode::kConfigured, "configured");
  configured.t_ns = 4 * kS;
  log.add(configured, table);
  log.add(ev(0, Mode::kConfigured, Mode::kReady, "loop started"), table);
  log.add(ev(0, Mode::kReady, Mode::kRunning, "auto start"), table);
  log.add(fault(4512, FaultClass::kActuatorTorque, Severity::kWarning, 1, 0.031, 0.03,
                "torque residual"), table);
  log.add(ev(248100, Mode::kRunning, Mode::kRunning, "stop walking: gait frozen, holding"), table);
  log.add(ev(600000, Mode::kRunning, Mode::kSafeStop, "cycle limit reached"), table);
  return log;
}

TEST(RunEvents, ClassifiesAndGivesTheReactionTaken) {
  ReactionTable t;
  const EventLog log = field_run(t);
  const auto e = log.events();
  ASSERT_EQ(e.size(), 6u);
  EXPECT_EQ(e[0].kind, EventKind::kMode);
  EXPECT_FALSE(e[0].listed) << "routine start-up transitions are not listed";
  EXPECT_EQ(e[3].kind, EventKind::kWarning);
  EXPECT_EQ(e[3].reaction, EventReaction::kContinue);
  EXPECT_TRUE(e[3].listed);
  EXPECT_EQ(e[4].kind, EventKind::kOperator);
  EXPECT_EQ(e[4].reaction, EventReaction::kHold);
  EXPECT_TRUE(e[4].listed);
  EXPECT_EQ(e[5].reaction, EventReaction::kSafeStop);
  EXPECT_FALSE(e[5].listed) << "the end of the run is the exit line's reason";
  // Time origin: the READY transition; CONFIGURED came a second before it.
  EXPECT_DOUBLE_EQ(log.seconds(e[4].sample), 248.1);
  EXPECT_DOUBLE_EQ(log.seconds(e[0].sample), -1.0);

  // Degrade → hold by the default table; a per-class override wins.
  EXPECT_EQ(reaction_of(fault(1, FaultClass::kStaleData, Severity::kDegrade, 0, 1, 1, "x"), t),
            EventReaction::kHold);
  t.by_class[static_cast<std::size_t>(FaultClass::kStaleData)] = Reaction::kSafeStop;
  EXPECT_EQ(reaction_of(fault(1, FaultClass::kStaleData, Severity::kDegrade, 0, 1, 1, "x"), t),
            EventReaction::kSafeStop);
  // Rejected commands do nothing.
  EventSample rejected = ev(7, Mode::kRunning, Mode::kRunning, "stop walking rejected: not walking");
  rejected.severity = Severity::kWarning;
  EXPECT_EQ(classify(rejected), EventKind::kOperator);
  EXPECT_EQ(reaction_of(rejected, t), EventReaction::kNone);
}

TEST(RunEvents, ExitLineListsWarningsAndHoldsWithOneBasedJoints) {
  const EventLog log = field_run(ReactionTable{});
  RunResult r;
  r.reason = ExitReason::kCycleLimit;
  r.final_mode = Mode::kSafeStop;
  const std::string line = format_exit_line(r, log);
  EXPECT_EQ(line,
            "exit: cycle_limit, final mode SAFE_STOP, no stopping fault; 2 events: warning "
            "actuator_torque joint 2 (value 0.031, threshold 0.03) → continue; operator stop "
            "walking at 248.1 s → gait frozen, holding");
  EXPECT_EQ(line.find("no fault"), std::string::npos);
  const std::string one = format_event(log.events()[3], log);
  EXPECT_EQ(one, "[t 4.512 s, cycle 4512] warning actuator_torque joint 2 (value 0.031, threshold "
                 "0.03) severity warning: torque residual → continue");
}

TEST(RunEvents, TheStoppingFaultIsReportedOnceWithSafeStop) {
  ReactionTable t;
  EventLog log;
  log.add(ev(0, Mode::kConfigured, Mode::kReady, "loop started"), t);
  // A warning-by-table class that then stops the run (e.g. a NaN command: not sent whatever the
  // table says): the FAULT transition marks its evidence event.
  t.by_class[static_cast<std::size_t>(FaultClass::kImplausible)] = Reaction::kContinue;
  log.add(fault(10, FaultClass::kImplausible, Severity::kStop, 3, 0, 0, "non-finite command"), t);
  EventSample f = ev(10, Mode::kRunning, Mode::kFault, "non-finite command");
  f.fault = FaultClass::kImplausible;
  f.severity = Severity::kStop;
  f.joint = 3;
  log.add(f, t);
  log.add(ev(10, Mode::kFault, Mode::kSafeStop, "non-finite command"), t);
  const auto e = log.events();
  EXPECT_EQ(e[1].reaction, EventReaction::kSafeStop);
  EXPECT_FALSE(e[2].listed) << "the FAULT transition repeats the listed evidence";
  RunResult r;
  r.reason = ExitReason::kFault;
  r.final_mode = Mode::kSafeStop;
  r.fault = FaultClass::kImplausible;
  r.fault_joint = 3;
  const std::string line = format_exit_line(r, log);
  EXPECT_NE(line.find("fault implausible on joint 4; 1 event: fault implausible joint 4"),
            std::string::npos) << line;
  EXPECT_NE(line.find("→ safe stop"), std::string::npos) << line;
}

TEST(RunEvents, EmergencyStopIsListedAndNothingIsNoFault) {
  ReactionTable t;
  EventLog log;
  log.add(ev(0, Mode::kConfigured, Mode::kReady, "loop started"), t);
  RunResult r;
  r.reason = ExitReason::kCycleLimit;
  r.final_mode = Mode::kSafeStop;
  EXPECT_EQ(format_exit_line(r, log),
            "exit: cycle_limit, final mode SAFE_STOP, no stopping fault; no events (no warnings, "
            "holds or operator commands)");
  log.add(ev(20, Mode::kRunning, Mode::kSafeStop, "operator emergency stop"), t);
  r.reason = ExitReason::kEmergencyStop;
  const std::string line = format_exit_line(r, log);
  EXPECT_NE(line.find("1 event: operator emergency stop at 0.0 s (RUNNING → SAFE_STOP)"),
            std::string::npos) << line;
}

TEST(RunEvents, MemoryIsBoundedFirstAndLastKeptRestCounted) {
  ReactionTable t;
  EventLog log;
  const std::uint64_t n = 10'000;
  for (std::uint64_t k = 0; k < n; ++k)
    log.add(fault(k, FaultClass::kSaturation, Severity::kWarning, 0, 1, 1, "flapping"), t);
  const auto e = log.events();
  ASSERT_EQ(e.size(), EventLog::kHead + EventLog::kTail);
  EXPECT_EQ(log.total(), n);
  EXPECT_EQ(log.dropped(), n - e.size());
  EXPECT_EQ(e.front().sample.seq, 0u);
  EXPECT_EQ(e[EventLog::kHead - 1].sample.seq, EventLog::kHead - 1);
  EXPECT_EQ(e[EventLog::kHead].sample.seq, n - EventLog::kTail) << "the tail in order";
  EXPECT_EQ(e.back().sample.seq, n - 1);
  RunResult r;
  const std::string line = format_exit_line(r, log);
  EXPECT_NE(line.find("… and "), std::string::npos) << "at most 8 in the exit line";
  EXPECT_NE(line.find(std::to_string(log.dropped()) + " more events not kept"), std::string::npos);
}

}  // namespace

TEST(RunEvents, AFaultAndTheHoldItCausedAreOneEntryOfTheExitLine) {
  ReactionTable t;
  EventLog log;
  log.add(ev(0, Mode::kConfigured, Mode::kReady, "loop started"), t);
  log.add(fault(6308, FaultClass::kActuatorTorque, Severity::kDegrade, 3, 0.38, 0.03,
                "observer: actuator torque"), t);
  log.add(fault(6308, FaultClass::kActuatorTorque, Severity::kDegrade, 3, 0.38, 0.03,
                "fault reaction: gait frozen, holding"), t);
  RunResult r;
  r.reason = ExitReason::kCycleLimit;
  r.final_mode = Mode::kSafeStop;
  EXPECT_EQ(format_exit_line(r, log),
            "exit: cycle_limit, final mode SAFE_STOP, no stopping fault; 1 event: fault "
            "actuator_torque joint 4 (value 0.38, threshold 0.03) at 6.3 s → gait frozen, holding");
}
