#include "pedalwave/drivers/can_protocol.hpp"

#include <cstring>

#include "pedalwave/drivers/crc.hpp"
#include "pedalwave/drivers/wire.hpp"

namespace pedalwave::drivers::can {
namespace {

using wire::get_i16;
using wire::get_u16;
using wire::put_i16;
using wire::put_u16;

constexpr canid_t kFlagMask = CAN_EFF_FLAG | CAN_RTR_FLAG | CAN_ERR_FLAG;

// CRC-8 over the 11-bit id (2 bytes, little-endian) followed by `n` data bytes.
std::uint8_t crc8_frame(canid_t id, const std::uint8_t* data, std::size_t n) noexcept {
  const std::uint8_t idb[2] = {static_cast<std::uint8_t>(id & 0xFFu),
                               static_cast<std::uint8_t>((id >> 8) & 0x07u)};
  std::uint8_t reg = crc8_j1850_update(kCrc8Init, idb, 2);
  reg = crc8_j1850_update(reg, data, n);
  return crc8_j1850_final(reg);
}

std::uint16_t crc16_frame(canid_t id, const std::uint8_t* data, std::size_t n) noexcept {
  const std::uint8_t idb[2] = {static_cast<std::uint8_t>(id & 0xFFu),
                               static_cast<std::uint8_t>((id >> 8) & 0x07u)};
  return crc16_ccitt(data, n, crc16_ccitt(idb, 2));
}

void clear(can_frame& f) noexcept { std::memset(&f, 0, sizeof f); }

// Encoder outcome from the accumulated quantization flags.
CodecStatus from_flags(std::uint8_t flags) noexcept {
  if (flags & wire::kQuantNotFinite) return CodecStatus::kNotFinite;
  if (flags & wire::kQuantClamped) return CodecStatus::kClamped;
  return CodecStatus::kOk;
}

// Common checks of an 8-byte classic frame with id base + node (1…63) and CRC-8 in data[7].
CodecStatus check_classic(const can_frame& in, canid_t base, int& node) noexcept {
  if (in.can_id & kFlagMask) return CodecStatus::kWrongId;
  const canid_t id = in.can_id & CAN_SFF_MASK;
  if (id < base + 1 || id > base + static_cast<canid_t>(kMaxNode)) return CodecStatus::kWrongId;
  node = static_cast<int>(id - base);
  if (in.len != 8) return CodecStatus::kWrongLength;
  if (crc8_frame(id, in.data, 7) != in.data[7]) return CodecStatus::kChecksum;
  return CodecStatus::kOk;
}

bool node_ok(int node) noexcept { return node >= 1 && node <= kMaxNode; }

}  // namespace

std::uint8_t canfd_round_len(int n) noexcept {
  static constexpr std::uint8_t kLens[] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64};
  for (std::uint8_t l : kLens)
    if (l >= n) return l;
  return 0;
}

std::uint8_t fd_command_len(int count) noexcept {
  return canfd_round_len(4 + kFdJointBytes * count);
}

// ---- SYNC ---------------------------------------------------------------------------------------
CodecStatus encode_sync(std::uint8_t counter, can_frame& out) noexcept {
  clear(out);
  out.can_id = kSyncId;
  out.len = 2;
  out.data[0] = counter;
  out.data[1] = crc8_frame(kSyncId, out.data, 1);
  return CodecStatus::kOk;
}

CodecStatus decode_sync(const can_frame& in, std::uint8_t& counter) noexcept {
  if ((in.can_id & kFlagMask) || (in.can_id & CAN_SFF_MASK) != kSyncId) return CodecStatus::kWrongId;
  if (in.len != 2) return CodecStatus::kWrongLength;
  if (crc8_frame(kSyncId, in.data, 1) != in.data[1]) return CodecStatus::kChecksum;
  counter = in.data[0];
  return CodecStatus::kOk;
}

