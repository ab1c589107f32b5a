// The module emulator's CANopen personality (issue 14 item 3): every joint j is a CiA 301 node
// (node id cfg.node[j], default j + 1) with the CiA 402 drive profile (cyclic synchronous torque
// and position) and the SEA deflection as a CiA 406 encoder position value (6004h). The object
// dictionary is module_dictionary() below; drivers/canopen/pedalwave_module.eds describes the same
// objects (a test parses it and compares), drivers/PROTOCOL.md §7 lists them.
//
// Behaviour of each node, as a drive on a real bus:
//  - NMT: after power-on, NMT reset node or reset communication it sends its boot-up message
//    (0x700 + node, 0x00) and is pre-operational; NMT start → operational, stop → stopped,
//    enter pre-operational. Reset communication restores 1000h–1FFFh to their defaults, reset node
//    every object. SDOs are served in pre-operational and operational; PDOs only in operational.
//  - SDO server (expedited and segmented, canopen::SdoServer) on 0x600 + node / 0x580 + node.
//    PDO mappings follow CiA 301's procedure: a PDO's COB-ID must be invalid (bit 31) while its
//    mapping changes, the mapping's sub 0 must be 0 while entries are written; writing sub 0 = n
//    checks the n entries (existing, PDO-mappable objects, at most 64 bits): abort 06040041h /
//    06040042h otherwise.
//  - SYNC (0x080): every node samples the plant (ModuleBank::on_sync), actuates the synchronous
//    RPDOs received since the previous SYNC, and sends its valid synchronous TPDOs (transmission
//    type 1 … 240: every n-th SYNC) in arbitration order, each after the one before on the wire.
//  - RPDOs write the mapped objects; with transmission type 254/255 they act on arrival.
//  - CiA 402: 6040h drives cia402::drive_transition; the output is on only in Operation Enabled
//    while operational. 6060h = 10 (CST): u = 6071h target torque; 6060h = 8 (CSP):
//    u = 60B2h torque offset + kp (607Ah − β) + kd (60B1h − β̇) with kp = 2010h, kd = 2011h
//    (manufacturer objects, REAL32). Units: positions in increments, 608Fh:01 per revolution
//    (608Fh:02 = 1); velocities in increments/s; torques in ‰ of 6076h (mN·m); the deflection
//    in 6001h increments per revolution, two's complement in the UNSIGNED32 6004h.
//  - Heartbeat producer: 1017h ms (0 = off), the NMT state on 0x700 + node.
//  - EMCY (0x080 + node) and Fault when the plant reports over-temperature (4210h) or an encoder
//    fault (7305h), or at an injected fault; 1001h, 603Fh hold the error; fault reset (402
//    transition 15) sends the EMCY error reset (0000h) and clears them.
//  - A silent module (FaultConfig::module[j].silent, ModulePlant::answering) sends nothing: no
//    heartbeat, no PDO, no SDO answer.
#pragma once

#include <linux/can.h>

#include <array>
#include <atomic>
#include <cstdint>
#include <span>
#include <memory>
#include <string>
#include <vector>

#include "pedalwave/drivers/posix_util.hpp"
#include "pedalwave/drivers/canopen.hpp"
#include "pedalwave/drivers/cia402.hpp"
#include "pedalwave/drivers/module_emulator.hpp"

namespace pedalwave::drivers::canopen {

// CiA 301 data types (the EDS's DataType numbers).
enum class DataType : std::uint16_t {
  kInteger8 = 0x0002,
  kInteger16 = 0x0003,
  kInteger32 = 0x0004,
  kUnsigned8 = 0x0005,
  kUnsigned16 = 0x0006,
  kUnsigned32 = 0x0007,
  kReal32 = 0x0008,
  kVisibleString = 0x0009,
};
std::size_t size_of(DataType t) noexcept;  // bytes (a VISIBLE_STRING: 0, its length varies)
enum class Access : std::uint8_t { kRo, kRw, kConst };
const char* to_string(Access a) noexcept;  // "ro", "rw", "const" (the EDS's AccessType)

// One sub-index of the module's object dictionary. `object` is the CiA 301 object code of the
// index it belongs to (7 VAR, 8 ARRAY, 9 RECORD); `default_value`: the value after reset (a
// node-id dependent one is given for node 0 and `plus_node` says the node id is added: COB-IDs,
// 1018h:04 serial number); `text`: a VISIBLE_STRING's value.
struct ObjectEntry {
  std::uint16_t index;
  std::uint8_t sub;
  std::uint8_t object;  // 7, 8, 9
  const char* index_name;
  const char* name;
  DataType type;
  Access access;
  bool pdo;             // PDO-mappable
  std::uint32_t default_value;
  bool plus_node;
  const char* text;
};
std::span<const ObjectEntry> module_dictionary() noexcept;
// The module's EDS (CiA 306 INI text) generated from module_dictionary(); the shipped file
// drivers/canopen/pedalwave_module.eds is this text.
std::string module_eds();

// The objects and EMCY codes of the dictionary are canopen.hpp's (shared with the master).

struct CanOpenEmulatorConfig {
  std::array<std::uint8_t, kMaxJoints> node{};  // node id of joint j; 0 = j + 1
  std::uint32_t encoder_increments = 1u << 20;     // 608Fh:01 [inc/rev]
  std::uint32_t deflection_increments = 1u << 20;  // 6001h [inc/rev]
  std::uint32_t rated_torque_mnm = 2000;           // 6076h [mN·m]
  // An injected drive fault: node of joint emcy_joint goes to Fault with EMCY emcy_code at SYNC
  // number emcy_at_sync (−1 / 0: none).
  int emcy_joint = -1;
  std::uint64_t emcy_at_sync = 0;
  std::uint16_t emcy_code = 0x2310;  // continuous over-current (device output side)
  // A node whose SDO server aborts every download to this object (fault injection: a drive that
  // refuses a configuration): joint, index; −1 = none.
  int refuse_joint = -1;
  std::uint16_t refuse_index = 0;
  // A drive that powers up in Fault (error code emcy_code, kept over NMT resets): −1 = none.
  int fault_at_boot_joint = -1;
};

class CanOpenModuleEmulator {
 public:
  CanOpenModuleEmulator(int fd, const EmulatorConfig& cfg, const CanOpenEmulatorConfig& co,
                        ModulePlant& plant);
  // Sends the boot-up messages, then serves the bus until `stop`.
  void run(const std::atomic<bool>& stop);
  EmulatorStats& stats() { return bank_.stats(); }
  ModuleBank& bank() { return bank_; }
  // Node j's NMT and drive state as of the emulator's last turn (readable from any thread).
  NmtState nmt(int j) const {
    return static_cast<NmtState>(pub_nmt_[static_cast<std::size_t>(j)].load(std::memory_order_acquire));
  }
  cia402::State drive(int j) const {
    return static_cast<cia402::State>(pub_drive_[static_cast<std::size_t>(j)].load(std::memory_order_acquire));
  }
  std::atomic<std::uint64_t> emcy_sent{0};
  std::atomic<std::uint64_t> heartbeats_sent{0};
  std::atomic<std::uint64_t> sdo_served{0};
  // TPDOs not sent because their synchronous window (1007h) had closed when the drive got to them:
  // past the window length after their SYNC, or a newer SYNC came first (CiA 301).
  std::atomic<std::uint64_t> window_dropped{0};

