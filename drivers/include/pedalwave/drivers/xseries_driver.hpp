// Serial driver mode for stock DYNAMIXEL X-series servos in current control plus a separate SEA
// deflection sensor per joint (drivers/PROTOCOL.md §3.6). SerialDriver runs it when
// SerialConfig::devices == SerialDevices::kXSeries (config: `driver: {type: serial,
// devices: x_series, …}`); it can also be used on its own over an injected fd (tests).
//
// Servo of joint j: ID j + 1; its sensor: ID j + 1 + sensor_id_offset.
// Configuration (configure(), before the loop; allocates, throws std::runtime_error naming the
// device, the register, the value found and the one expected): per servo a Read of 0 … 11 (model
// number 1020 XM430-W350 or 1030 XM430-W210, firmware, ID, baud rate, Operating Mode), Hardware
// Error Status 0, Torque Enable 0, Operating Mode 0 (current control) written with torque off
// (or, with set_operating_mode = false, a servo in another mode refused), return delay written,
// Current Limit (38) read, Goal Current 0, Bus Watchdog (98) = command_timeout in 20 ms steps
// (a servo that hears nothing that long stops by itself); per sensor model 0x5053, ID, baud,
// Hardware Error Status, return delay. Torque stays off until the first command without torque_off.
// Cycle: read() drains what is waiting (answers that missed the previous cycle's deadline: late;
// a joint without a fresh answer this cycle gets them, as the previous Bulk Read's sample,
// kStatusLate, `late_used`), sends one Bulk
// Read (0x92) of Realtime Tick … Present Position (120, 16 bytes) from every servo and the
// deflection (124, 2 bytes) from every sensor, gathers the 2J status packets until the deadline.
// write() evaluates the module law on the host from the last sample,
//   u = τ + kp (β_ref − β) + kd (β̇_ref − β̇),
// and sends one Sync Write (0x83) of Goal Current = u / k_t (102, 2 bytes, saturated at the
// servo's Current Limit), plus a Sync Write of Torque Enable (64) where a servo's torque changes.
// With kp = kd = 0 (the controller's pd_placement: host, which the daemon requires for this mode)
// the servo applies τ: a held torque, the observer's exact ZOH model. safe_stop(): Goal Current 0
// and Torque Enable 0 on every servo.
// Timing (Feedback::timing = kModule, times from the host's clock, PROTOCOL.md §3.6): a stock
// servo has no sync counter and no module clock in the pedalwave sense; it samples when the Bulk
// Read has arrived: sample_ns = the Bulk Read's send time + its wire time, no earlier than its
// write() returned. The command acts on arrival of the Sync Write: applied_ns = its send time +
// its wire time (no earlier than the write's return), applied_seq = the Command::seq of the last
// write() that went out before the sample.
// Held samples: a joint without a fresh answer keeps its last sample (age counted in cycles:
// DriverCounters::held, held_age_max); older than max_stale_cycles it is flagged
// kStatusStaleFeedback and write() gives its servo Goal Current 0 (the host's PD is blind).
// feedback_spec() declares the servos' and sensors' resolution for the observer's thresholds.
// read()/write()/safe_stop() never allocate, lock, throw or block past their deadline.
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "pedalwave/drivers/dxl_link.hpp"
#include "pedalwave/drivers/dynamixel.hpp"
#include "pedalwave/interface/io.hpp"
#include "pedalwave/drivers/serial_driver.hpp"

namespace pedalwave::drivers {

// What configure() found on joint j's servo and sensor.
struct XSeriesIdentity {
  std::uint16_t model = 0;           // servo model number (register 0) [-]
  std::uint8_t firmware = 0;         // servo firmware version (register 6) [-]
  std::uint8_t operating_mode = 0;   // Operating Mode (11) as found, before configuration [-]
  std::uint16_t current_limit = 0;   // Current Limit (38) [LSB]
  std::uint16_t sensor_model = 0;    // sensor model number (0) [-]
  std::uint8_t sensor_firmware = 0;  // sensor firmware version (2) [-]
};

// The X-series models the driver accepts: model number → name and Goal Current LSB [A]
// (ROBOTIS e-Manual control tables). nullptr / 0 for any other model.
const char* xseries_model_name(std::uint16_t model) noexcept;
double xseries_current_lsb(std::uint16_t model) noexcept;

// Where a servo's Realtime Tick (register 120: its millisecond counter, mod 32768) puts the sample
// it came with, against the host's time for it (PROTOCOL.md §3.6, "Which Bulk Read an answer
// is"). A status packet carries no cycle counter, so on a link that delivers late (a loaded
// host's pty, a USB adapter's latency timer) an answer to an older Bulk Read can arrive after this
// cycle's request and pass for this cycle's; the tick tells them apart to its resolution.
//   d = tick · 1 ms − t_host (mod 32.768 s), kept = min d over the samples taken when the host
//   said (two blocks of kBlock, so it follows the clocks' drift), e = d − kept:
//   a sample taken at t_host: 0 ≤ e < 1 ms (the tick's phase); taken δ later: ≈ δ … δ + 1 ms;
//   an older request's (m periods back): ≈ −m·period … −m·period + 1 ms.
// seed() before the loop (bracketed Reads of the tick at configuration) gives kept a start that
// no late answer has touched; place() is then meaningful. Allocation-free, O(1).
class XSeriesTickClock {
 public:
  static constexpr std::int64_t kTickNs = 1'000'000;
  static constexpr std::int64_t kWrapNs = std::int64_t{dxl::x::kTickWrap} * kTickNs;
  static constexpr int kBlock = 256;  // samples per block of the kept minimum [-]
  // A sample taken at t_ns reported tick: d into the kept minimum (also before seeded()).
  void learn(std::uint16_t tick, std::int64_t t_ns) noexcept;
  bool seeded() const noexcept { return seeded_; }
  // e [ns] for a sample reported with tick, against host time t_ns (0 … 1 ms: taken then).
  std::int64_t place(std::uint16_t tick, std::int64_t t_ns) const noexcept;

