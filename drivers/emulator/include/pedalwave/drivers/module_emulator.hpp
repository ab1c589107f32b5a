// Module emulator ("virtual robot" modules): answers as the robot's SEA modules would, on a CAN
// transport (socket-pair end or raw CAN socket) or on the far end of a serial line (pty master),
// with configurable fault injection (drivers/PROTOCOL.md §6).
//
// Behaviour of every emulated module j (node / ID j+1), as on a real bus (PROTOCOL.md §1.1, §6):
//  - Every frame occupies the bus for its wire time at the configured bit rate / baud
//    (BusTimingConfig): a frame read at host time `now` has arrived at the modules at
//    max(now, bus busy until) + its wire time. Answers are sent one after the other in bus order
//    (CAN: arbitration, lower id first; serial: ID order, each after its return delay), each when
//    its last bit would have left the wire.
//  - On the SYNC's arrival (CAN) or the broadcast sync-counter write's (serial) at time t:
//      plant.advance_to(t)          integrate with the commands applied so far
//      plant.measure(fb)            sample β, β̇, deflection, module status
//      stamp                        the module's own clock (offset, drift) at t
//    then (CAN) send the feedback (and, on a classic bus, the timing) frames, or (serial) keep the
//    sample for the next Sync Read.
//  - A command takes effect when it arrives: the plant is integrated up to the arrival with the
//    previous command, then the new one applies; the module remembers its tag and the arrival time
//    (by its clock) and reports both with its next sample.
//  - Command lifetime: if no valid command frame arrived for command_timeout_ns, the module drops
//    to safe torque (torque off, u = 0) at the next SYNC and reports kStatusTorqueOff and "no
//    command" until a command arrives. Modules start torque-off until their first command.
//  - Classic CAN: gains (kp, kd) come from the gains frame and stay until the next one.
// Fault injection (from SYNC number onset_sync on): reply latency, per-frame loss probability,
// per-frame bit-error probability (one payload bit flipped so the checksum fails), a module that
// stops answering, a module whose echoed counter repeats or goes backwards by one per SYNC.
//
// run(stop) loops on the calling thread until `stop` becomes true (checked at least every 1 ms);
// start it on its own thread. The emulator does not own the file descriptor.
#pragma once

#include <linux/can.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <vector>
#include <random>

#include "pedalwave/drivers/dynamixel.hpp"
#include "pedalwave/interface/io.hpp"
#include "pedalwave/drivers/wire.hpp"

