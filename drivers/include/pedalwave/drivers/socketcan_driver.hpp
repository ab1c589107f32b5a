// SocketCAN driver of the pedalwave CAN module protocol (can_protocol.hpp, PROTOCOL.md §2, §4).
//
// Transport: a raw CAN socket bound to an interface (open()), or — for tests and for kernels
// without PF_CAN — any already open file descriptor of a SOCK_SEQPACKET socket pair that carries
// raw `struct can_frame` (CAN_MTU bytes) / `struct canfd_frame` (CANFD_MTU bytes) records. Both go
// through the same read/write/decode code.
//
// Cycle (Driver contract): read() sends SYNC with the next 8-bit counter c, then gathers one
// feedback frame per joint (and on a classic bus one timing frame, PROTOCOL.md §1.1) until
// deadline_ns with non-blocking receives and ppoll() on the
// remaining time. Each frame is classified with the rolling counter (rolling_counter.hpp): only
// the first frame echoing c and received (kernel timestamp) before the deadline is used;
// duplicates, late frames (answers to older SYNCs, or received after the deadline), backwards
// counters, CRC failures and malformed frames are counted in DriverCounters and marked in
// Feedback::status of their joint (kStatusStale, kStatusOutOfOrder, kStatusChecksum). A joint
// without a fresh frame at the deadline takes the cycle's newest late answer, which carries its
// own sample time (late_sample.hpp, PROTOCOL.md §4: kStatusLate, counted in `late_used`); a joint
// with neither is kStatusMissing (counted in `missing`) and keeps its previous values. Error frames (bus-off, error-passive, controller problems) are counted in
// bus_errors and mark every joint kStatusBusError; read() then returns IoStatus::kBusError.
// write() sends the commands tagged with c (classic: one command frame per joint + one gains frame
// per cycle, round robin with changed gains first; FD: one command-group frame per 6 joints),
// which the modules apply on arrival. safe_stop() sends torque-off to every module.
// Timing (Feedback::timing = kModule): each module's sample stamp goes through its ModuleClock
// (lower bound: the SYNC's send time + its wire time) into Feedback::sample_ns; the applied
// command's tag maps back to the Command::seq written with it, its age to applied_ns. A joint
// whose data is fresh but whose timing record did not come is kStatusNoTiming (sample_ns = 0).
// An answer that comes after the deadline, or to an older SYNC, is kStatusLate (timing), not
// stale; duplicates stay kStatusStale and backward counters kStatusOutOfOrder (module faults).
// read()/write()/safe_stop() never allocate, lock, throw or block past the deadline.
#pragma once

#include <linux/can.h>
#include <sys/socket.h>

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "pedalwave/drivers/posix_util.hpp"
#include "pedalwave/drivers/can_protocol.hpp"
#include "pedalwave/interface/io.hpp"
#include "pedalwave/drivers/late_sample.hpp"
#include "pedalwave/drivers/module_clock.hpp"
#include "pedalwave/drivers/rolling_counter.hpp"

