// Codec of the pedalwave CAN module protocol (drivers/PROTOCOL.md §2): a SYNC-driven cycle in the
// CANopen manner. Per cycle the host sends SYNC (rolling counter c); every module samples when the
// SYNC arrives and answers with its feedback and its timing record (the sample time by its own
// clock, the command it applied last and when) echoing c; then the host sends the commands
// (tagged with c), which the modules apply as they arrive.
//
//   id            frame                   dlc  content
//   0x080         SYNC                    2    counter c (8 bit), CRC-8
//   0x180 + node  feedback (module→host)  8    β, β̇, deflection (int16), status|c mod 16, CRC-8
//                 feedback (FD bus)       16   the same + applied tag, sample time, age, CRC-16
//   0x200 + node  command (classic)       8    τ, β_ref, β̇_ref (int16), flags|c mod 16, CRC-8
//   0x280 + g     command group (FD)      ≤64  6 joints × {τ, β_ref, β̇_ref, kp, kd}, c, CRC-16
//   0x300 + node  gains (classic)         8    kp, kd (uint16), c mod 16, CRC-8
//   0x380 + node  timing (classic bus)    8    sample time u32 µs, age u16, c|tag mod 16, CRC-8
// node = joint index + 1 (1…63); FD group g covers joints 6g … 6g+5.
//
// Every function is pure (no I/O), allocation-free and noexcept; each returns a CodecStatus.
// Decoders check id, length and checksum, in that order, and report the first failure.
#pragma once

#include <linux/can.h>

#include <array>
#include <cstdint>

#include "pedalwave/interface/io.hpp"
#include "pedalwave/drivers/wire.hpp"