namespace pedalwave::drivers {

// What the emulated modules drive. The real plant model is wired in by the simulation layer.
class ModulePlant {
 public:
  virtual ~ModulePlant() = default;
  // From now on, module j applies u_j = tau_j + kp_j (beta_ref_j − β_j) + kd_j (beta_dot_ref_j − β̇_j)
  // at its internal rate; a torque-off joint has tau = kp = kd = 0 (u = 0), cmd.torque_off means
  // every joint is off.
  virtual void apply(const Command& cmd) = 0;
  // Sample the current state: joints, beta, beta_dot, deflection and module status bits
  // (kStatusSaturated, kStatusOverTemp, kStatusEncoderFault); stamp/seq are set by the caller.
  virtual void measure(Feedback& out) = 0;
  // Integrate the plant up to absolute time t_ns (CLOCK_MONOTONIC) [ns].
  virtual void advance_to(std::int64_t t_ns) = 0;
  // The modules' own thread was held for ns (the machine paused it): time stood still for the
  // plant as well, so the next advance does not integrate that span. Default: integrate it.
  virtual void hold(std::int64_t /*ns*/) {}
  // false while module j does not answer (a plant-side fault, e.g. a scene's module_silent); the
  // emulator then sends nothing for it, as for its own FaultConfig::module[j].silent.
  virtual bool answering(int /*j*/) const { return true; }
};

enum class CounterFault : std::uint8_t {
  kNone = 0,
  kRepeat,     // the module keeps echoing the same counter
  kBackwards,  // the echoed counter decreases by one per SYNC
};

struct ModuleFault {
  bool silent = false;                         // the module stops answering
  CounterFault counter = CounterFault::kNone;  // rolling-counter fault
};

struct FaultConfig {
  std::int64_t reply_latency_ns = 0;  // delay from SYNC / Sync Read to the answer [ns]
  double frame_loss = 0.0;            // probability that an answer frame/packet is not sent [-]
  double bit_error = 0.0;             // probability that one payload bit of an answer is flipped [-]
  std::array<ModuleFault, kMaxJoints> module{};  // per joint, (N-1)
  std::uint64_t onset_sync = 1;       // faults act from this SYNC on (1 = the first) [-]
  // The modules' thread is held for thread_stall_ns after it has handled stall_first_sync SYNCs,
  // and again every stall_every_syncs SYNCs after that (0 = once): a machine that deschedules the
  // modules while the host's loop runs on (the VM's starved vCPU). The host's frames queue in the
  // meantime and are handled late, all at once, as the emulator answers them: a backlog of SYNCs.
  // 0 = never [ns, -].
  std::int64_t thread_stall_ns = 0;
  std::uint64_t stall_first_sync = 0;
  std::uint64_t stall_every_syncs = 0;
  std::uint32_t seed = 1;             // random generator seed [-]
};

// The bus the modules sit on, for wire times (drivers/bus_budget.hpp's frame sizes).
struct BusTimingConfig {
  bool wire = true;               // frames take their wire time (false: instantaneous)
  double bitrate = 1e6;           // CAN nominal bit rate [bit/s]
  double data_bitrate = 5e6;      // CAN FD data-phase bit rate [bit/s]
  int baud = 4'000'000;           // serial [bit/s], 8N1 (10 bits per byte)
  double return_delay_s = 20e-6;  // serial: each module's initial status return delay [s]
                                  // (register 9, 2 µs steps, at most 508 µs)
  // serial: a packet still incomplete this long after its last byte is dropped (its LEN was too
  // long, or the line broke mid-packet) [ns]
  std::int64_t inter_byte_timeout_ns = 1'000'000;
};

// SerialDevices (what sits on the serial bus): dynamixel.hpp.
struct XSeriesConfig {
  std::uint16_t model = 1020;         // the servos' model number (XM430-W350) [-]
  double torque_constant = 1.78;      // output torque per current [N·m/A] (XM430-W350 at 12 V:
                                      // 4.1 N·m stall at 2.3 A)
  double current_lsb = 2.69e-3;       // Goal / Present Current LSB [A]
  std::uint16_t current_limit = 1193; // register 38 [LSB]
  int sensor_id_offset = 100;         // sensor ID = servo ID + this [-]
};

struct EmulatorConfig {
  int joints = 5;                                 // modules, nodes/IDs 1…joints [-]
  SerialDevices serial_devices = SerialDevices::kPedalwave;
  XSeriesConfig x{};
  bool fd = false;                                // CAN: FD frame set (command groups, FD replies)
  std::int64_t command_timeout_ns = 500'000'000;  // command lifetime [ns] (> the host's stale_timeout)
  std::size_t trace_syncs = 0;                    // keep a SyncTrace of the first this many SYNCs [-]
  BusTimingConfig bus{};
  // Each module's free-running microsecond clock: reading at the emulator's first SYNC [µs] and
  // rate error [ppm] (a crystal: tens of ppm), (N-1).
  std::array<std::uint32_t, kMaxJoints> clock_offset_us{};
  std::array<double, kMaxJoints> clock_drift_ppm{};
  FaultConfig faults{};
};

// Spread for the CLI and tests: module j's clock offset drawn from `seed`, its drift spread
// evenly over [−drift_ppm, +drift_ppm] across the modules.
void spread_module_clocks(EmulatorConfig& cfg, double drift_ppm, std::uint32_t seed);

// Counters of the emulated side (read from any thread).
struct EmulatorStats {
  std::atomic<std::uint64_t> syncs{0};           // SYNCs handled [-]
  std::atomic<std::uint64_t> replies_sent{0};    // feedback frames / the cycle's status packets
                                                 // (answers to Sync / Bulk Read) sent [-]
  std::atomic<std::uint64_t> other_replies{0};   // serial: status packets answering anything else
                                                 // (Ping, Read, Write, errors: configuration) [-]
  std::atomic<std::uint64_t> replies_dropped{0}; // not sent because of injected loss/silence [-]
  std::atomic<std::uint64_t> replies_corrupted{0};  // sent with an injected bit error [-]
  std::atomic<std::uint64_t> commands{0};        // valid command frames / blocks latched [-]
  std::atomic<std::uint64_t> torque_off_cmds{0}; // of which torque-off [-]
  std::atomic<std::uint64_t> lifetime_expired{0};// module dropped to torque-off (timeout) [-]
  std::atomic<std::uint64_t> rx_errors{0};       // malformed / CRC-failed frames received [-]
  std::atomic<std::uint64_t> rx_lost{0};         // frames the kernel dropped, the receive queue full (SO_RXQ_OVFL) [-]
  std::atomic<std::uint64_t> keep_ups{0};        // plant advances between overdue SYNCs [-]
  std::atomic<std::uint64_t> self_stalls{0};     // this thread held ≥ 20 ms by the machine [-]
  std::atomic<std::int64_t> self_stall_ns{0};    // their total [ns]
  std::atomic<std::uint64_t> self_stall_holds{0};// of which the plant held (> 10 SYNC intervals) [-]
  std::atomic<std::uint64_t> first_off_sync{0};  // SYNCs handled when the first torque-off command
                                                 // reached a module that was on (0: none) [-]
  // The longest interval between two SYNC arrivals, and between two replies handed to the
  // kernel (host clock) [ns]: with the host's loop running, a long SYNC gap means the link (or
  // this thread) held the SYNCs, not the host.
  std::atomic<std::int64_t> sync_gap_max_ns{0};
  std::atomic<std::int64_t> reply_gap_max_ns{0};
  // SYNCs and commands stamped before the time the plant had already been integrated to (the
  // sample was taken, or the command applied, later than its stamp says), and the largest such
  // lag [-, ns]. 0 on a consistent emulator: every stamp the host sees is when it happened.
  std::atomic<std::uint64_t> stamped_behind{0};
  std::atomic<std::int64_t> stamped_behind_max_ns{0};
};

// The modules' state and fault logic, shared by the CAN and serial front ends.
class ModuleBank {
 public:
  ModuleBank(const EmulatorConfig& cfg, ModulePlant& plant);
  // One SYNC as the bank handled it (EmulatorConfig::trace_syncs; diagnostics of the bus tests):
  // its stamp, when this thread got to it, and how far the plant was already past the stamp
  // (kept at wall time while the SYNC was overdue: the sample is the plant's, that much later).
  struct SyncTrace {
    std::uint64_t sync = 0;
    std::int64_t stamp_ns = 0, handled_ns = 0, behind_ns = 0;
  };
  const std::vector<SyncTrace>& sync_trace() const { return trace_; }
  int joints() const { return cfg_.joints; }
  // SYNC with counter c arriving at time t: advance, check lifetimes, sample and stamp.
  void on_sync(std::uint8_t counter, std::int64_t t_ns) noexcept;
  // Joint j's command (gains only if has_gains), computed in cycle `tag`, arriving at t_ns: the
  // plant is advanced to t_ns with the previous command, then this one applies.
  void latch(int j, double tau, double beta_ref, double beta_dot_ref, bool has_gains, double kp,
             double kd, bool torque_off, std::uint8_t tag, std::int64_t t_ns) noexcept;
  void latch_gains(int j, double kp, double kd) noexcept;
  // Module j's command lifetime from now on [ns]; 0 = never expires (the serial modules' register
  // 10). Starts at EmulatorConfig::command_timeout_ns.
  void set_command_timeout(int j, std::int64_t ns) noexcept;
  std::int64_t command_timeout_ns(int j) const { return timeout_ns_[static_cast<std::size_t>(j)]; }
  // Between SYNCs (the front ends call it every loop turn, ≤ 1 ms apart): the world does not
  // wait for a stalled host. Once the SYNC is overdue (2 of its intervals since the plant last
  // moved) and while the modules still hold a command (within its lifetime of the last SYNC, and
  // not every output off: after a safe stop the plant waits for the host as before), the
  // plant is kept at wall time, so the next SYNC samples at once. Integrated lazily at that SYNC,
  // a 0.23 s host stall was answered ~6 ms late: three cycles of replies missed after it.
  void keep_up(std::int64_t now_ns) noexcept;
  // At the top of every loop turn (before input is handled): a turn that comes more than 20 ms
  // after the previous one ended (turns wait ≤ 1 ms) means the machine held this thread. If the
  // span is longer than 10 of the host's usual SYNC intervals (the median of the last 16), the
  // plant is told to hold() it rather than integrate it on the next SYNC. A real robot's world does not pause, but a simulated one
  // paused with its machine: integrating 0.2 s of plant afterwards (≈ 5 ms of work) answered
  // the following SYNCs late, three cycles of replies missed and a module named silent after a
  // whole-machine stall. No host integrates its model across 10 intervals without a sample (the
  // observer skips an interval beyond kMaxGap + 1.5 periods), so that hold is invisible to it.
  // A shorter span is integrated, as the real world would have moved: held, it made the modules'
  // clocks (which ran on) and the plant disagree by the span, and at 100 Hz a 30–50 ms machine
  // stall was an encoder_jump and a residual of 8–12 N·m (BusModel.AMachineStallAt100Hz…).
  void on_turn(std::int64_t now_ns) noexcept;
  // How long the front end's thread must now be held (FaultConfig::thread_stall_ns), once per
  // stall point; 0 = not now [ns].
  std::int64_t take_thread_stall() noexcept;
  void end_turn(std::int64_t now_ns) noexcept { last_turn_ns_ = now_ns; }
  // After on_sync: the sample, the counter module j echoes and its timing record.
  const Feedback& sample() const { return sample_; }
  std::uint8_t echo(int j) const { return echo_[static_cast<std::size_t>(j)]; }
  const wire::ModuleTiming& timing(int j) const { return timing_[static_cast<std::size_t>(j)]; }
  // Module j's clock at host time t_ns [µs] (wrapping), and the truth the tests compare the
  // host's clock estimate with: host time of the last sample / command application [ns].
  std::uint32_t module_clock_us(int j, std::int64_t t_ns) const noexcept;
  std::int64_t sample_host_ns() const { return sample_.stamp_ns; }
  std::int64_t applied_host_ns(int j) const { return applied_ns_[static_cast<std::size_t>(j)]; }
  bool faults_active() const { return syncs_ >= cfg_.faults.onset_sync; }
  bool silent(int j) const;
  bool lose() noexcept;     // draw: drop this answer?
  bool corrupt() noexcept;  // draw: flip a bit in this answer?
  std::uint32_t random() noexcept { return static_cast<std::uint32_t>(rng_()); }
  std::int64_t latency_ns() const { return faults_active() ? cfg_.faults.reply_latency_ns : 0; }
  const EmulatorConfig& config() const { return cfg_; }
  EmulatorStats& stats() { return stats_; }
  bool torque_off(int j) const { return off_[static_cast<std::size_t>(j)]; }
  // A front end handed a whole reply to the kernel at t_ns (counts it, keeps the longest gap).
  void on_reply_sent(std::int64_t t_ns) noexcept;