namespace pedalwave::drivers {

// What the bus speaks (driver.protocol): the pedalwave module protocol (PROTOCOL.md §2) or
// CANopen CiA 301/402 (PROTOCOL.md §7, canopen_driver.hpp).
enum class CanProtocol : std::uint8_t { kPedalwave, kCanOpen };
// CiA 402 mode the drives run in: cyclic synchronous torque (the host computes the whole torque:
// pd_placement host) or cyclic synchronous position (the drive's position loop is the module PD).
enum class CanOpenMode : std::uint8_t { kCst, kCsp };
struct CanOpenOptions {
  std::array<std::uint8_t, kMaxJoints> node{};  // node id of joint j, 1 … 127; 0 = j + 1
  CanOpenMode mode = CanOpenMode::kCst;
  double heartbeat_s = 0.05;          // producer heartbeat time set on every node (1017h) [s]
  double heartbeat_timeout_s = 0.15;  // consumer: a node without heartbeat this long is lost [s]
  double sdo_timeout_s = 0.2;         // one SDO answer at configuration [s]
  double boot_timeout_s = 2.0;        // boot-ups after NMT reset communication [s]
  // Synchronous window length set on every node (1007h) as a share of the SYNC period (1006h): a
  // drive sends no synchronous TPDO later than this after its SYNC, so every TPDO received before
  // the next SYNC answers this one. < 1, leaving the next cycle's RPDOs room before its SYNC; longer
  // than the read budget, so an answer after the read deadline is still sent (and used late) [-].
  double sync_window = 0.9;
  // CSP: the drives' position loop gains written at bring-up (2010h, 2011h; the module PD's k_p,
  // k_d: the controller's K_p, K_D); a Command with other gains changes them by SDO.
  std::array<double, kMaxJoints> csp_kp{}, csp_kd{};  // [N·m/rad], [N·m·s/rad]
};

struct SocketCanConfig {
  std::string ifname = "can0";  // interface for open() (e.g. can0, vcan0)
  int joints = 5;               // modules (joints) on the bus, nodes 1…joints [-]
  bool fd = false;              // CAN FD frame set (needs an FD-capable interface)
  double bitrate = 1e6;         // nominal bit rate, for the budget check [bit/s]
  double data_bitrate = 5e6;    // CAN FD data bit rate, for the budget check [bit/s]
  double period_s = 1e-3;       // cycle period, for the budget check [s]
  double max_load = 0.8;        // admissible bus load per cycle [-]
  CanProtocol protocol = CanProtocol::kPedalwave;
  CanOpenOptions canopen{};     // protocol kCanOpen only
};

// Options of a raw CAN socket.
struct CanSocketOptions {
  std::string ifname;                  // interface name
  bool fd_frames = false;              // CAN_RAW_FD_FRAMES
  std::span<const can_filter> filters; // CAN_RAW_FILTER (empty: receive everything)
  bool error_frames = true;            // CAN_RAW_ERR_FILTER: bus-off, error-passive, controller,
                                       // protocol, tx timeout, restarted
  bool timestamps = true;              // SO_TIMESTAMPNS + SO_RXQ_OVFL
  bool own_frames = false;             // CAN_RAW_RECV_OWN_MSGS: this socket's frames come back when
                                       // they have been sent (received with MSG_CONFIRM)
};

// Opens, configures and binds a non-blocking raw CAN socket; returns its fd. Throws
// std::system_error naming the step and the interface; on a kernel without PF_CAN the message
// says "this kernel has no PF_CAN; see the vcan VM test".
int open_can_socket(const CanSocketOptions& opt);

// True if socket(PF_CAN, SOCK_RAW, CAN_RAW) works on this kernel.
bool can_sockets_available() noexcept;

class SocketCanDriver final : public Driver {
 public:
  // Checks the bus budget (std::invalid_argument), opens cfg.ifname with filters for the feedback
  // ids 0x181…0x180+joints and error frames (std::system_error).
  static std::unique_ptr<SocketCanDriver> open(const SocketCanConfig& cfg);

  // Injected transport: takes ownership of `fd` (made non-blocking). Checks the budget.
  SocketCanDriver(int fd, const SocketCanConfig& cfg);
  ~SocketCanDriver() override;
  SocketCanDriver(const SocketCanDriver&) = delete;
  SocketCanDriver& operator=(const SocketCanDriver&) = delete;

  int joints() const override { return joints_; }
  IoStatus read(std::int64_t now_ns, std::int64_t deadline_ns, Feedback& out) override;
  IoStatus write(const Command& cmd) override;
  void safe_stop() override;
  const DriverCounters& counters() const override { return counters_; }

  std::uint8_t sync_counter() const { return sync_counter_; }  // counter of the last SYNC [-]
  int fd() const { return fd_; }
  const ModuleClock& clock(int j) const { return clocks_[static_cast<std::size_t>(j)]; }