namespace pedalwave::drivers::can {

inline constexpr canid_t kSyncId = 0x080;
inline constexpr canid_t kFeedbackBase = 0x180;   // + node
inline constexpr canid_t kCommandBase = 0x200;    // + node
inline constexpr canid_t kFdCommandBase = 0x280;  // + group
inline constexpr canid_t kGainsBase = 0x300;      // + node
inline constexpr canid_t kTimingBase = 0x380;     // + node (classic bus)
inline constexpr std::uint8_t kFdFeedbackLen = 16; // FD feedback frame payload [bytes]
inline constexpr int kMaxNode = kMaxJoints;       // nodes 1…63
inline constexpr int kFdJointsPerFrame = 6;       // joints per CAN FD command frame
inline constexpr int kFdJointBytes = 10;          // bytes per joint in an FD command frame
inline constexpr int kMaxFdGroups = (kMaxJoints + kFdJointsPerFrame - 1) / kFdJointsPerFrame;
inline constexpr std::uint8_t kClassicCounterMask = 0x0F;  // classic frames carry c mod 16

inline constexpr int node_of_joint(int joint) noexcept { return joint + 1; }
inline constexpr int joint_of_node(int node) noexcept { return node - 1; }

enum class CodecStatus : std::uint8_t {
  kOk = 0,
  kWrongId,       // identifier outside the frame type's range (or an RTR/error/extended frame)
  kWrongLength,   // DLC/len not the one the frame type requires
  kChecksum,      // CRC mismatch
  kBadField,      // a field holds an impossible value (e.g. joint count 0 or > 6)
  kClamped,       // (encoders) a value was saturated to the wire range; the frame is valid
  kNotFinite,     // (encoders) a value was NaN/Inf: sent as 0, command frames also torque-off
  kBadArgument,   // (encoders) node/group/count outside the protocol's range: no frame produced
};

// What a feedback frame carries: the module's measurement and the SYNC counter it answers.
struct FeedbackFrame {
  JointSample sample{};       // β, β̇, deflection, module StatusBits (saturated, over-temp,
                              // encoder, torque off)
  std::uint8_t counter = 0;   // echoed SYNC counter, mod 16 on classic frames [-]
};

// One joint's command (classic command frame; gains travel in the gains frame).
struct JointCommand {
  double tau = 0.0;           // feed-forward torque [N·m]
  double beta_ref = 0.0;      // motor angle set-point [rad]
  double beta_dot_ref = 0.0;  // motor rate set-point [rad/s]
  bool torque_off = false;    // safe torque off for this module
  std::uint8_t counter = 0;   // SYNC counter the command was computed in (mod 16) [-]
};

// One joint's module-side PD gains (classic gains frame).
struct JointGains {
  double kp = 0.0;            // stiffness gain [N·m/rad]
  double kd = 0.0;            // damping gain [N·m·s/rad]
  std::uint8_t counter = 0;   // SYNC counter (mod 16) [-]
};

// One joint's slot in a CAN FD command frame.
struct FdJointCommand {
  double tau = 0.0;           // feed-forward torque [N·m]
  double beta_ref = 0.0;      // motor angle set-point [rad]
  double beta_dot_ref = 0.0;  // motor rate set-point [rad/s]
  double kp = 0.0;            // stiffness gain [N·m/rad]
  double kd = 0.0;            // damping gain [N·m·s/rad]
};

// A whole CAN FD command frame (group g: joints 6g … 6g+count−1).
struct FdCommandGroup {
  int group = 0;                                           // g [-]
  int count = 0;                                           // joints in this frame, 1…6 [-]
  std::uint8_t counter = 0;                                // SYNC counter (8 bit) [-]
  bool torque_off = false;                                 // safe torque off for the group
  std::array<FdJointCommand, kFdJointsPerFrame> joint{};   // (count)
};

// Smallest valid CAN FD payload length (0…8, 12, 16, 20, 24, 32, 48, 64) ≥ n; 0 if n > 64.
std::uint8_t canfd_round_len(int n) noexcept;
// Payload length of an FD command frame carrying `count` joints (4 + 10·count, rounded up).
std::uint8_t fd_command_len(int count) noexcept;

// SYNC: data[0] = counter, data[1] = CRC-8 over (id LE, data[0]).
CodecStatus encode_sync(std::uint8_t counter, can_frame& out) noexcept;
CodecStatus decode_sync(const can_frame& in, std::uint8_t& counter) noexcept;

// Feedback of `node`. Encoder: kClamped/kNotFinite report saturation (frame still valid).
CodecStatus encode_feedback(int node, const FeedbackFrame& fb, can_frame& out) noexcept;
// Decoder: node from the id; on kChecksum, `node` still holds the node named by the id.
CodecStatus decode_feedback(const can_frame& in, int& node, FeedbackFrame& fb) noexcept;

// Timing record of `node` on a classic bus (0x380 + node): [0-3] sample time, [4-5] age,
// [6] bits 0-3 c mod 16 (the SYNC it answers), bits 4-7 applied tag mod 16, [7] CRC-8.
CodecStatus encode_timing(int node, const wire::ModuleTiming& t, std::uint8_t counter,
                          can_frame& out) noexcept;
CodecStatus decode_timing(const can_frame& in, int& node, wire::ModuleTiming& t,
                          std::uint8_t& counter) noexcept;

// Feedback of `node` on an FD bus (0x180 + node, 16 bytes, BRS): [0-6] as the classic feedback,
// [7] applied tag (8 bit), [8-11] sample time, [12-13] age, [14-15] CRC-16 over id + [0-13].
CodecStatus encode_feedback_fd(int node, const FeedbackFrame& fb, const wire::ModuleTiming& t,
                               canfd_frame& out) noexcept;
// On kChecksum, `node` still holds the node named by the id. kWrongLength for any other length.
CodecStatus decode_feedback_fd(const canfd_frame& in, int& node, FeedbackFrame& fb,
                               wire::ModuleTiming& t) noexcept;

// Classic command of `node`. A NaN/Inf value encodes torque-off (and returns kNotFinite).
CodecStatus encode_command(int node, const JointCommand& cmd, can_frame& out) noexcept;
CodecStatus decode_command(const can_frame& in, int& node, JointCommand& cmd) noexcept;

// Gains of `node`. Negative gains saturate to 0 (kClamped).
CodecStatus encode_gains(int node, const JointGains& g, can_frame& out) noexcept;
CodecStatus decode_gains(const can_frame& in, int& node, JointGains& g) noexcept;

// CAN FD command group. A NaN/Inf value in any slot sets torque-off for the group (kNotFinite).
CodecStatus encode_fd_command(const FdCommandGroup& grp, canfd_frame& out) noexcept;
CodecStatus decode_fd_command(const canfd_frame& in, FdCommandGroup& grp) noexcept;

// A CAN FD frame of payload length ≤ 8 viewed as a classic frame (modules on an FD bus send
// their 8-byte frames as FD frames). Returns false if in.len > 8.
bool fd_to_classic(const canfd_frame& in, can_frame& out) noexcept;

}  // namespace pedalwave::drivers::can
