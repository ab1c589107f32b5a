// The SocketCAN driver's CANopen master (driver.protocol: canopen; drivers/PROTOCOL.md §7).
//
// Bring-up (the constructor; blocking, throws std::runtime_error naming the node, its joint and the
// object): NMT reset communication to every node, wait for each configured node's boot-up;
// per node by SDO (canopen::SdoClient, expedited and segmented): read 1000h (a CiA 402 device),
// 1008h (name, a segmented upload), 608Fh:01/02, 6001h, 6076h (the units); map TPDO 1 = 6041h
// statusword + 6064h position actual + 6077h torque actual, TPDO 2 = 606Ch velocity actual + 6004h
// deflection (CiA 406 position value), RPDO 1 = 6040h controlword + 6071h target torque (CST) or
// + 607Ah target position + 60B2h torque offset (CSP), RPDO 2 = 60B1h velocity offset (CSP), all
// synchronous (transmission type 1); 1017h producer heartbeat; 6060h mode of operation; then NMT
// start and the CiA 402 state machine to Switched On (shutdown → switch on; a drive in Fault gets a
// fault reset first). An SDO abort is a refusal naming node, joint, object and the abort code.
//
// Cycle (Driver contract, allocation- and lock-free): read() sends SYNC, gathers every node's
// TPDO 1 and TPDO 2 until the deadline. A PDO carries no SYNC counter, so which SYNC a TPDO
// answers is made certain by the protocol: bring-up sets 1006h (communication cycle period) and
// 1007h (synchronous window length, CanOpenOptions::sync_window_s, shorter than the period) on
// every node, and a drive does not send a synchronous PDO outside its window (CiA 301). A TPDO
// received before this read's SYNC went out (queued after the previous read's deadline) therefore
// answers the previous SYNC: a late answer. As the own protocol does (late_sample.hpp, PROTOCOL.md
// §4), a joint without a fresh pair this cycle gets its late pair as an older sample at that
// SYNC's time (kStatusLate, counted in late_used) — the values are exact, only older — if no
// newer sample was handed out; a joint with neither is missing. "Before the next SYNC" holds for
// a late loop too: no SYNC goes out while the previous one's window is open (waited out before the
// read's deadline, or this read sends none: syncs_held()), and with the SYNC's echo a sample's
// time is when the SYNC was on the bus and a TPDO received before the echo is the previous one's.
//
// write() sends RPDOs whose controlword is enable operation (0x0F), or disable operation (0x07,
// the drive's output off) for Command::torque_off; the drives act on them at the next SYNC
// (FeedbackTiming::kModule: a sample at its SYNC reports the command the previous SYNC put in
// force, applied at that SYNC). CSP: a changed k_p / k_d
// goes to 2010h / 2011h by one expedited SDO download at a time between the PDOs.
// Heartbeat consumer: a node without heartbeat for heartbeat_timeout_s is lost; EMCY consumer: an
// emergency with a non-zero code (or a statusword in Fault) is a drive fault. Either is latched,
// named in fault_text() ("node 3 (joint 3): heartbeat lost …", "node 2 (joint 2): EMCY 2310h …"),
// and the joint's feedback is reported kStatusMissing (lost) / kStatusStale | kStatusTorqueOff
// (fault), which the runtime turns into its stale-data fault on that joint.
// safe_stop(): RPDO 1 with disable operation and zero targets to every node, then a SYNC.
#pragma once

#include <linux/can.h>

#include <array>
#include <cstdint>
#include <memory>
#include <string>

#include "pedalwave/drivers/posix_util.hpp"
#include "pedalwave/drivers/bus_budget.hpp"
#include "pedalwave/drivers/canopen.hpp"
#include "pedalwave/drivers/cia402.hpp"
#include "pedalwave/interface/io.hpp"
#include "pedalwave/drivers/socketcan_driver.hpp"

namespace pedalwave::drivers {

// SocketCanDriver (protocol kPedalwave) or CanOpenDriver (kCanOpen) on cfg.ifname.
std::unique_ptr<Driver> open_socketcan(const SocketCanConfig& cfg);

// Bus budget spec of a configuration (either protocol).
CanBusSpec can_bus_spec(const SocketCanConfig& cfg) noexcept;

class CanOpenDriver final : public Driver {
 public:
  // Opens cfg.ifname with filters for this master's COB-IDs and brings the nodes up.
  static std::unique_ptr<CanOpenDriver> open(const SocketCanConfig& cfg);
  // Injected transport (socket pair): takes ownership of `fd`; checks the budget, brings up.
  CanOpenDriver(int fd, const SocketCanConfig& cfg);
  ~CanOpenDriver() override;
  CanOpenDriver(const CanOpenDriver&) = delete;
  CanOpenDriver& operator=(const CanOpenDriver&) = delete;