 private:
  std::int64_t d(std::uint16_t tick, std::int64_t t_ns) const noexcept;  // relative to ref_
  bool seeded_ = false;
  std::int64_t ref_ = 0;                  // the first d (absolute), all else relative to it [ns]
  std::int64_t cur_min_ = 0, prev_min_ = 0;  // this block's and the last block's minimum [ns]
  int count_ = 0;                         // samples in this block [-]
};

class XSeriesDriver final : public Driver, private DxlPacketSink {
 public:
  // Takes ownership of fd (a tty or pty slave in raw mode). Checks cfg (joints, sensor IDs clear
  // of the servos' and ≤ 252, torque constant > 0, return delay 0 … 508 µs) and the X-series bus
  // budget; std::invalid_argument naming the value otherwise.
  XSeriesDriver(int fd, const SerialConfig& cfg);
  ~XSeriesDriver() override;
  XSeriesDriver(const XSeriesDriver&) = delete;
  XSeriesDriver& operator=(const XSeriesDriver&) = delete;

  void configure(std::int64_t reply_timeout_ns = 50'000'000);
  const XSeriesIdentity& identity(int j) const { return identity_[static_cast<std::size_t>(j)]; }
  bool torque_on(int j) const { return torque_on_[static_cast<std::size_t>(j)]; }
  // The last Goal Current sent to joint j's servo [LSB].
  std::int16_t goal(int j) const { return goal_[static_cast<std::size_t>(j)]; }

  int joints() const override { return joints_; }
  IoStatus read(std::int64_t now_ns, std::int64_t deadline_ns, Feedback& out) override;
  IoStatus write(const Command& cmd) override;
  void safe_stop() override;
  const DriverCounters& counters() const override { return counters_; }
  // Present Position / Velocity LSBs, the sensor's deflection LSB, Goal Current LSB × k_t, and
  // SerialConfig::max_stale_cycles as the stale limit of the host-side PD.
  FeedbackSpec feedback_spec() const override;
  // Answers the servos' Realtime Tick placed: sampled ≥ 0.5 ms later than the host's time for
  // them (given no time), and answers to a Bulk Read before the previous one (dropped) [-].
  std::uint64_t tick_delayed() const { return tick_delayed_; }
  std::uint64_t tick_stale() const { return tick_stale_; }
  const XSeriesTickClock& tick_clock(int j) const { return tick_[static_cast<std::size_t>(j)]; }

 private:
  enum class Dev : std::uint8_t { kNone, kServo, kSensor };
  Dev device_of(std::uint8_t id, int& j) const noexcept;
  std::string name(int j, bool sensor) const;
  // A packet from the link (DxlPacketSink): an answer classified by when it came (before_request_).
  void on_packet(dxl::DxlStatus s, const dxl::Packet& p, std::int64_t stamp_ns) noexcept override;
  void handle_status(const dxl::Packet& p, std::int64_t stamp_ns, bool before_request) noexcept;
  bool send(const Command* cmd, std::int64_t until_ns) noexcept;
  std::vector<std::uint8_t> read_registers(int j, bool sensor, std::uint16_t addr,
                                           std::uint16_t len, std::int64_t timeout_ns);
  void write_registers(int j, bool sensor, std::uint16_t addr,
                       const std::vector<std::uint8_t>& data, std::int64_t timeout_ns);
  std::int64_t wire_ns(std::size_t bytes) const noexcept;
  void seed_tick(int j, std::int64_t reply_timeout_ns);