 private:
  enum class Tx : std::uint8_t { kOk, kDropped, kDown };
  Tx transmit(const void* f, std::size_t size) noexcept;  // counts it as sent or dropped
  Tx send_classic(const can_frame& f) noexcept;
  Tx send_fd(const canfd_frame& f) noexcept;
  void note_tx(Tx t, bool& dropped, bool& down) noexcept;
  void drain(std::int64_t rt_minus_mono_ns) noexcept;
  void handle_frame(const canfd_frame& f, std::size_t nbytes, std::int64_t stamp_ns) noexcept;
  void handle_error_frame(const can_frame& f) noexcept;
  void handle_feedback(const can_frame& f, std::int64_t stamp_ns) noexcept;
  void handle_feedback_fd(const canfd_frame& f, std::int64_t stamp_ns) noexcept;
  void take_feedback(int j, const can::FeedbackFrame& fb, const wire::ModuleTiming* t,
                     std::int64_t stamp_ns) noexcept;
  void handle_timing(const can_frame& f, std::int64_t stamp_ns) noexcept;
  int pick_gains_joint(const Command& cmd) noexcept;

  int fd_ = -1;
  int joints_ = 0;
  bool fd_mode_ = false;
  DriverCounters counters_{};
  SilenceMeter silence_;
  std::uint64_t cycle_ = 0;         // host cycles (read() calls) [-]
  std::uint8_t sync_counter_ = 0;   // counter of the current SYNC [-]
  int fresh_count_ = 0;             // joints with a fresh frame this cycle [-]
  std::int64_t stamp_ns_ = 0;       // latest acquisition time of a fresh frame [ns]
  std::int64_t deadline_ns_ = 0;    // this cycle's read deadline, CLOCK_MONOTONIC [ns]
  bool bus_off_ = false;            // controller reported bus-off (until restarted)
  bool error_passive_ = false;      // controller reported error-passive (until active again)
  bool bus_error_cycle_ = false;    // an error frame arrived this cycle
  bool peer_closed_ = false;        // injected transport: the far end closed
  std::uint32_t rxq_ovfl_ = 0;      // last SO_RXQ_OVFL value [-]
  std::array<RollingCounterState, kMaxJoints> rc_{};
  std::array<std::uint16_t, kMaxJoints> status_{};   // this cycle's bits per joint
  std::array<JointSample, kMaxJoints> last_{};  // last fresh values per joint
  // Gains sent last (classic: gains frame round robin).
  std::array<double, kMaxJoints> sent_kp_{};
  std::array<double, kMaxJoints> sent_kd_{};
  std::array<bool, kMaxJoints> gains_sent_{};
  int gains_cursor_ = 0;
  alignas(cmsghdr) std::array<char, 128> cmsg_buf_{};
  // Timing: this cycle's records, the module clocks, tag → Command::seq, the SYNC's lower bound.
  std::array<wire::ModuleTiming, kMaxJoints> timing_{};
  std::array<bool, kMaxJoints> have_timing_{};
  std::array<LateSample, kMaxJoints> late_{};      // the newest late answer (and record) this cycle
  std::array<HandedOut, kMaxJoints> handed_{};     // the last sample time handed out
  std::array<ModuleClock, kMaxJoints> clocks_{};
  std::int64_t sync_wire_ns_ = 0;   // SYNC frame's wire time at the configured bit rate [ns]
  std::int64_t sync_lower_ns_ = 0;  // no module can have sampled before this [ns]
  detail::RealtimeOffset rt_offset_;  // the kernel stamps onto CLOCK_MONOTONIC
  // Each answer placed among the host's cycles (answer_log.hpp): the cycles' SYNC bounds and
  // commands, per joint the answers' track and this cycle's fresh answer's cycle.
  CycleLog log_;
  std::array<AnswerTrack, kMaxJoints> track_{};
  std::array<std::uint64_t, kMaxJoints> fresh_answered_{};
  std::array<bool, kMaxJoints> fresh_sure_{};
};

}  // namespace pedalwave::drivers