 private:
  class NodeDictionary;
  struct Pending {
    std::int64_t due_ns = 0;
    can_frame frame{};
    bool pdo = false;  // a TPDO answering a SYNC (counted in replies_sent)
    std::int64_t window_end_ns = 0;  // not sent after this (its synchronous window); 0: none
  };
  void handle(const can_frame& f, std::int64_t now) noexcept;
  void on_sync(std::int64_t now) noexcept;
  // NMT reset node (whole_node) / reset communication; announce: send the boot-up message.
  void reset(int j, bool whole_node, std::int64_t now, bool announce) noexcept;
  void send(const can_frame& f, std::int64_t now, bool pdo = false, std::int64_t window_end_ns = 0) noexcept;
  void flush(std::int64_t now) noexcept;
  void heartbeats(std::int64_t now) noexcept;
  void refresh(int j) noexcept;                       // live values into the dictionary
  std::uint32_t write_value(int j, int entry, std::uint32_t v) noexcept;  // SDO write, checked
  void set_controlword(int j, std::uint16_t cw, std::int64_t now) noexcept;
  void fault(int j, std::uint16_t code, std::int64_t now) noexcept;
  void actuate(int j, std::int64_t now) noexcept;     // the drive's command into the bank
  void receive_pdo(int j, int pdo, const can_frame& f, std::int64_t now) noexcept;
  void apply_rpdos(int j, std::int64_t now) noexcept;
  bool node_silent(int j) const;
  std::int64_t wire_ns(int len) const noexcept;

  struct Node {
    std::uint8_t id = 0;
    NmtState nmt = NmtState::kPreOperational;
    cia402::State drive = cia402::State::kSwitchOnDisabled;
    std::uint16_t controlword = 0;
    std::int64_t next_heartbeat_ns = 0;
    bool over_temp = false, encoder = false;  // conditions already reported
    std::array<can_frame, 2> rpdo{};          // synchronous RPDOs waiting for the SYNC
    std::array<bool, 2> rpdo_pending{};
  };

  int fd_;
  CanOpenEmulatorConfig co_;
  ModuleBank bank_;
  WireClock wire_;       // the drives' frames, one after the other
  WireClock host_wire_;  // the host's frames (its transmit queue), one after the other
  std::uint64_t syncs_ = 0;
  std::array<Node, kMaxJoints> node_{};
  std::array<std::array<std::uint32_t, 64>, kMaxJoints> value_{};  // per node, per entry
  std::array<std::int8_t, 128> joint_of_node_{};
  // The law each drive applies now (torque actual is computed from it).
  std::array<double, kMaxJoints> u_tau_{}, u_kp_{}, u_kd_{}, u_ref_{}, u_vref_{};
  std::array<Pending, 512> queue_{};
  std::size_t head_ = 0, tail_ = 0;
  bool blocked_ = false;
  std::uint32_t rxq_ovfl_ = 0;  // last SO_RXQ_OVFL value [-]
  detail::RealtimeOffset rt_offset_;  // the kernel stamps onto CLOCK_MONOTONIC
  bool booted_ = false;
  std::array<std::atomic<std::uint8_t>, kMaxJoints> pub_nmt_{}, pub_drive_{};
  void publish() noexcept;  // node_[j].nmt / drive → pub_*
  std::vector<std::unique_ptr<NodeDictionary>> dict_;
  std::vector<std::unique_ptr<SdoServer>> sdo_;

 public:
  ~CanOpenModuleEmulator();
};

}  // namespace pedalwave::drivers::canopen