  int fd_ = -1;
  int joints_ = 0;
  int baud_ = 0;
  int sensor_offset_ = 100;
  double k_t_ = 1.78;
  bool set_mode_ = true;
  int stale_limit_ = 8;                // SerialConfig::max_stale_cycles [cycles]
  std::uint8_t return_delay_steps_ = 0;
  std::uint8_t watchdog_steps_ = 25;   // Bus Watchdog to set [20 ms]
  std::int64_t write_timeout_ns_ = 0;
  std::array<XSeriesIdentity, kMaxJoints> identity_{};
  std::array<double, kMaxJoints> lsb_{};           // Goal Current LSB per servo [A]

  DriverCounters counters_{};
  DxlLink link_;                     // the byte stream (shared with the pedalwave modules' driver)
  bool before_request_ = false;      // receiving what waited before this cycle's Bulk Read
  std::uint64_t cycle_ = 0;
  std::int64_t deadline_ns_ = 0;
  std::int64_t sample_ns_ = 0;       // this cycle's sample time (Bulk Read arrival) [ns]
  std::int64_t stamp_ns_ = 0;        // newest fresh reception this cycle [ns]
  int fresh_packets_ = 0;            // status packets of this cycle's Bulk Read received [-]
  std::array<bool, kMaxJoints> got_servo_{}, got_sensor_{};
  std::array<dxl::x::PresentValues, kMaxJoints> servo_{};   // this cycle's
  std::array<double, kMaxJoints> sensor_{};                 // this cycle's deflection [rad]
  std::array<std::uint16_t, kMaxJoints> alert_{};           // StatusBits from alert bits
  // Answers that came after the previous cycle's deadline, before this cycle's request: the
  // previous Bulk Read's, sampled at prev_sample_ns_ with prev_applied_* in effect.
  std::array<bool, kMaxJoints> late_servo_got_{}, late_sensor_got_{};
  std::array<dxl::x::PresentValues, kMaxJoints> late_servo_{};
  std::array<double, kMaxJoints> late_sensor_{};
  std::int64_t prev_sample_ns_ = 0;
  std::uint64_t prev_applied_seq_ = kNoCommandSeq;
  std::array<std::int64_t, kMaxJoints> prev_applied_ns_{};
  std::uint64_t sample_applied_seq_ = kNoCommandSeq;        // in effect at sample_ns_
  std::array<std::int64_t, kMaxJoints> sample_applied_ns_{};
  std::array<std::int64_t, kMaxJoints> handed_ns_{};        // sample time handed out last [ns]
  std::array<std::uint16_t, kMaxJoints> status_{};
  // The sample handed out last (what write() evaluates the law on).
  std::array<JointSample, kMaxJoints> last_{};  // (status unused: set per cycle in read())
  std::array<bool, kMaxJoints> have_sample_{};
  std::array<std::uint64_t, kMaxJoints> age_{};  // cycles since that sample's Bulk Read [-]
  // Commands: per servo whether its torque is on, the last goal, and what was applied when.
  std::array<bool, kMaxJoints> torque_on_{};
  std::array<std::int16_t, kMaxJoints> goal_{};
  std::array<std::uint8_t, kMaxJoints> goal_flags_{};
  std::uint64_t applied_seq_ = kNoCommandSeq;
  std::array<std::int64_t, kMaxJoints> applied_ns_{};

  std::array<std::uint8_t, 2 * kMaxJoints> ids_{};  // servos (0 … J−1), then sensors
  std::array<std::uint8_t, dxl::kMaxPacket> bulk_tx_{};
  std::size_t bulk_len_ = 0;
  std::int64_t bulk_wire_ns_ = 0;
  std::int64_t min_reply_ns_ = 0;  // wire time of the shortest status packet [ns]
  // Which Bulk Read an answer is (the servos' Realtime Tick): per servo its clock, the Bulk Read
  // (cycle_ numbering; 0: older than the previous one) its last answer belonged to (the sensor's
  // answer after it is the same Bulk Read's), and per joint whether this cycle's servo answer was
  // sampled later than the host can say.
  static constexpr int kTickSeedReads = 16;           // Reads of the tick at configuration [-]
  static constexpr std::int64_t kTickSlackNs = 500'000;  // beyond the tick's 1 ms [ns]
  std::array<XSeriesTickClock, kMaxJoints> tick_{};
  std::array<std::uint64_t, kMaxJoints> servo_req_{};
  std::array<bool, kMaxJoints> untimed_{};
  std::uint64_t tick_delayed_ = 0, tick_stale_ = 0;
  std::array<std::uint8_t, 3 * dxl::kMaxPacket> tx_{};
  std::array<std::uint8_t, kMaxJoints * 2> data_{};
  std::array<std::uint8_t, kMaxJoints> sel_ids_{};
};

}  // namespace pedalwave::drivers
