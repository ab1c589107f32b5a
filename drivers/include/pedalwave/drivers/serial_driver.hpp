// Serial servo-bus driver: DYNAMIXEL Protocol 2.0 to the pedalwave modules (dynamixel.hpp,
// PROTOCOL.md §3, §4) over a tty in raw mode (termios), or an injected fd (pty for tests).
//
// Cycle (Driver contract): read() first parses what is already waiting (answers to older cycles:
// late / duplicate / out-of-order; a packet still incomplete from before is a short read, counted
// as malformed and dropped), then sends one buffer holding the broadcast Write of the cycle
// counter c to register 96 (the serial bus's SYNC) and the Sync Read (0x82) of the 8-byte
// feedback block at 120 from IDs 1…J, and gathers the J status packets until deadline_ns
// (ppoll on the remaining time). Status packets are checked (CRC-16, framing, id, length, error
// field) and classified with the rolling counter (8-bit echo of c). write() sends one Sync Write
// (0x83) of the 12-byte command block at 100 (tagged with c) to every module; safe_stop() sends
// it with the torque-off flag. A joint without a fresh answer takes the cycle's newest late one
// (its own sample time: late_sample.hpp, `late_used`); with neither it is `missing`
// (+ IoStatus::kTimeout/kPartial). CRC errors
// `checksum` (also a module-reported CRC error, error number 3), framing/length/id errors and
// short reads `malformed`.
// Timing (Feedback::timing = kModule): the feedback block carries each module's timing record
// (PROTOCOL.md §1.1); its sample stamp goes through the module's ModuleClock (lower bound: the
// sync-counter write's send time + its wire time), the applied command's counter maps back to
// the Command::seq written with it. Answers after the deadline or to older cycles: kStatusLate.
// RS-485 half-duplex assumption: the adapter switches direction itself and does not echo the
// host's own bytes (e.g. an FTDI/U2D2-style adapter with automatic direction control).
// read()/write()/safe_stop() never allocate, lock, throw or block past their deadline (write():
// write_timeout_ns).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "pedalwave/drivers/dxl_link.hpp"
#include "pedalwave/drivers/dynamixel.hpp"
#include "pedalwave/interface/io.hpp"
#include "pedalwave/drivers/late_sample.hpp"
#include "pedalwave/drivers/module_clock.hpp"
#include "pedalwave/drivers/rolling_counter.hpp"

namespace pedalwave::drivers {

class XSeriesDriver;

struct SerialConfig {
  std::string device = "/dev/ttyUSB0";  // tty for open()
  int baud = 4'000'000;                 // [bit/s], 8N1
  int joints = 5;                       // modules, IDs 1…joints [-]
  double period_s = 1e-3;               // cycle period, for the budget check [s]
  double return_delay_s = 20e-6;        // modules' return delay, for the budget check [s]
  double turnaround_s = 0.0;            // host turnaround per exchange, for the budget check [s]
  double max_load = 0.8;                // admissible bus occupation per cycle [-]
  std::int64_t write_timeout_ns = 200'000;  // longest write() waits for a full output queue [ns]
  // The modules' command lifetime, written to their register 10 at configuration [s] (1 ms steps)
  double command_timeout_s = 0.5;
  // What sits on the bus: pedalwave modules, or stock X-series servos in current control with a
  // deflection sensor per joint (PROTOCOL.md §3.6; the driver then runs XSeriesDriver).
  SerialDevices devices = SerialDevices::kPedalwave;
  // X-series only: output torque per current of the servos [N·m/A] (XM430-W350 at 12 V: 1.78),
  // sensor ID = servo ID + sensor_id_offset, and whether configuration may set the Operating
  // Mode to current control (0) with torque off (false: a servo in another mode is refused).
  double torque_constant = 1.78;
  int sensor_id_offset = 100;
  bool set_operating_mode = true;
  // X-series only: the host evaluates the PD (the controller's pd_placement: host); a joint whose
  // last sample is more than this many cycles old gets no torque and is flagged
  // kStatusStaleFeedback (the observer names it stale_feedback) [cycles].
  int max_stale_cycles = 8;
};

// What configure_modules() found on module j (joint j + 1, ID j + 1).
struct ModuleIdentity {
  std::uint16_t model = 0;     // model number (register 0) [-]
  std::uint8_t firmware = 0;   // firmware version (register 2) [-]
};

// The baud rates a port opens at (termios' standard rates) [bit/s]: open_serial_port refuses any
// other, and so does the daemon configuration's driver.baud, at its line.
inline constexpr std::array<int, 14> kSerialBauds = {9600,    19200,   38400,   57600,   115200,
                                                     230400,  460800,  500000,  921600,  1000000,
                                                     1500000, 2000000, 3000000, 4000000};
// kSerialBauds for messages: "9600, 19200, …, 4000000".
std::string serial_bauds_text();

// Opens `path` as a raw 8N1 tty at `baud` (non-blocking, no flow control, VMIN = VTIME = 0).
// Throws std::system_error / std::invalid_argument (a baud rate not in kSerialBauds) naming path
// and value.
int open_serial_port(const std::string& path, int baud);

class SerialDriver final : public Driver, private DxlPacketSink {
 public:
  // Checks the bus budget, opens cfg.device, configure_modules(). With cfg.devices == kXSeries
  // every call below goes to an XSeriesDriver (xseries_driver.hpp) on the same port.
  static std::unique_ptr<SerialDriver> open(const SerialConfig& cfg);
  // Injected transport (a pty slave, a tty opened elsewhere): takes ownership of fd.
  SerialDriver(int fd, const SerialConfig& cfg);
  ~SerialDriver() override;
  SerialDriver(const SerialDriver&) = delete;
  SerialDriver& operator=(const SerialDriver&) = delete;

