// The narrow hardware interface: plain structs that every driver (SocketCAN, serial servo bus,
// simulated plant) reads and writes, and the abstract Driver the runtime cycle calls.
// Fixed maximum sizes, so nothing in the cycle allocates (N links up to kMaxLinks).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>

#include "pedalwave/interface/sea.hpp"

namespace pedalwave::drivers {

inline constexpr int kMaxLinks = 64;
inline constexpr int kMaxJoints = kMaxLinks - 1;

// Per-joint status bits reported by a module (or synthesized by the driver).
enum StatusBit : std::uint16_t {
  kStatusOk = 0,
  kStatusMissing = 1u << 0,       // no fresh frame for this joint this cycle
  kStatusStale = 1u << 1,         // frame older than the cycle (late / repeated counter)
  kStatusOutOfOrder = 1u << 2,    // rolling counter went backwards
  kStatusChecksum = 1u << 3,      // CRC/checksum error on the frame carrying this joint
  kStatusSaturated = 1u << 4,     // module reports its torque limit active
  kStatusOverTemp = 1u << 5,      // module over-temperature
  kStatusEncoderFault = 1u << 6,  // module's own encoder diagnostics
  kStatusBusError = 1u << 7,      // bus-level error (bus-off, error-passive) affecting the joint
  kStatusTorqueOff = 1u << 8,     // module's output stage is disabled (safe torque off)
  kStatusLate = 1u << 9,          // the answer came after the read deadline, or an answer to an
                                  // older SYNC arrived: timing, not a module fault (with Missing)
  kStatusNoTiming = 1u << 10,     // fresh data, but the module's timing record did not arrive:
                                  // sample_ns / applied_* of this joint are unknown this cycle
  kStatusStaleFeedback = 1u << 11,  // the values are held from a sample more than the driver's
                                    // FeedbackSpec::stale_limit cycles old: a law evaluated on the
                                    // host is blind for this joint (with kStatusMissing)
};

// What a driver declares about its feedback (Driver::feedback_spec(), known after configuration):
// the resolution of each quantity as its sensors and wire deliver it, and how long it lets a
// host-side law act on a held sample. A field of 0 is not declared (continuous, or a driver that
// does not say): the observer then keeps its configured thresholds for it
// (runtime/observer/README.md §1.3 derives them from these).
struct FeedbackSpec {
  double beta_lsb = 0.0;        // motor angle β: one count [rad]
  double beta_dot_lsb = 0.0;    // motor rate β̇: one count [rad/s]
  double deflection_lsb = 0.0;  // spring deflection: one count [rad]
  double torque_lsb = 0.0;      // applied torque: one count of what the actuator is given (the
                                // command's quantization at the actuator) [N·m]
  // How far a reported sample time (Feedback::sample_ns) may be from when the device really
  // sampled [s]: 0 for modules that stamp their samples on their own clock; a device sampled when
  // the host's request reaches it, stamped by the host, is off by the request's delivery jitter.
  double sample_time_uncertainty = 0.0;
  // The driver evaluates a law on the host (a stock servo's current command): a joint whose last
  // sample is more than this many cycles old gets no torque from that law and is flagged
  // kStatusStaleFeedback [cycles]; 0 = the law runs in the modules, not the driver's concern.
  int stale_limit = 0;
};

// How the driver knows when the modules sampled and when they applied the commands.
enum class FeedbackTiming : std::uint8_t {
  kNominal = 0,  // samples on the loop's deadline grid, and the command written in a cycle acts
                 // from the next sample on, over a whole interval (the in-process plant: exact)
  kModule,       // per joint: sample_ns, applied_seq and applied_ns from the module's own clock
};

// Command::seq of "no command": a module that was never commanded (or whose command lifetime
// expired) applies zero torque. CommandHistory::find() maps it to an all-off command.
inline constexpr std::uint64_t kNoCommandSeq = ~0ull;
// Command::seq of "a command, but which one is not known" (the module's answer could not be
// placed among the host's cycles, answer_log.hpp): CommandHistory::find() has none, so the
// observer integrates no interval in which it acts.
inline constexpr std::uint64_t kUnknownSeq = ~0ull - 1;

// One joint's measurement, motor side (model-spec.md §1): what a module reports per sample — the
// own CAN feedback frame (can::FeedbackFrame) and the DYNAMIXEL feedback block (dxl::FeedbackBlock)
// carry one beside their protocol's extras — and what Feedback holds per joint.
struct JointSample {
  double beta = 0.0;          // motor output angle β [rad]
  double beta_dot = 0.0;      // motor output rate β̇ [rad/s]
  double deflection = 0.0;    // spring deflection β − α [rad]
  std::uint16_t status = 0;   // StatusBit mask (a module reports wire::kModuleStatusMask bits) [-]
};

// One cycle's measurements, motor side only (model-spec.md §1): the driver never sees link angles.
struct Feedback {
  int joints = 0;                                // N-1 joints present [-]
  std::uint64_t seq = 0;                         // driver's cycle counter [-]
  std::int64_t stamp_ns = 0;                     // acquisition time, CLOCK_MONOTONIC [ns]
  std::array<double, kMaxJoints> beta{};         // motor output angle β_j [rad], (N-1)
  std::array<double, kMaxJoints> beta_dot{};     // motor output rate β̇_j [rad/s], (N-1)
  std::array<double, kMaxJoints> deflection{};   // spring deflection β_j − α_j [rad], (N-1)
  std::array<std::uint16_t, kMaxJoints> status{};  // StatusBit mask per joint, (N-1)
  // ---- Timing (PROTOCOL.md §1.1); meaningful per joint only with timing == kModule ----
  FeedbackTiming timing = FeedbackTiming::kNominal;
  // When module j sampled β, β̇, deflection: its clock mapped to CLOCK_MONOTONIC by the driver's
  // clock estimate [ns], (N-1); 0 = unknown this cycle (kStatusNoTiming / missing).
  std::array<std::int64_t, kMaxJoints> sample_ns{};
  // The command module j applied last before its sample: Command::seq (kNoCommandSeq = output
  // off, no command) [-], and when it applied it (same clock as sample_ns) [ns], (N-1). Between
  // two samples the previous sample's applied command acts until applied_ns, this one after;
  // applied_ns = 0: when is unknown (the module's age field saturated, PROTOCOL.md §1.1).
  std::array<std::uint64_t, kMaxJoints> applied_seq{};
  std::array<std::int64_t, kMaxJoints> applied_ns{};
  // A late answer of module j that came this cycle (to an older SYNC: its data is not used): the
  // command it had applied and when [-, ns], (N-1); late_applied_ns = 0: none. Across a lost
  // sample it tells the observer when the gap's intermediate command took effect.
  std::array<std::uint64_t, kMaxJoints> late_applied_seq{};
  std::array<std::int64_t, kMaxJoints> late_applied_ns{};