 private:
  void apply_now() noexcept;
  void start_clock(std::int64_t t_ns) noexcept;

  EmulatorConfig cfg_;
  ModulePlant& plant_;
  EmulatorStats stats_;
  std::mt19937 rng_;
  std::uint64_t syncs_ = 0;
  std::uint64_t next_stall_sync_ = 0;  // the SYNC count of the next injected thread stall [-]
  std::int64_t last_sync_ns_ = -1, last_reply_ns_ = -1;
  std::int64_t sync_interval_ns_ = 0;   // the last SYNC interval under 100 ms [ns]
  // The host's usual SYNC interval [ns]: the shortest of the last 16 intervals (a stall inflates
  // one interval, not this; a slower host rate shows within 16 SYNCs).
  std::int64_t usual_sync_ns_ = 0;
  std::array<std::int64_t, 16> recent_sync_ns_{};
  std::size_t recent_sync_next_ = 0;
  std::int64_t last_advance_ns_ = -1;   // host time the plant was last advanced to [ns]
  std::int64_t front_ns_ = -1;          // the latest host time the plant has been integrated to [ns]
  std::vector<SyncTrace> trace_;        // reserved to cfg_.trace_syncs
  void advance_plant(std::int64_t t_ns) noexcept;  // plant_.advance_to, counting stamps behind
  std::int64_t last_turn_ns_ = -1;      // end of the front end's previous loop turn [ns]
  Feedback sample_{};
  Command latched_{};                      // latest command per joint (applied at SYNC)
  std::array<std::int64_t, kMaxJoints> last_cmd_ns_{};
  std::array<std::int64_t, kMaxJoints> timeout_ns_{};  // command lifetime per module (0: never) [ns]
  std::array<bool, kMaxJoints> have_cmd_{};
  std::array<bool, kMaxJoints> off_{};      // joint is torque-off
  std::array<bool, kMaxJoints> cmd_off_{};  // latched command says torque-off
  std::array<std::uint8_t, kMaxJoints> echo_{};
  // Timing: clock origin (first SYNC), the last application per module, the records.
  bool clock_started_ = false;
  std::int64_t clock_origin_ns_ = 0;
  std::array<std::int64_t, kMaxJoints> applied_ns_{};
  std::array<std::uint8_t, kMaxJoints> applied_tag_{};
  std::array<bool, kMaxJoints> no_command_{};
  std::array<wire::ModuleTiming, kMaxJoints> timing_{};
};

// Wire-time bookkeeping of one bus segment: frames occupy it one after the other.
class WireClock {
 public:
  explicit WireClock(bool enabled) : on_(enabled) {}
  // A frame of `duration_ns` that can start no earlier than `earliest_ns`, and `gap_ns` after the
  // bus went quiet (a serial module's return delay): its end time.
  std::int64_t occupy(std::int64_t earliest_ns, std::int64_t duration_ns,
                      std::int64_t gap_ns = 0) noexcept {
    std::int64_t start = earliest_ns > busy_until_ ? earliest_ns : busy_until_;
    if (on_) start += gap_ns;
    busy_until_ = start + (on_ ? duration_ns : 0);
    return busy_until_;
  }
  bool enabled() const { return on_; }