// ---- Feedback -----------------------------------------------------------------------------------
CodecStatus encode_feedback(int node, const FeedbackFrame& fb, can_frame& out) noexcept {
  clear(out);
  if (!node_ok(node)) return CodecStatus::kBadArgument;
  std::uint8_t flags = 0;
  out.can_id = kFeedbackBase + static_cast<canid_t>(node);
  out.len = 8;
  wire::put_sample_values(out.data, fb.sample, flags);
  out.data[6] = static_cast<std::uint8_t>((fb.counter & kClassicCounterMask) |
                                          (wire::pack_module_status(fb.sample.status) << 4));
  out.data[7] = crc8_frame(out.can_id, out.data, 7);
  return from_flags(flags);
}

CodecStatus decode_feedback(const can_frame& in, int& node, FeedbackFrame& fb) noexcept {
  const CodecStatus s = check_classic(in, kFeedbackBase, node);
  if (s != CodecStatus::kOk) return s;
  wire::get_sample_values(in.data, fb.sample);
  fb.sample.status = wire::unpack_module_status(static_cast<std::uint8_t>(in.data[6] >> 4));
  fb.counter = in.data[6] & kClassicCounterMask;
  return CodecStatus::kOk;
}

// ---- Timing record (classic bus) ----------------------------------------------------------------
CodecStatus encode_timing(int node, const wire::ModuleTiming& t, std::uint8_t counter,
                          can_frame& out) noexcept {
  clear(out);
  if (!node_ok(node)) return CodecStatus::kBadArgument;
  out.can_id = kTimingBase + static_cast<canid_t>(node);
  out.len = 8;
  wire::put_u32(out.data + 0, t.sample_us);
  put_u16(out.data + 4, wire::pack_age(t));
  out.data[6] = static_cast<std::uint8_t>((counter & kClassicCounterMask) |
                                          ((t.applied_tag & kClassicCounterMask) << 4));
  out.data[7] = crc8_frame(out.can_id, out.data, 7);
  return CodecStatus::kOk;
}

CodecStatus decode_timing(const can_frame& in, int& node, wire::ModuleTiming& t,
                          std::uint8_t& counter) noexcept {
  const CodecStatus s = check_classic(in, kTimingBase, node);
  if (s != CodecStatus::kOk) return s;
  t.sample_us = wire::get_u32(in.data + 0);
  wire::unpack_age(get_u16(in.data + 4), t);
  counter = in.data[6] & kClassicCounterMask;
  t.applied_tag = static_cast<std::uint8_t>(in.data[6] >> 4);
  return CodecStatus::kOk;
}

// ---- Feedback on an FD bus ----------------------------------------------------------------------
CodecStatus encode_feedback_fd(int node, const FeedbackFrame& fb, const wire::ModuleTiming& t,
                               canfd_frame& out) noexcept {
  std::memset(&out, 0, sizeof out);
  can_frame c{};
  const CodecStatus s = encode_feedback(node, fb, c);
  if (s == CodecStatus::kBadArgument) return s;
  out.can_id = c.can_id;
  out.len = kFdFeedbackLen;
  out.flags = CANFD_BRS;
  std::memcpy(out.data, c.data, 7);  // β, β̇, deflection, status|c (its CRC-8 is not sent)
  out.data[7] = t.applied_tag;
  wire::put_u32(out.data + 8, t.sample_us);
  put_u16(out.data + 12, wire::pack_age(t));
  put_u16(out.data + 14, crc16_frame(out.can_id, out.data, 14));
  return s;
}

