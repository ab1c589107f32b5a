// Internal: conversions between the runtime's plain structs, the idlc-generated C types and the
// subscriber-side messages (messages.hpp).
#pragma once

#include "Telemetry.h"
#include "pedalwave/interface/telemetry_sink.hpp"
#include "pedalwave/telemetry/config.hpp"
#include "pedalwave/telemetry/messages.hpp"

namespace pedalwave::telemetry::detail {

static_assert(pedalwave_msg_dds__JointState_Constants_MAX_JOINTS == runtime::kMaxJoints,
              "pedalwave/msg/JointState MAX_JOINTS must equal runtime::kMaxJoints");

// What every header written by one robot shares: the frame (the robot's name) and the offset
// from the robot's CLOCK_MONOTONIC to the stamp clock (0 for StampClock::kMonotonic).
struct HeaderContext {
  const char* frame_id = "";         // must outlive the messages filled with it
  std::int64_t offset_ns = 0;        // stamp = t_ns + offset_ns [ns]
};
void fill_header(const HeaderContext& h, std::int64_t t_ns, std_msgs_msg_dds__Header_& m) noexcept;
std::int64_t stamp_ns(const builtin_interfaces_msg_dds__Time_& t) noexcept;
builtin_interfaces_msg_dds__Time_ ros_time(std::int64_t ns) noexcept;

// A sequence viewing n entries of a (const) array; _release = false: Cyclone never frees it.
template <std::size_t M>
dds_sequence_double view(const std::array<double, M>& a, int n) noexcept {
  dds_sequence_double s{};
  s._maximum = static_cast<std::uint32_t>(n);
  s._length = static_cast<std::uint32_t>(n);
  s._buffer = const_cast<double*>(a.data());  // NOLINT: read-only use by dds_write
  s._release = false;
  return s;
}

// Number of per-joint entries actually published: `joints` clamped to [0, kMaxJoints].
int clamp_joints(int joints) noexcept;

// Robot side. The message's sequences point INTO `s` (no copy, no allocation): the message is
// valid only while `s` lives and is unchanged (dds_write serializes synchronously).
void fill(const runtime::CycleSample& s, const HeaderContext& h,
          pedalwave_msg_dds__JointState_& m) noexcept;
void fill(const runtime::CycleSample& s, const HeaderContext& h,
          pedalwave_msg_dds__ControllerState_& m) noexcept;
void fill(const runtime::CycleSample& s, const HeaderContext& h,
          pedalwave_msg_dds__ObserverState_& m) noexcept;
void fill(const runtime::CycleSample& s, const HeaderContext& h,
          pedalwave_msg_dds__LoopTiming_& m) noexcept;
// event_seq: the topic's running count (1, 2, ...).
void fill(const runtime::EventSample& e, const HeaderContext& h, std::uint64_t event_seq,
          pedalwave_msg_dds__ModeEvent_& m) noexcept;
void fill(const runtime::EventSample& e, const HeaderContext& h, std::uint64_t event_seq,
          pedalwave_msg_dds__FaultEvent_& m) noexcept;
// Published rates are rate_hz / decimation.
void fill(const runtime::RobotDescription& d, const Decimation& dec, const char* ros_namespace,
          pedalwave_msg_dds__RobotDescription_& m) noexcept;
void fill(const runtime::OperatorCommand& c, const char* target, const char* sender,
          pedalwave_msg_dds__OperatorCommand_& m) noexcept;

// Subscriber side (copies).
JointStateMsg decode(const pedalwave_msg_dds__JointState_& m);
ControllerStateMsg decode(const pedalwave_msg_dds__ControllerState_& m);
ObserverStateMsg decode(const pedalwave_msg_dds__ObserverState_& m);
LoopTimingMsg decode(const pedalwave_msg_dds__LoopTiming_& m);
ModeEventMsg decode(const pedalwave_msg_dds__ModeEvent_& m);
FaultEventMsg decode(const pedalwave_msg_dds__FaultEvent_& m);
DescriptionMsg decode(const pedalwave_msg_dds__RobotDescription_& m);
CommandAckMsg decode(const pedalwave_msg_dds__CommandAck_& m);
OperatorCommandMsg decode(const pedalwave_msg_dds__OperatorCommand_& m);
std::string decode(const std_msgs_msg_dds__String_& m);
RosJointStatesMsg decode(const sensor_msgs_msg_dds__JointState_& m);
DiagnosticArrayMsg decode(const diagnostic_msgs_msg_dds__DiagnosticArray_& m);
TfMsg decode(const tf2_msgs_msg_dds__TFMessage_& m);
// The runtime's command from the wire form (kind passed through unchecked: validate_command).
runtime::OperatorCommand to_command(const pedalwave_msg_dds__OperatorCommand_& m) noexcept;

}  // namespace pedalwave::telemetry::detail
