// The fixed-rate loop: read → observe → control → write → publish, every period, on absolute
// deadlines; modes, faults, the safe stop, and the hand-off to telemetry through wait-free rings.
//
// How a daemon uses it (everything before run() may allocate and throw; run() is the RT part):
//
//   pedalwave::runtime::RuntimeConfig cfg;          // from config/: rt, stale_timeout, reactions…
//   cfg.rt = {.rate_hz = 1000, .priority = 80, .cpu = 1, .lock_memory = true,
//             .prefault_stack_bytes = 256 * 1024};
//   auto rt = std::make_unique<Runtime>(cfg, driver, controller, &observer);  // ~6 MB: heap
//   pedalwave::runtime::install_stop_signal_handlers();   // SIGINT, SIGTERM, SIGHUP, SIGQUIT
//   TelemetryConsumer consumer(*rt, {&dds_sink});   // non-RT thread: drains rings, logs events
//   consumer.start();
//   RunResult r;
//   std::thread loop([&] { r = rt->run(); });       // RT setup + loop on that thread
//   … operator commands: rt->post(cmd) from one thread …
//   loop.join();                                    // returns after SAFE_STOP
//   consumer.stop();                                // drains, prints the summary table
//
// Guarantees of run():
//   - Every exit (signal, request_stop, operator e-stop, fault with kSafeStop reaction, stale
//     sensors, NaN, an exception from a stage or the driver, the cycle limit, a failing RT setup)
//     ends with Driver::safe_stop() as the LAST call on the driver; the loop then returns.
//   - Inside the loop nothing allocates, locks, logs or throws (tests/runtime/core/no_alloc_test.cpp).
//   - One CycleSample per cycle goes into cycle_ring() (its overruns field counts the overruns of
//     the cycles before it, ring_drops the samples dropped before it); every mode change, newly
//     active fault class and operator-command outcome goes into event_ring() as an EventSample.
#pragma once

#include <atomic>
#include <cstdint>
#include <string>

#include "pedalwave/interface/io.hpp"
#include "pedalwave/runtime/histogram.hpp"
#include "pedalwave/runtime/loop_clock.hpp"
#include "pedalwave/runtime/modes.hpp"
#include "pedalwave/runtime/rt_setup.hpp"
#include "pedalwave/interface/sample.hpp"
#include "pedalwave/runtime/spsc_ring.hpp"
#include "pedalwave/interface/stages.hpp"
#include "pedalwave/interface/telemetry_sink.hpp"