CodecStatus decode_feedback_fd(const canfd_frame& in, int& node, FeedbackFrame& fb,
                               wire::ModuleTiming& t) noexcept {
  if (in.can_id & kFlagMask) return CodecStatus::kWrongId;
  const canid_t id = in.can_id & CAN_SFF_MASK;
  if (id < kFeedbackBase + 1 || id > kFeedbackBase + static_cast<canid_t>(kMaxNode))
    return CodecStatus::kWrongId;
  node = static_cast<int>(id - kFeedbackBase);
  if (in.len != kFdFeedbackLen) return CodecStatus::kWrongLength;
  if (crc16_frame(id, in.data, 14) != get_u16(in.data + 14)) return CodecStatus::kChecksum;
  wire::get_sample_values(in.data, fb.sample);
  fb.sample.status = wire::unpack_module_status(static_cast<std::uint8_t>(in.data[6] >> 4));
  fb.counter = in.data[6] & kClassicCounterMask;
  t.applied_tag = in.data[7];
  t.sample_us = wire::get_u32(in.data + 8);
  wire::unpack_age(get_u16(in.data + 12), t);
  return CodecStatus::kOk;
}

// ---- Classic command ----------------------------------------------------------------------------
CodecStatus encode_command(int node, const JointCommand& cmd, can_frame& out) noexcept {
  clear(out);
  if (!node_ok(node)) return CodecStatus::kBadArgument;
  std::uint8_t flags = 0;
  out.can_id = kCommandBase + static_cast<canid_t>(node);
  out.len = 8;
  put_i16(out.data + 0, wire::to_i16(cmd.tau, wire::kTauLsb, flags));
  put_i16(out.data + 2, wire::to_i16(cmd.beta_ref, wire::kBetaLsb, flags));
  put_i16(out.data + 4, wire::to_i16(cmd.beta_dot_ref, wire::kBetaDotLsb, flags));
  const bool off = cmd.torque_off || (flags & wire::kQuantNotFinite);
  out.data[6] = static_cast<std::uint8_t>((cmd.counter & kClassicCounterMask) | (off ? 0x10u : 0u));
  out.data[7] = crc8_frame(out.can_id, out.data, 7);
  return from_flags(flags);
}

CodecStatus decode_command(const can_frame& in, int& node, JointCommand& cmd) noexcept {
  const CodecStatus s = check_classic(in, kCommandBase, node);
  if (s != CodecStatus::kOk) return s;
  if (in.data[6] & 0xE0u) return CodecStatus::kBadField;  // reserved flag bits must be 0
  cmd.tau = wire::from_i16(get_i16(in.data + 0), wire::kTauLsb);
  cmd.beta_ref = wire::from_i16(get_i16(in.data + 2), wire::kBetaLsb);
  cmd.beta_dot_ref = wire::from_i16(get_i16(in.data + 4), wire::kBetaDotLsb);
  cmd.counter = in.data[6] & kClassicCounterMask;
  cmd.torque_off = (in.data[6] & 0x10u) != 0;
  return CodecStatus::kOk;
}

// ---- Gains --------------------------------------------------------------------------------------
CodecStatus encode_gains(int node, const JointGains& g, can_frame& out) noexcept {
  clear(out);
  if (!node_ok(node)) return CodecStatus::kBadArgument;
  std::uint8_t flags = 0;
  out.can_id = kGainsBase + static_cast<canid_t>(node);
  out.len = 8;
  put_u16(out.data + 0, wire::to_u16(g.kp, wire::kKpLsb, flags));
  put_u16(out.data + 2, wire::to_u16(g.kd, wire::kKdLsb, flags));
  out.data[6] = g.counter & kClassicCounterMask;
  out.data[7] = crc8_frame(out.can_id, out.data, 7);
  return from_flags(flags);
}

CodecStatus decode_gains(const can_frame& in, int& node, JointGains& g) noexcept {
  const CodecStatus s = check_classic(in, kGainsBase, node);
  if (s != CodecStatus::kOk) return s;
  g.kp = wire::from_u16(get_u16(in.data + 0), wire::kKpLsb);
  g.kd = wire::from_u16(get_u16(in.data + 2), wire::kKdLsb);
  g.counter = in.data[6] & kClassicCounterMask;
  return CodecStatus::kOk;
}