  // Joint j's measurement (β, β̇, deflection, status) as one sample, and its four arrays set from one.
  JointSample joint(std::size_t j) const noexcept { return {beta[j], beta_dot[j], deflection[j], status[j]}; }
  void set_joint(std::size_t j, const JointSample& s) noexcept {
    beta[j] = s.beta, beta_dot[j] = s.beta_dot, deflection[j] = s.deflection, status[j] = s.status;
  }
};

// One cycle's commands. The module applies, at its own internal rate until the next command,
//   u_j = tau_j + kp_j (beta_ref_j − β_j) + kd_j (beta_dot_ref_j − β̇_j)   [N·m, output side]
// With kp = kd = 0 this is a pure torque command. Module-side PD exists because a host-side PD at
// 1 kHz is discretely unstable for the paper's gains and a small reflected inertia (README).
struct Command {
  int joints = 0;                                // N-1 [-]
  std::uint64_t seq = 0;                         // cycle counter of the cycle that produced it [-]
  std::array<double, kMaxJoints> tau{};          // feed-forward torque [N·m], (N-1)
  std::array<double, kMaxJoints> beta_ref{};     // motor angle set-point [rad], (N-1)
  std::array<double, kMaxJoints> beta_dot_ref{}; // motor rate set-point [rad/s], (N-1)
  std::array<double, kMaxJoints> kp{};           // module stiffness gain [N·m/rad], (N-1)
  std::array<double, kMaxJoints> kd{};           // module damping gain [N·m·s/rad], (N-1)
  bool torque_off = false;                       // safe torque off: every module output disabled
};

// The torque command c makes module j apply at (β, β̇): the module law (sea.hpp), 0 with torque
// off (before any limit the module applies).
constexpr double module_torque(const Command& c, std::size_t j, double beta, double beta_dot) noexcept {
  return c.torque_off ? 0.0
                      : module_law(c.tau[j], c.kp[j], c.beta_ref[j], c.kd[j], c.beta_dot_ref[j], beta, beta_dot);
}

// The commands the host wrote recently: a non-owning view of a ring indexed by seq % capacity
// (the runtime keeps it; Runtime::kCommandHistory entries). A single Command converts to a view of
// itself (the in-process plant's case: the last command acted over the whole interval).
class CommandHistory {
 public:
  CommandHistory(const Command& only) noexcept  // NOLINT: implicit on purpose
      : ring_(&only), capacity_(1), newest_(only.seq) {}
  CommandHistory(const Command* ring, int capacity, std::uint64_t newest_seq) noexcept
      : ring_(ring), capacity_(capacity), newest_(newest_seq) {}
  // The newest command written.
  const Command& last() const noexcept { return ring_[newest_ % static_cast<std::uint64_t>(capacity_)]; }
  // The command with Command::seq == seq (kNoCommandSeq: an all-off command), or nullptr if it is
  // no longer (or not yet) in the ring.
  const Command* find(std::uint64_t seq) const noexcept {
    if (seq == kNoCommandSeq) return &all_off();
    if (seq > newest_) return nullptr;
    const Command& c = ring_[seq % static_cast<std::uint64_t>(capacity_)];
    return c.seq == seq ? &c : nullptr;
  }
  static const Command& all_off() noexcept;