  int joints() const override { return joints_; }
  IoStatus read(std::int64_t now_ns, std::int64_t deadline_ns, Feedback& out) override;
  IoStatus write(const Command& cmd) override;
  void safe_stop() override;
  const DriverCounters& counters() const override { return counters_; }
  // The drives' units after bring-up (608Fh, 6001h, 6076h: the coarsest joint's), and the sample
  // time's uncertainty: a PDO carries no time stamp, so a sample's time is the host's SYNC time —
  // taken before write(), a lower bound — and a loaded host's send path delays the SYNC by up to
  // about a millisecond (measured in the vcan VM: consistency errors of 6e-4 … 8e-4 rad at
  // 1 … 2 rad/s), as a host-stamped serial request does (the X-series driver declares the same).
  FeedbackSpec feedback_spec() const override;

  // The first drive fault / lost node, named; "" while none.
  const char* fault_text() const noexcept { return fault_text_.data(); }
  int fault_joint() const noexcept { return fault_joint_; }  // −1: none
  std::uint16_t emcy_code(int j) const { return emcy_[static_cast<std::size_t>(j)]; }
  bool lost(int j) const { return lost_[static_cast<std::size_t>(j)]; }
  cia402::State drive_state(int j) const;
  double torque_actual(int j) const { return torque_[static_cast<std::size_t>(j)]; }  // [N·m]
  std::uint64_t emcy_received() const { return emcy_count_; }
  const std::string& device_name(int j) const { return names_[static_cast<std::size_t>(j)]; }
  std::uint8_t node(int j) const { return node_[static_cast<std::size_t>(j)]; }
  // The SYNC's echo (a SocketCAN socket with CAN_RAW_RECV_OWN_MSGS, which open() sets): the time
  // the SYNC was on the bus, for the samples' time and for telling this SYNC's answers from the
  // previous one's. On by itself for such a socket; a socket pair's peer that loops the SYNC back
  // as the kernel does turns it on here (tests).
  bool sync_echo() const noexcept { return echo_; }
  void expect_sync_echo(bool on) noexcept { echo_ = on; }
  // The longest time between asking for a SYNC and its echo [ns], SYNCs whose echo came more than
  // 1 ms after, and echoes never received.
  std::int64_t sync_delay_max_ns() const noexcept { return sync_delay_max_ns_; }
  std::uint64_t syncs_delayed() const noexcept { return syncs_delayed_; }
  std::uint64_t sync_echoes_lost() const noexcept { return echo_lost_; }
  // Reads that sent no SYNC because the previous SYNC's synchronous window was still open (read()).
  std::uint64_t syncs_held() const noexcept { return syncs_held_; }
  // The clock offset that maps kernel stamps onto CLOCK_MONOTONIC (detail::RealtimeOffset): reads
  // that had to read it again (the thread preempted between the clock reads), and those without
  // a tight bracket in three tries (the previous offset used).
  const detail::RealtimeOffset& clock_offset() const noexcept { return rt_offset_; }
  // SYNC echoes whose kernel stamp was taken when this thread read them (ReceivedFrame::
  // stamped_at_read): that SYNC's samples and the command it put in force carry no time
  // (kStatusNoTiming; the observer bridges them) [-].
  std::uint64_t echoes_stamped_at_read() const noexcept { return echoes_stamped_at_read_; }
  // SYNCs whose time is the end of the frames this master sent ahead of them (by its send
  // times), later than the echo's stamp — their samples go out without a time — and the most it
  // moved one [-, ns].
  std::uint64_t syncs_after_frames() const noexcept { return syncs_after_frames_; }
  std::int64_t after_frames_max_ns() const noexcept { return after_frames_max_ns_; }

 private:
  enum class Tx : std::uint8_t { kOk, kDropped, kDown };
  Tx send(const can_frame& f) noexcept;
  // Bring-up helpers (not in the cycle).
  void bring_up();
  void send_blocking(const can_frame& f);
  bool receive_until(std::int64_t deadline_ns, can_frame& f);
  std::uint32_t sdo_upload(int j, std::uint16_t index, std::uint8_t sub, const char* what);
  std::string sdo_upload_text(int j, std::uint16_t index, std::uint8_t sub, const char* what);
  void sdo_download(int j, std::uint16_t index, std::uint8_t sub, std::uint32_t value, int bytes,
                    const char* what);
  void sdo_transfer(int j, can_frame req, std::uint16_t index, std::uint8_t sub, const char* what,
                    const std::string& value_text);
  std::string who(int j) const;
  // Cycle.
  void drain(std::int64_t rt_minus_mono_ns, bool before_sync) noexcept;
  void handle(const can_frame& f, std::int64_t stamp_ns, bool before_sync) noexcept;
  void on_sync_echo(std::int64_t stamp_ns, bool stamp_known) noexcept;
  // read()'s end: the feedback of what this read gathered, fresh or late.
  IoStatus finish_read(Feedback& out, Tx tx) noexcept;
  void note_fault(int j, const char* fmt, unsigned a, unsigned b, const char* text) noexcept;
  void send_gains() noexcept;