 private:
  bool on_;
  std::int64_t busy_until_ = 0;
};

// CAN front end: reads SYNC / command / gains / FD command frames, sends feedback frames.
class CanModuleEmulator {
 public:
  CanModuleEmulator(int fd, const EmulatorConfig& cfg, ModulePlant& plant);
  void run(const std::atomic<bool>& stop);
  const EmulatorStats& stats() { return bank_.stats(); }
  ModuleBank& bank() { return bank_; }

 private:
  struct Pending {
    std::int64_t due_ns = 0;   // send time, CLOCK_MONOTONIC [ns]
    std::size_t size = 0;      // CAN_MTU or CANFD_MTU [bytes]
    canfd_frame frame{};
  };
  void handle(const canfd_frame& rec, std::size_t n, std::int64_t now) noexcept;
  void handle_classic(const can_frame& f, std::int64_t now) noexcept;
  void on_sync(std::uint8_t counter, std::int64_t now) noexcept;
  void enqueue(std::int64_t due, const canfd_frame& f, std::size_t size) noexcept;
  void flush(std::int64_t now) noexcept;
  std::int64_t wire_ns(std::size_t mtu, int len) const noexcept;  // frame's wire time [ns]

  int fd_;
  ModuleBank bank_;
  WireClock wire_;
  std::array<Pending, 256> queue_{};  // ring of answers waiting for their due time
  std::size_t head_ = 0, tail_ = 0;
  bool blocked_ = false;  // the last send found the transport full
};

// Serial (DYNAMIXEL 2.0) front end on a pty master or a tty. Each module has the control table of
// PROTOCOL.md §3.2 (dxl::kRegisters) and answers as a DYNAMIXEL does:
//  - Ping; Read and Write of any range within the table (dxl::check_read / check_write: access,
//    length and range errors; the EEPROM area only while torque enable = 0, else kErrAccess);
//    Sync Read / Sync Write and Bulk Read / Bulk Write of any range; Reboot (the RAM area back to
//    its initial values, torque off). Factory Reset, Reg Write, Action, Clear, Control Table
//    Backup, Fast Sync Read, Fast Bulk Read and unknown instructions: kErrInstruction (unicast; for
//    the fast reads the first listed module answers it).
//  - Status return level (register 68): 0 answers Ping only, 1 also the reads, 2 everything;
//    broadcast Read/Write never answered. Every status packet carries the alert bit while the
//    Hardware Error Status (register 70: over-temperature, encoder fault) is non-zero.
//  - The SYNC is any write of the sync counter (register 96): on_sync for the whole bank.
//  - A write touching the command block latches the block; writing torque enable = 0 turns the
//    output off at once; register 10 sets the command lifetime, register 9 the return delay.
//  - A CRC failure resynchronizes on the next byte; a packet still incomplete after
//    BusTimingConfig::inter_byte_timeout_ns of silence is dropped (both counted in rx_errors).
class SerialModuleEmulator {
 public:
  SerialModuleEmulator(int fd, const EmulatorConfig& cfg, ModulePlant& plant);
  void run(const std::atomic<bool>& stop);
  const EmulatorStats& stats() { return bank_.stats(); }
  ModuleBank& bank() { return bank_; }