 private:
  const Command* ring_;
  int capacity_;
  std::uint64_t newest_;
};

namespace detail {
constexpr Command make_all_off() noexcept {
  Command c;
  c.joints = kMaxJoints;
  c.seq = kNoCommandSeq;
  c.torque_off = true;
  return c;
}
inline constexpr Command kAllOffCommand = make_all_off();
}  // namespace detail
inline const Command& CommandHistory::all_off() noexcept { return detail::kAllOffCommand; }

// Result of a driver call inside the cycle: never throws, never blocks past the given deadline.
enum class IoStatus : std::uint8_t {
  kOk = 0,        // every joint has a sample: fresh, or a late answer used (kStatusLate)
  kPartial,       // some joints missing/stale: see Feedback::status
  kTimeout,       // no joint has a sample (nothing arrived before the deadline)
  kBusError,      // bus-off / interface down
};

// Counters every driver keeps (monotonic, read by the runtime for telemetry and fault logic).
struct DriverCounters {
  std::uint64_t frames_tx = 0;
  std::uint64_t frames_rx = 0;
  std::uint64_t missing = 0;       // expected frames that never came
  std::uint64_t late = 0;          // frames that came after the cycle's deadline
  std::uint64_t late_used = 0;     // of those, used as their joint's (older) sample: no fresh
                                   // answer came, and the late one carries its sample time
  std::uint64_t duplicate = 0;     // same rolling counter twice
  std::uint64_t out_of_order = 0;  // rolling counter went backwards
  std::uint64_t checksum = 0;      // CRC / checksum failures
  std::uint64_t malformed = 0;     // wrong length / id / framing
  std::uint64_t bus_errors = 0;    // error frames (bus-off, error-passive, controller problems)
  std::uint64_t tx_dropped = 0;    // writes the kernel/bus refused (EAGAIN, ENOBUFS)
  std::uint64_t rx_dropped = 0;    // frames the kernel dropped from a full receive queue
                                   // (SocketCAN SO_RXQ_OVFL; serial: input overrun)
  std::int64_t rx_silence_max_ns = 0;  // the link's longest silence: the longest interval between
                                       // two receptions of anything (bytes, frames) [ns]
  // Held samples (drivers that evaluate a law on the host, FeedbackSpec::stale_limit > 0): joint-
  // cycles whose values were held from an earlier cycle's sample (missing, or a late answer used),
  // the oldest sample a law was evaluated on, and joint-cycles beyond the limit (no torque given).
  std::uint64_t held = 0;          // [joint-cycles]
  std::uint64_t held_age_max = 0;  // [cycles] (1: the previous cycle's sample)
  std::uint64_t stale_feedback = 0;  // [joint-cycles]
};

// Keeps DriverCounters::rx_silence_max_ns: call on_rx(t) whenever something arrived at t.
class SilenceMeter {
 public:
  void on_rx(std::int64_t t_ns, DriverCounters& c) noexcept {
    if (have_ && t_ns - last_ns_ > c.rx_silence_max_ns) c.rx_silence_max_ns = t_ns - last_ns_;
    if (!have_ || t_ns > last_ns_) last_ns_ = t_ns;
    have_ = true;
  }

 private:
  bool have_ = false;
  std::int64_t last_ns_ = 0;
};

// The one interface the runtime cycle uses. Everything is sized and opened before the loop
// (open()), the cycle only calls read()/write(), which never allocate, lock or throw.
class Driver {
 public:
  virtual ~Driver() = default;
  // Number of joints (N-1) this driver serves; fixed after construction.
  virtual int joints() const = 0;
  // Start of cycle: trigger acquisition (e.g. send SYNC) and gather feedback until deadline_ns
  // (CLOCK_MONOTONIC). now_ns is the cycle's wake-up time.
  virtual IoStatus read(std::int64_t now_ns, std::int64_t deadline_ns, Feedback& out) = 0;
  // Called by the loop just before read(): the cycle's scheduled time on the loop's deadline grid
  // (CLOCK_MONOTONIC). It differs from the wake-up time by the wake latency, which can exceed a
  // period on a loaded machine. A driver that simulates the robot in step with the loop uses it to
  // advance exactly the scheduled time; hardware drivers ignore it.
  virtual void begin_cycle(std::int64_t scheduled_ns) noexcept { (void)scheduled_ns; }
  // End of cycle: send commands (applied by the modules at the next SYNC / immediately).
  virtual IoStatus write(const Command& cmd) = 0;
  // Safe command on every exit path: torque off (or hold) sent before the bus is let go.
  virtual void safe_stop() = 0;
  virtual const DriverCounters& counters() const = 0;
  // Resolution and host-law staleness of the feedback (above); before the loop. Default: nothing
  // declared.
  virtual FeedbackSpec feedback_spec() const { return {}; }
};

}  // namespace pedalwave::drivers