  int fd_ = -1;
  int joints_ = 0;
  SocketCanConfig cfg_;
  DriverCounters counters_{};
  SilenceMeter silence_;
  std::uint64_t cycle_ = 0;
  std::int64_t deadline_ns_ = 0;
  std::int64_t sync_wire_ns_ = 0, sync_lower_ns_ = 0;
  std::int64_t t_sync_ns_ = 0;  // when this read's SYNC was handed to the socket (its echo's stamp) [ns]
  std::int64_t wire_before_sync_ns_ = 0;  // the bus busy until then before the SYNC [ns]
  bool echo_ = false;          // the SYNC comes back (sync_echo())
  bool echo_pending_ = false;  // the last SYNC sent, its echo not yet received
  std::int64_t sync_delay_max_ns_ = 0;
  std::uint64_t syncs_delayed_ = 0, echo_lost_ = 0, syncs_held_ = 0;
  std::int64_t period_ns_ = 0, window_ns_ = 0;  // the SYNC period, its synchronous window (1007h) [ns]
  std::array<std::int64_t, 9> frame_wire_ns_{};  // a classic frame of n bytes on the wire [ns]
  std::int64_t wire_busy_ns_ = 0;  // the bus is busy with frames sent / seen until then [ns]
  bool bus_error_cycle_ = false, peer_closed_ = false, bus_off_ = false;
  std::array<std::int8_t, 128> joint_of_node_{};
  std::array<std::uint8_t, kMaxJoints> node_{};
  std::array<std::string, kMaxJoints> names_{};
  // Units per node.
  std::array<double, kMaxJoints> rad_per_inc_{}, defl_rad_per_inc_{}, nm_per_permille_{};
  // This cycle per joint.
  std::array<bool, kMaxJoints> got1_{}, got2_{};
  std::array<std::uint16_t, kMaxJoints> status_{};
  // A drive's TPDO contents in SI units.
  struct DriveValues {
    std::uint16_t statusword = 0;
    double beta = 0, beta_dot = 0, defl = 0, torque = 0;  // [rad], [rad/s], [rad], [N·m]
  };
  // TPDO 1 (t1) or TPDO 2 of joint j into v.
  void decode_tpdo(bool t1, const can_frame& f, std::size_t j, DriveValues& v) const noexcept;
  // Last values per joint.
  std::array<double, kMaxJoints> beta_{}, beta_dot_{}, defl_{}, torque_{};
  std::array<std::uint16_t, kMaxJoints> statusword_{};
  // Heartbeat / EMCY consumer.
  std::array<std::int64_t, kMaxJoints> last_hb_ns_{};
  std::array<bool, kMaxJoints> lost_{}, faulted_{};
  std::array<std::uint16_t, kMaxJoints> emcy_{};
  std::uint64_t emcy_count_ = 0;
  std::int64_t hb_timeout_ns_ = 0;
  std::array<char, 256> fault_text_{};
  int fault_joint_ = -1;
  // Commands: the seq written last (acts from the next SYNC) and the one the drives act on now.
  std::uint64_t written_seq_ = kNoCommandSeq, acting_seq_ = kNoCommandSeq, prev_acting_seq_ = kNoCommandSeq;
  std::int64_t prev_sync_ns_ = 0;  // the previous SYNC's lower bound [ns]
  bool sync_known_ = true, prev_sync_known_ = true;  // sync_lower_ns_ / prev_sync_ns_ are the bus times
  std::uint64_t echoes_stamped_at_read_ = 0, syncs_after_frames_ = 0;
  std::int64_t after_frames_max_ns_ = 0;
  bool written_ = false;
  // The SYNC sent by the previous read, for its late answers: its lower bound, and the command its
  // sample reports applied (seq, when) [ns].
  struct SyncRecord {
    std::uint64_t cycle = 0;  // 0: none yet
    std::int64_t lower_ns = 0;
    std::uint64_t applied_seq = kNoCommandSeq;
    std::int64_t applied_ns = 0;  // 0: when is unknown
    bool known = true;            // lower_ns is when the drives sampled (false: its echo's stamp
                                  // was taken at read, the sample's time is unknown)
  };
  SyncRecord last_sync_{}, prev_sync_{};
  detail::RealtimeOffset rt_offset_;  // the kernel stamps onto CLOCK_MONOTONIC
  // Late answers (to prev_sync_) per joint, and the SYNC of the sample handed out last.
  std::array<bool, kMaxJoints> late1_{}, late2_{};
  std::array<DriveValues, kMaxJoints> late_{};
  std::array<std::uint64_t, kMaxJoints> handed_cycle_{};
  // CSP gains by SDO: sent values, the transfer under way.
  canopen::SdoClient sdo_;
  std::array<double, kMaxJoints> sent_kp_{}, sent_kd_{}, want_kp_{}, want_kd_{};
  std::array<bool, kMaxJoints> kp_sent_{}, kd_sent_{};
  int sdo_joint_ = -1;
  bool sdo_kp_ = false;
  double sdo_value_ = 0;
  std::int64_t sdo_started_ns_ = 0;
  int gains_cursor_ = 0;
  std::uint32_t rxq_ovfl_ = 0;  // last SO_RXQ_OVFL value [-]
  alignas(cmsghdr) std::array<char, 128> cmsg_buf_{};
};

}  // namespace pedalwave::drivers