  // Configuration (before the loop; allocates, throws): every module, by unicast Read / Write
  // (PROTOCOL.md §3.4): identified (model number 0x5057, firmware), its ID (7) and baud rate (8)
  // checked against the configuration, its Hardware Error Status (70) zero, torque off (64),
  // then its return delay (9) and command timeout (10) written and read back. A module that does
  // not answer or disagrees stops it: std::runtime_error naming the module (ID, joint), the
  // register, the value found and the value expected. reply_timeout_ns per try, 3 tries.
  void configure_modules(std::int64_t reply_timeout_ns = 50'000'000);
  const ModuleIdentity& identity(int j) const;
  // The X-series mode's driver (nullptr on a bus of pedalwave modules).
  XSeriesDriver* x_series() const noexcept { return x_.get(); }

  int joints() const override { return joints_; }
  IoStatus read(std::int64_t now_ns, std::int64_t deadline_ns, Feedback& out) override;
  IoStatus write(const Command& cmd) override;
  void safe_stop() override;
  const DriverCounters& counters() const override;
  // The wire's resolutions (wire.hpp: β, β̇, deflection, τ), no host law; X-series: its own.
  FeedbackSpec feedback_spec() const override;
  std::uint8_t sync_counter() const { return counter_; }
  const ModuleClock& clock(int j) const { return clocks_[static_cast<std::size_t>(j)]; }

 private:
  // A packet from the link (DxlPacketSink): a status packet classified by its rolling counter.
  void on_packet(dxl::DxlStatus s, const dxl::Packet& p, std::int64_t stamp_ns) noexcept override;
  void handle_status(const dxl::Packet& p, std::int64_t stamp_ns) noexcept;
  bool send_commands(const Command* cmd, bool all_off, std::int64_t until_ns) noexcept;
  void poll_overruns() noexcept;
  // One unicast request and its status packet from `id` (false: none within timeout_ns).
  std::vector<std::uint8_t> read_registers(int j, std::uint16_t addr, std::uint16_t len,
                                           std::int64_t timeout_ns);
  void write_registers(int j, std::uint16_t addr, const std::vector<std::uint8_t>& data,
                       std::int64_t timeout_ns);

  std::unique_ptr<XSeriesDriver> x_;    // X-series mode: everything goes there
  int baud_ = 0;
  std::uint8_t return_delay_steps_ = 0;  // return delay to set [2 µs]
  std::uint16_t command_timeout_ms_ = 0; // command lifetime to set [ms]
  std::array<ModuleIdentity, kMaxJoints> identity_{};

  int fd_ = -1;
  int joints_ = 0;
  std::int64_t write_timeout_ns_ = 0;
  DriverCounters counters_{};
  DxlLink link_;                    // the byte stream (shared with the X-series mode's driver)
  std::uint64_t cycle_ = 0;
  std::uint8_t counter_ = 0;        // cycle counter c [-]
  int fresh_count_ = 0;
  std::int64_t deadline_ns_ = 0;
  std::int64_t stamp_ns_ = 0;
  bool icount_ok_ = true;           // TIOCGICOUNT supported
  std::uint64_t overruns_ = 0;      // last kernel overrun count [-]
  std::array<RollingCounterState, kMaxJoints> rc_{};
  std::array<std::uint16_t, kMaxJoints> status_{};
  std::array<dxl::FeedbackBlock, kMaxJoints> last_{};
  std::array<std::uint8_t, kMaxJoints> ids_{};
  std::array<std::uint8_t, 64 + kMaxJoints> sync_tx_{};  // sync-counter write + Sync Read
  std::size_t sync_read_len_ = 0;
  std::array<std::uint8_t, dxl::kMaxPacket> tx_{};
  std::array<std::uint8_t, kMaxJoints * dxl::kCommandBlockSize> blocks_{};
  std::array<ModuleClock, kMaxJoints> clocks_{};
  std::array<LateSample, kMaxJoints> late_{};      // the newest late answer (and record) this cycle
  std::array<HandedOut, kMaxJoints> handed_{};     // the last sample time handed out
  std::int64_t sync_wire_ns_ = 0;   // the sync-counter write's wire time [ns]
  std::int64_t sync_lower_ns_ = 0;  // no module can have sampled before this [ns]
  // Each answer placed among the host's cycles (answer_log.hpp): the cycles' SYNC bounds and
  // commands, per joint the answers' track and this cycle's fresh answer's cycle.
  CycleLog log_;
  std::array<AnswerTrack, kMaxJoints> track_{};
  std::array<std::uint64_t, kMaxJoints> fresh_answered_{};
  std::array<bool, kMaxJoints> fresh_sure_{};
};

}  // namespace pedalwave::drivers