namespace pedalwave::runtime {

using CycleRing = SpscRing<CycleSample, 1024>;     // ~1 s at 1 kHz
using EventRing = SpscRing<EventSample, 256>;
using CommandRing = SpscRing<OperatorCommand, 64>;

// CALIBRATING (DESIGN.md's modes): before READY, with every module torque-off, the loop averages
// each joint's deflection sensor over `duration` and takes the mean as the sensor's zero. With the
// motor free and at rest the spring carries no torque (the motor's equation I_r·β̈ = u − τ_s with
// u = 0 and β̈ = 0), so what the sensor reads is its own offset (mounting, magnet, drift). The
// offsets are subtracted from every later reading, before the observer and the controller see it.
// The window is `duration` of consecutive cycles at rest: a joint that moves (|β̇| > max_rate, or
// its deflection spreads over more than max_spread) starts it again. Refused, with a FAULT naming
// the joint, when the robot is not at rest within `timeout` or an offset is beyond max_offset (a
// sensor that far off is broken or mounted wrong, not to be zeroed away). duration 0: no
// CALIBRATING, zeros are 0.
struct CalibrationConfig {
  double duration = 0.0;     // averaging time [s]; 0 = off
  double timeout = 5.0;      // longest wait for `duration` at rest [s], ≥ duration
  double max_offset = 0.05;  // largest offset accepted [rad]
  double max_rate = 0.05;    // largest motor rate of a robot at rest [rad/s]
  double max_spread = 2e-3;  // largest max − min deflection during the average [rad]
};

struct RuntimeConfig {
  RtConfig rt;                            // rate, priority, affinity, mlockall, stack
  ClockMode clock = ClockMode::kRealtime; // kLockstep: deterministic, no sleeping
  std::int64_t lockstep_start_ns = 0;     // lockstep: time of the first deadline [ns]
  double read_budget = 0.5;               // driver read deadline = wake + budget·period [-], (0, 1]
  double stale_timeout = 0.02;            // feedback missing longer than this → kStaleData [s],
                                          // ≥ one period
  bool auto_start = false;                // READY → RUNNING in the first READY cycle in which every
                                          // joint has reported (no operator start)
  std::uint64_t max_cycles = 0;           // stop (safe stop) after this many cycles; 0 = no limit
  std::uint32_t overrun_fault_after = 0;  // this many consecutive overruns → kOverrun fault with
                                          // severity kStop; 0 = overruns are only counted
  int max_commands_per_cycle = 4;         // operator commands taken per cycle [-], 1..64
  CalibrationConfig calibration;          // zero the deflection sensors before READY
  ReactionTable reactions;                // what each verdict does
  RobotDescription description;           // published once; spring_stiffness gives tau_sea
};

// Throws std::invalid_argument naming the item, the value and the expected range; `scope` as
// validate(RtConfig) (kValues: nothing of this machine, e.g. its CPU count, is asked).
void validate(const RuntimeConfig& cfg, ValidateScope scope = ValidateScope::kThisMachine);

enum class ExitReason : std::uint8_t {
  kNone = 0,
  kCycleLimit,      // max_cycles reached
  kStopRequested,   // request_stop()
  kSignal,          // SIGINT / SIGTERM
  kEmergencyStop,   // operator kEmergencyStop
  kFault,           // a verdict / runtime check with reaction kSafeStop (see RunResult::fault)
};
const char* to_string(ExitReason r) noexcept;

struct RunResult {
  ExitReason reason = ExitReason::kNone;
  Mode final_mode = Mode::kUnconfigured;
  FaultClass fault = FaultClass::kNone;  // fault that stopped the loop (reason kFault)
  std::int16_t fault_joint = -1;         // its joint, −1 none
  int signal = 0;                        // signal number (reason kSignal)
  RtReport rt;                           // what the real-time setup got
  std::uint64_t cycles = 0;              // cycles run [-]
  std::uint64_t overruns = 0;            // [-]
  std::uint64_t skipped_periods = 0;     // [-]
  std::uint32_t max_skipped = 0;         // most periods skipped at once (one stall) [-]
  std::uint64_t cycle_drops = 0;         // CycleSamples dropped (ring full) [-]
  std::uint64_t event_drops = 0;         // EventSamples dropped (ring full) [-]
  int joints = 0;                        // N-1 [-]
  bool calibrated = false;               // CALIBRATING ran to READY
  std::array<double, drivers::kMaxJoints> deflection_zero{};  // offsets subtracted [rad]
};

// Process-wide stop flag set by SIGINT/SIGTERM/SIGHUP/SIGQUIT (async-signal-safe: a lock-free atomic store).
void install_stop_signal_handlers();
int pending_stop_signal() noexcept;   // 0 = none, else the signal number
void clear_stop_signal() noexcept;    // tests only

class Runtime {
 public:
  // Validates cfg (throws std::invalid_argument), sizes everything, and moves the mode machine
  // UNCONFIGURED → CONFIGURED. The driver must already be open. The object is large (rings and
  // histograms inside): allocate it with std::make_unique. observer may be null.
  Runtime(const RuntimeConfig& cfg, drivers::Driver& driver, Controller& controller,
          Observer* observer = nullptr);
  Runtime(const Runtime&) = delete;
  Runtime& operator=(const Runtime&) = delete;

  // Commands kept for the observer (drivers::CommandHistory): the modules name the command they
  // applied by its tag, at most 16 cycles back (the 4-bit tag of classic CAN).
  static constexpr int kCommandHistory = 16;

  // Applies cfg.rt to the calling thread (throws if require_rt and refused, after safe_stop()),
  // CONFIGURED → READY, then runs the loop until one of the exits above. Call once.
  RunResult run();

  // Any thread, also from a signal handler: ask the loop to stop (safe stop) at the next cycle.
  void request_stop() noexcept { stop_requested_.store(true, std::memory_order_relaxed); }

  // Operator mailbox, producer side: ONE non-real-time thread. false = mailbox full (dropped).
  bool post(const OperatorCommand& cmd) noexcept { return commands_.push(cmd); }

  // Consumer side of the telemetry rings: ONE non-real-time thread (the TelemetryConsumer).
  CycleRing& cycle_ring() noexcept { return cycles_; }
  EventRing& event_ring() noexcept { return events_; }
  const CycleRing& cycle_ring() const noexcept { return cycles_; }
  const EventRing& event_ring() const noexcept { return events_; }

  Mode mode() const noexcept { return mode_snapshot_.load(std::memory_order_relaxed); }
  const RuntimeConfig& config() const noexcept { return cfg_; }
  std::int64_t period_ns() const noexcept { return period_ns_; }
  // Lockstep only, from a stage (the real-time thread) inside run(): move the loop clock forward
  // as if the stage had computed for ns — simulations and tests use it to exercise overruns
  // deterministically. No-op in real-time mode.
  void lockstep_advance(std::int64_t ns) noexcept { clock_.advance(ns); }
  // Histograms and counters of the loop. Read only after run() has returned.
  const LoopMetrics& metrics() const noexcept { return metrics_; }