 private:
  struct Pending {
    std::int64_t due_ns = 0;   // send time, CLOCK_MONOTONIC [ns]
    std::size_t len = 0;       // bytes still to send [bytes]
    std::size_t off = 0;       // bytes already sent [bytes]
    bool feedback = false;     // an answer to the cycle's Sync / Bulk Read [-]
    std::array<std::uint8_t, 256> bytes{};  // a status packet of the whole table: 191 bytes
  };
  enum class Kind : std::uint8_t { kPing, kRead, kOther };  // for the status return level
  void handle(std::int64_t now) noexcept;
  void enqueue(std::int64_t due, const std::uint8_t* p, std::size_t n, bool feedback) noexcept;
  void process(std::int64_t now) noexcept;
  void flush(std::int64_t now) noexcept;
  std::int64_t bytes_ns(std::size_t n) const noexcept;  // wire time of n bytes [ns]
  // The control table.
  // Devices d: 0 … joints − 1 the modules (or X-series servos) of joint d; kMaxJoints + j the
  // deflection sensor of joint j (X-series bus only).
  static constexpr int kSensor = kMaxJoints;
  int joint_of(std::uint8_t id) const noexcept;  // the device answering to `id`, -1: none
  std::span<const dxl::Register> registers(int d) const noexcept;
  std::uint16_t table_size(int d) const noexcept;
  void refresh(int d) noexcept;                  // live registers (torque, errors, feedback)
  std::uint16_t realtime_tick(int j, std::int64_t t_ns) const noexcept;  // register 120 [ms]
  std::uint8_t read_table(int d, std::uint16_t addr, std::uint16_t len) noexcept;  // → reply_
  std::uint8_t write_table(int d, std::uint16_t addr, std::span<const std::uint8_t> data,
                           std::int64_t now) noexcept;
  void latch_block(int j, bool off, std::int64_t now) noexcept;
  void latch_servo(int j, std::int64_t now) noexcept;  // X-series: goal current → torque
  void reset_ram(int d) noexcept;
  void sample_now(std::int64_t now) noexcept;  // X-series: a read samples (no sync counter)
  // Module j's status packet (error | alert, params) after its return delay, if its status return
  // level answers `kind`; `cycle`: the cycle's Sync / Bulk Read (loss, bit errors, latency
  // apply; counted in replies_sent, the rest in other_replies).
  void answer(int j, std::uint8_t err, std::span<const std::uint8_t> params, Kind kind,
              std::int64_t now, bool cycle) noexcept;

  int fd_;
  ModuleBank bank_;
  WireClock wire_;
  std::size_t packet_bytes_ = 0;  // bytes of the packet being handled (as received) [-]
  std::int64_t request_ns_ = 0;   // when the packet being handled arrived (its last byte) [ns]
  std::int64_t power_on_ns_ = 0;  // (set at construction) the servos' Realtime Tick counts from here
  std::array<std::uint8_t, 4096> rx_{};
  dxl::Packet pkt_{};
  std::size_t rx_len_ = 0;
  std::int64_t last_rx_ns_ = 0;   // when the last byte arrived [ns]
  bool resync_ = false;           // skipping the rest of a packet that failed its CRC
  bool x_ = false;                // an X-series bus
  std::uint8_t x_syncs_ = 0;      // the X-series bus's sample counter [-]
  std::array<std::array<std::uint8_t, dxl::x::kTableSize>, 2 * kMaxJoints> table_{};
  std::array<std::uint8_t, dxl::x::kTableSize> reply_{};
  std::array<Pending, 256> queue_{};
  std::size_t head_ = 0, tail_ = 0;
  bool blocked_ = false;  // the last write found the line full
};

}  // namespace pedalwave::drivers