// ---- CAN FD command group -----------------------------------------------------------------------
CodecStatus encode_fd_command(const FdCommandGroup& grp, canfd_frame& out) noexcept {
  std::memset(&out, 0, sizeof out);
  if (grp.group < 0 || grp.group >= kMaxFdGroups || grp.count < 1 ||
      grp.count > kFdJointsPerFrame)
    return CodecStatus::kBadArgument;
  std::uint8_t flags = 0;
  out.can_id = kFdCommandBase + static_cast<canid_t>(grp.group);
  out.len = fd_command_len(grp.count);
  out.flags = CANFD_BRS;
  out.data[0] = grp.counter;
  for (int k = 0; k < grp.count; ++k) {
    std::uint8_t* p = out.data + 2 + kFdJointBytes * k;
    const FdJointCommand& j = grp.joint[static_cast<std::size_t>(k)];
    put_i16(p + 0, wire::to_i16(j.tau, wire::kTauLsb, flags));
    put_i16(p + 2, wire::to_i16(j.beta_ref, wire::kBetaLsb, flags));
    put_i16(p + 4, wire::to_i16(j.beta_dot_ref, wire::kBetaDotLsb, flags));
    put_u16(p + 6, wire::to_u16(j.kp, wire::kKpLsb, flags));
    put_u16(p + 8, wire::to_u16(j.kd, wire::kKdLsb, flags));
  }
  const bool off = grp.torque_off || (flags & wire::kQuantNotFinite);
  out.data[1] = static_cast<std::uint8_t>((off ? 0x01u : 0u) | ((grp.count - 1) << 4));
  const std::uint16_t crc = crc16_frame(out.can_id, out.data, out.len - 2u);
  put_u16(out.data + out.len - 2, crc);
  return from_flags(flags);
}

CodecStatus decode_fd_command(const canfd_frame& in, FdCommandGroup& grp) noexcept {
  if (in.can_id & kFlagMask) return CodecStatus::kWrongId;
  const canid_t id = in.can_id & CAN_SFF_MASK;
  if (id < kFdCommandBase || id >= kFdCommandBase + static_cast<canid_t>(kMaxFdGroups))
    return CodecStatus::kWrongId;
  if (in.len < fd_command_len(1) || in.len > CANFD_MAX_DLEN) return CodecStatus::kWrongLength;
  if (crc16_frame(id, in.data, in.len - 2u) != get_u16(in.data + in.len - 2))
    return CodecStatus::kChecksum;
  const int count = ((in.data[1] >> 4) & 0x07) + 1;
  if (count > kFdJointsPerFrame || (in.data[1] & 0x8Eu)) return CodecStatus::kBadField;
  if (in.len != fd_command_len(count)) return CodecStatus::kWrongLength;
  grp.group = static_cast<int>(id - kFdCommandBase);
  grp.count = count;
  grp.counter = in.data[0];
  grp.torque_off = (in.data[1] & 0x01u) != 0;
  for (int k = 0; k < count; ++k) {
    const std::uint8_t* p = in.data + 2 + kFdJointBytes * k;
    FdJointCommand& j = grp.joint[static_cast<std::size_t>(k)];
    j.tau = wire::from_i16(get_i16(p + 0), wire::kTauLsb);
    j.beta_ref = wire::from_i16(get_i16(p + 2), wire::kBetaLsb);
    j.beta_dot_ref = wire::from_i16(get_i16(p + 4), wire::kBetaDotLsb);
    j.kp = wire::from_u16(get_u16(p + 6), wire::kKpLsb);
    j.kd = wire::from_u16(get_u16(p + 8), wire::kKdLsb);
  }
  return CodecStatus::kOk;
}

bool fd_to_classic(const canfd_frame& in, can_frame& out) noexcept {
  if (in.len > CAN_MAX_DLEN) return false;
  std::memset(&out, 0, sizeof out);
  out.can_id = in.can_id;
  out.len = in.len;
  std::memcpy(out.data, in.data, in.len);
  return true;
}

}  // namespace pedalwave::drivers::can