 private:
  struct StopDecision {
    bool stop = false;
    ExitReason reason = ExitReason::kNone;
    Verdict verdict;        // fault evidence (reason kFault)
    const char* text = "";  // static reason text
  };

  // Clock readings through one cycle, for its timing record [ns].
  struct Stamps {
    std::int64_t wake = 0, read = 0, observe = 0, control = 0, write = 0;
  };

  bool cycle(std::int64_t deadline, std::int64_t prev_deadline, std::int64_t wake) noexcept;
  void cycle_body(std::int64_t deadline, std::int64_t prev_deadline, std::int64_t wake,
                  StopDecision& stop);
  // The cycle's steps, in the order cycle_body() calls them.
  void start_record(std::int64_t deadline, std::int64_t wake) noexcept;
  void take_stop_requests(StopDecision& stop) noexcept;
  void read_feedback(std::int64_t deadline, Stamps& at);
  Verdict check_feedback(std::int64_t wake) const noexcept;
  void apply_operator_commands();
  Verdict observe(double t, double dt, Stamps& at);
  void publish_faults(const Verdict& rt, const Verdict& ov) noexcept;
  void control(double t, double dt, Stamps& at);
  void check_command(StopDecision& stop) noexcept;
  void write(Stamps& at);

  void calibrate(StopDecision& stop) noexcept;

  void take_operator_commands(StopDecision& stop) noexcept;
  void apply_operator_command(const OperatorCommand& c);
  void react(const Verdict& v, StopDecision& stop);
  void enter_safe_stop(const StopDecision& stop) noexcept;
  TransitionStatus set_mode(Mode to, const char* why, const Verdict* v = nullptr) noexcept;
  void push_event(Mode from, Mode to, const Verdict* v, const char* text) noexcept;
  void fill_measured(const drivers::Feedback& fb) noexcept;

  RuntimeConfig cfg_;
  drivers::Driver& driver_;
  Controller& controller_;
  Observer* observer_;
  int joints_ = 0;
  std::int64_t period_ns_ = 0;
  std::int64_t read_budget_ns_ = 0;
  std::int64_t stale_timeout_ns_ = 0;

  ModeMachine modes_;
  std::atomic<Mode> mode_snapshot_{Mode::kUnconfigured};
  std::atomic<bool> stop_requested_{false};
  LoopClock clock_{ClockMode::kLockstep, 0};

  // Cycle workspace (sized once).
  drivers::Feedback fb_{};
  drivers::Command cmd_{};
  std::array<drivers::Command, kCommandHistory> history_{};  // written commands, by seq % 16
  std::uint64_t newest_written_ = 0;                         // seq of the newest in history_
  CycleSample sample_{};
  std::array<std::int64_t, drivers::kMaxJoints> last_fresh_ns_{};  // last fresh frame per joint [ns]
  std::array<OperatorCommand, 64> pending_{};                        // commands taken this cycle
  int n_pending_ = 0;
  std::uint64_t seq_ = 0;
  std::int64_t running_since_ns_ = 0;  // deadline of the first RUNNING cycle [ns]
  std::int64_t cur_deadline_ = 0;      // this cycle's deadline [ns]
  bool held_ = false;                  // gait frozen (hold)
  std::uint32_t active_flags_ = 0;     // fault classes active last cycle (edge detection)
  std::uint32_t consecutive_overruns_ = 0;
  bool overrun_fault_pending_ = false;
  std::int32_t last_skipped_ = 0;
  bool auto_start_pending_ = false;    // cfg.auto_start, until READY with every joint heard
  std::array<bool, drivers::kMaxJoints> heard_{};  // a fresh reading seen from this joint
  int heard_count_ = 0;

  // CALIBRATING: running sums per joint, and the zeros found (0 until then).
  struct CalibrationSums {
    std::int64_t cycles = 0, needed = 0, timeout = 0, window = 0;
    struct Why {
      int joint = -1;
      double value = 0.0, threshold = 0.0;
      const char* text = nullptr;
    } why;
    std::array<std::int64_t, drivers::kMaxJoints> n{};
    std::array<double, drivers::kMaxJoints> sum{}, lo{}, hi{}, max_rate{};
  } cal_{};
  std::array<double, drivers::kMaxJoints> deflection_zero_{};

  LoopMetrics metrics_;
  RunResult result_;
  bool ran_ = false;

  CommandRing commands_;
  CycleRing cycles_;
  EventRing events_;
};

}  // namespace pedalwave::runtime
