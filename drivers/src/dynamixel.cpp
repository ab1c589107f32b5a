#include "pedalwave/drivers/dynamixel.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "pedalwave/drivers/crc.hpp"
#include "pedalwave/drivers/wire.hpp"

namespace pedalwave::drivers::dxl {
namespace {

constexpr std::uint8_t kHeader[4] = {0xFF, 0xFF, 0xFD, 0x00};

// Writes header, id, length, the stuffed body and the CRC. body = [inst, (err), params...] given
// as two pieces (a small prefix and the parameters) so no temporary buffer is needed.
DxlStatus build_packet(std::uint8_t id, std::span<const std::uint8_t> prefix,
                       std::span<const std::uint8_t> params, std::span<std::uint8_t> out,
                       std::size_t& out_len) noexcept {
  out_len = 0;
  if (id == 0xFF || id == 0xFD) return DxlStatus::kBadArgument;
  if (out.size() < kHeaderSize + prefix.size() + 2) return DxlStatus::kOverflow;
  std::memcpy(out.data(), kHeader, 4);
  out[4] = id;
  // Stuff prefix and params as one stream (a pattern may straddle the two pieces).
  std::size_t n = kHeaderSize;
  int ff_run = 0;  // number of consecutive 0xFF just emitted (capped at 2)
  auto emit = [&](std::uint8_t b) noexcept -> bool {
    if (n >= out.size()) return false;
    out[n++] = b;
    return true;
  };
  auto push = [&](std::uint8_t b) noexcept -> bool {
    if (!emit(b)) return false;
    if (b == 0xFD && ff_run >= 2) {
      if (!emit(0xFD)) return false;
      ff_run = 0;
      return true;
    }
    ff_run = (b == 0xFF) ? (ff_run < 2 ? ff_run + 1 : 2) : 0;
    return true;
  };
  for (std::uint8_t b : prefix)
    if (!push(b)) return DxlStatus::kOverflow;
  for (std::uint8_t b : params)
    if (!push(b)) return DxlStatus::kOverflow;
  const std::size_t len = (n - kHeaderSize) + 2;  // body + CRC
  if (len > 0xFFFF || n + 2 > out.size() || n + 2 > kMaxPacket) return DxlStatus::kOverflow;
  wire::put_u16(out.data() + 5, static_cast<std::uint16_t>(len));
  const std::uint16_t crc = crc16_dxl(out.data(), n);
  wire::put_u16(out.data() + n, crc);
  out_len = n + 2;
  return DxlStatus::kOk;
}

}  // namespace

DxlStatus stuff(std::span<const std::uint8_t> in, std::span<std::uint8_t> out,
                std::size_t& out_len) noexcept {
  out_len = 0;
  int ff_run = 0;
  for (std::uint8_t b : in) {
    if (out_len >= out.size()) return DxlStatus::kOverflow;
    out[out_len++] = b;
    if (b == 0xFD && ff_run >= 2) {
      if (out_len >= out.size()) return DxlStatus::kOverflow;
      out[out_len++] = 0xFD;
      ff_run = 0;
      continue;
    }
    ff_run = (b == 0xFF) ? (ff_run < 2 ? ff_run + 1 : 2) : 0;
  }
  return DxlStatus::kOk;
}

DxlStatus unstuff(std::span<const std::uint8_t> in, std::span<std::uint8_t> out,
                  std::size_t& out_len) noexcept {
  out_len = 0;
  int ff_run = 0;
  for (std::size_t i = 0; i < in.size(); ++i) {
    const std::uint8_t b = in[i];
    if (out_len >= out.size()) return DxlStatus::kOverflow;
    out[out_len++] = b;
    if (b == 0xFD && ff_run >= 2) {
      // The stuffed FD must follow; drop it.
      if (i + 1 >= in.size() || in[i + 1] != 0xFD) return DxlStatus::kMalformed;
      ++i;
      ff_run = 0;
      continue;
    }
    ff_run = (b == 0xFF) ? (ff_run < 2 ? ff_run + 1 : 2) : 0;
  }
  return DxlStatus::kOk;
}

DxlStatus build_instruction(std::uint8_t id, std::uint8_t instruction,
                            std::span<const std::uint8_t> params, std::span<std::uint8_t> out,
                            std::size_t& out_len) noexcept {
  const std::uint8_t prefix[1] = {instruction};
  return build_packet(id, prefix, params, out, out_len);
}

DxlStatus build_status(std::uint8_t id, std::uint8_t error, std::span<const std::uint8_t> params,
                       std::span<std::uint8_t> out, std::size_t& out_len) noexcept {
  const std::uint8_t prefix[2] = {kInstStatus, error};
  return build_packet(id, prefix, params, out, out_len);
}

DxlStatus build_sync_read(std::uint16_t address, std::uint16_t length,
                          std::span<const std::uint8_t> ids, std::span<std::uint8_t> out,
                          std::size_t& out_len) noexcept {
  out_len = 0;
  std::array<std::uint8_t, 4 + 253> p{};
  if (ids.empty() || ids.size() > 253) return DxlStatus::kBadArgument;
  wire::put_u16(p.data(), address);
  wire::put_u16(p.data() + 2, length);
  std::memcpy(p.data() + 4, ids.data(), ids.size());
  return build_instruction(kBroadcastId, kInstSyncRead,
                           std::span<const std::uint8_t>(p.data(), 4 + ids.size()), out, out_len);
}

DxlStatus build_sync_write(std::uint16_t address, std::uint16_t length,
                           std::span<const std::uint8_t> ids, std::span<const std::uint8_t> data,
                           std::span<std::uint8_t> out, std::size_t& out_len) noexcept {
  out_len = 0;
  if (ids.empty() || data.size() != ids.size() * length) return DxlStatus::kBadArgument;
  const std::size_t n = 4 + ids.size() * (1u + length);
  std::array<std::uint8_t, kMaxParams> p{};
  if (n > p.size()) return DxlStatus::kOverflow;
  wire::put_u16(p.data(), address);
  wire::put_u16(p.data() + 2, length);
  std::size_t k = 4;
  for (std::size_t i = 0; i < ids.size(); ++i) {
    p[k++] = ids[i];
    std::memcpy(p.data() + k, data.data() + i * length, length);
    k += length;
  }
  return build_instruction(kBroadcastId, kInstSyncWrite, std::span<const std::uint8_t>(p.data(), n),
                           out, out_len);
}

DxlStatus build_read(std::uint8_t id, std::uint16_t address, std::uint16_t length,
                     std::span<std::uint8_t> out, std::size_t& out_len) noexcept {
  std::uint8_t p[4];
  wire::put_u16(p, address);
  wire::put_u16(p + 2, length);
  return build_instruction(id, kInstRead, p, out, out_len);
}

DxlStatus build_write(std::uint8_t id, std::uint16_t address, std::span<const std::uint8_t> data,
                      std::span<std::uint8_t> out, std::size_t& out_len) noexcept {
  out_len = 0;
  std::array<std::uint8_t, 2 + kTableSize> p{};
  if (data.empty() || data.size() > kTableSize) return DxlStatus::kBadArgument;
  wire::put_u16(p.data(), address);
  std::memcpy(p.data() + 2, data.data(), data.size());
  return build_instruction(id, kInstWrite, std::span<const std::uint8_t>(p.data(), 2 + data.size()),
                           out, out_len);
}

const Register* register_at(std::span<const Register> regs, std::uint16_t address) noexcept {
  for (const Register& r : regs)
    if (r.size > 0 && address >= r.address && address < r.address + r.size) return &r;
  return nullptr;
}

const Register* register_at(std::uint16_t address) noexcept {
  return register_at(kRegisters, address);
}

int baud_index(int baud) noexcept {
  for (int i = 0; i <= 6; ++i)
    if (baud_of_index(i) == baud) return i;
  return -1;
}

const char* error_name(std::uint8_t error) noexcept {
  switch (error & 0x7F) {
    case kErrResultFail: return "Result Fail";
    case kErrInstruction: return "Instruction Error";
    case kErrCrc: return "CRC Error";
    case kErrDataRange: return "Data Range Error";
    case kErrDataLength: return "Data Length Error";
    case kErrDataLimit: return "Data Limit Error";
    case kErrAccess: return "Access Error";
    default: return "unknown error";
  }
}

std::string baud_text(int index) {
  const int b = baud_of_index(index);
  return b > 0 ? std::to_string(b) + " baud" : "no rate of the index";
}

int baud_of_index(int index) noexcept {
  constexpr int kBaud[] = {9600, 57600, 115200, 1'000'000, 2'000'000, 3'000'000, 4'000'000};
  return index >= 0 && index <= 6 ? kBaud[index] : 0;
}

std::uint8_t check_read(std::span<const Register> regs, std::uint16_t size, std::uint16_t address,
                        std::uint16_t length) noexcept {
  if (length == 0) return kErrDataLength;
  if (std::size_t{address} + length > size) return kErrAccess;
  for (std::size_t a = address; a < std::size_t{address} + length; ++a) {
    const Register* r = register_at(regs, static_cast<std::uint16_t>(a));
    if (r && r->access == Access::kW) return kErrAccess;
  }
  return 0;
}

std::uint8_t check_write(std::span<const Register> regs, std::uint16_t size, std::uint16_t address,
                         std::span<const std::uint8_t> data, bool& eeprom) noexcept {
  eeprom = false;
  if (data.empty()) return kErrDataLength;
  if (std::size_t{address} + data.size() > size) return kErrAccess;
  std::size_t a = address;
  const std::size_t end = address + data.size();
  while (a < end) {
    const Register* r = register_at(regs, static_cast<std::uint16_t>(a));
    if (!r || r->access == Access::kR) return kErrAccess;  // a gap or a read-only register
    if (r->address != a || a + r->size > end) return kErrDataLength;  // entered or left midway
    std::uint32_t v = 0;
    for (std::size_t k = 0; k < r->size; ++k) v |= std::uint32_t{data[a - address + k]} << (8 * k);
    if (v < r->min || v > r->max) return kErrDataRange;
    eeprom = eeprom || r->eeprom;
    a += r->size;
  }
  return 0;
}

std::uint8_t check_read(std::uint16_t address, std::uint16_t length) noexcept {
  return check_read(kRegisters, kTableSize, address, length);
}

std::uint8_t check_write(std::uint16_t address, std::span<const std::uint8_t> data,
                         bool& eeprom) noexcept {
  return check_write(kRegisters, kTableSize, address, data, eeprom);
}

DxlStatus parse_packet(std::span<const std::uint8_t> in, Packet& pkt,
                       std::size_t& consumed) noexcept {
  consumed = 0;
  // 1. Find the header FF FF FD 00. Bytes before it are garbage.
  std::size_t h = 0;
  while (h + 4 <= in.size() && std::memcmp(in.data() + h, kHeader, 4) != 0) ++h;
  if (h + 4 > in.size()) {
    // No full header: keep a possible header prefix (up to 3 trailing bytes), drop the rest.
    std::size_t keep = 0;
    for (std::size_t k = std::min<std::size_t>(3, in.size()); k > 0; --k) {
      if (std::memcmp(in.data() + in.size() - k, kHeader, k) == 0) {
        keep = k;
        break;
      }
    }
    consumed = in.size() - keep;
    return consumed ? DxlStatus::kGarbage : DxlStatus::kNeedMore;
  }
  if (h > 0) {
    consumed = h;
    return DxlStatus::kGarbage;
  }
  // 2. Id and length.
  if (in.size() < kHeaderSize) return DxlStatus::kNeedMore;
  const std::uint8_t id = in[4];
  const std::size_t len = wire::get_u16(in.data() + 5);
  if (id == 0xFF || id == 0xFD || len < 3 || kHeaderSize + len > kMaxPacket) {
    consumed = 1;  // resynchronize on the next header
    return DxlStatus::kMalformed;
  }
  const std::size_t total = kHeaderSize + len;
  if (in.size() < total) return DxlStatus::kNeedMore;
  consumed = total;
  pkt.id = id;
  // 3. CRC over the packet as sent (stuffed).
  if (crc16_dxl(in.data(), total - 2) != wire::get_u16(in.data() + total - 2))
    return DxlStatus::kChecksum;
  // 4. Unstuff instruction + (error) + parameters.
  std::array<std::uint8_t, kMaxPacket> body{};
  std::size_t body_len = 0;
  if (unstuff(in.subspan(kHeaderSize, len - 2), body, body_len) != DxlStatus::kOk || body_len < 1)
    return DxlStatus::kMalformed;
  pkt.instruction = body[0];
  std::size_t first = 1;
  pkt.error = 0;
  if (pkt.instruction == kInstStatus) {
    if (body_len < 2) return DxlStatus::kMalformed;
    pkt.error = body[1];
    first = 2;
  }
  pkt.param_count = body_len - first;
  std::memcpy(pkt.params.data(), body.data() + first, pkt.param_count);
  return DxlStatus::kOk;
}

std::uint8_t encode_command_block(const CommandBlock& c, std::uint8_t* o) noexcept {
  std::uint8_t f = 0;
  wire::put_i16(o + 0, wire::to_i16(c.tau, wire::kTauLsb, f));
  wire::put_i16(o + 2, wire::to_i16(c.beta_ref, wire::kBetaLsb, f));
  wire::put_i16(o + 4, wire::to_i16(c.beta_dot_ref, wire::kBetaDotLsb, f));
  wire::put_u16(o + 6, wire::to_u16(c.kp, wire::kKpLsb, f));
  wire::put_u16(o + 8, wire::to_u16(c.kd, wire::kKdLsb, f));
  o[10] = (c.torque_off || (f & wire::kQuantNotFinite)) ? 0x01 : 0x00;
  o[11] = c.counter;
  return f;
}

void decode_command_block(const std::uint8_t* i, CommandBlock& c) noexcept {
  c.tau = wire::from_i16(wire::get_i16(i + 0), wire::kTauLsb);
  c.beta_ref = wire::from_i16(wire::get_i16(i + 2), wire::kBetaLsb);
  c.beta_dot_ref = wire::from_i16(wire::get_i16(i + 4), wire::kBetaDotLsb);
  c.kp = wire::from_u16(wire::get_u16(i + 6), wire::kKpLsb);
  c.kd = wire::from_u16(wire::get_u16(i + 8), wire::kKdLsb);
  c.torque_off = (i[10] & 0x01u) != 0;
  c.counter = i[11];
}

std::uint8_t encode_feedback_block(const FeedbackBlock& fb, std::uint8_t* o) noexcept {
  std::uint8_t f = 0;
  wire::put_sample_values(o, fb.sample, f);
  o[6] = wire::pack_module_status(fb.sample.status);
  o[7] = fb.echo;
  wire::put_u32(o + 8, fb.timing.sample_us);
  wire::put_u16(o + 12, wire::pack_age(fb.timing));
  o[14] = fb.timing.applied_tag;
  return f;
}

void decode_feedback_block(const std::uint8_t* i, FeedbackBlock& fb) noexcept {
  wire::get_sample_values(i, fb.sample);
  fb.sample.status = wire::unpack_module_status(static_cast<std::uint8_t>(i[6] & 0x0Fu));
  fb.echo = i[7];
  fb.timing.sample_us = wire::get_u32(i + 8);
  wire::unpack_age(wire::get_u16(i + 12), fb.timing);
  fb.timing.applied_tag = i[14];
}

namespace x {

void decode_present_values(const std::uint8_t* i, double current_lsb, PresentValues& f) noexcept {
  f.tick = wire::get_u16(i);
  f.current = wire::get_i16(i + (kRegPresentCurrent - kFeedbackAddress)) * current_lsb;
  f.velocity = static_cast<std::int32_t>(wire::get_u32(i + (kRegPresentVelocity - kFeedbackAddress))) * kVelocityLsb;
  f.position = static_cast<std::int32_t>(wire::get_u32(i + (kRegPresentPosition - kFeedbackAddress))) * kPositionLsb;
}

std::int16_t goal_current(double tau, double k_t, double current_lsb, std::uint16_t limit,
                          std::uint8_t& flags) noexcept {
  const double counts = tau / (k_t * current_lsb);
  if (!std::isfinite(counts)) {
    flags |= wire::kQuantNotFinite;
    return 0;
  }
  const double lim = limit;
  if (counts > lim || counts < -lim) flags |= wire::kQuantClamped;
  return static_cast<std::int16_t>(std::lround(std::clamp(counts, -lim, lim)));
}

}  // namespace x

}  // namespace pedalwave::drivers::dxl
