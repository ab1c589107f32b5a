// Internal: conversions between the runtime's plain structs, the idlc-generated C types and the
// subscriber-side messages (messages.hpp).
#pragma once

#include "Telemetry.h"
#include "pedalwave/runtime/telemetry_sink.hpp"
#include "pedalwave/telemetry/config.hpp"
#include "pedalwave/telemetry/messages.hpp"

namespace pedalwave::telemetry::detail {

static_assert(pedalwave_msg_dds__MAX_JOINTS == runtime::kMaxJoints,
              "IDL MAX_JOINTS must equal runtime::kMaxJoints");

// Number of per-joint entries actually published: `joints` clamped to [0, kMaxJoints].
int clamp_joints(int joints) noexcept;

// Robot side. The message's sequences point INTO `s` (no copy, no allocation): the message is
// valid only while `s` lives and is unchanged (dds_write serializes synchronously).
void fill(const runtime::CycleSample& s, pedalwave_msg_dds__JointState_& m) noexcept;
void fill(const runtime::CycleSample& s, pedalwave_msg_dds__ControllerState_& m) noexcept;
void fill(const runtime::CycleSample& s, pedalwave_msg_dds__ObserverState_& m) noexcept;
void fill(const runtime::CycleSample& s, pedalwave_msg_dds__LoopTiming_& m) noexcept;
void fill(const runtime::EventSample& e, pedalwave_msg_dds__ModeEvent_& m) noexcept;
void fill(const runtime::EventSample& e, pedalwave_msg_dds__FaultEvent_& m) noexcept;
// Published rates are rate_hz / decimation.
void fill(const runtime::RobotDescription& d, const Decimation& dec,
          pedalwave_msg_dds__RobotDescription_& m) noexcept;
void fill(const runtime::OperatorCommand& c, const char* sender,
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
// The runtime's command from the wire form (kind passed through unchecked: validate_command).
runtime::OperatorCommand to_command(const pedalwave_msg_dds__OperatorCommand_& m) noexcept;

}  // namespace pedalwave::telemetry::detail
