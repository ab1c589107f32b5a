// Fuzzes decode_fd_command (CAN FD command-group frame). Input: id (2 bytes), len, flags, then up
// to 64 payload bytes; bit 0 of the flags byte patches a correct CRC-16 in. Properties: never
// crashes; a decoded frame re-encodes to the same bytes (up to padding and −32768).
#include <cstdint>
#include <cstring>

#include "fuzz_common.hpp"
#include "pedalwave/drivers/can_protocol.hpp"
#include "pedalwave/drivers/crc.hpp"

namespace can = pedalwave::drivers::can;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 4) return 0;
  canfd_frame f{};
  f.can_id = static_cast<canid_t>(data[0] | (data[1] << 8));
  f.len = data[2];
  const std::uint8_t flags = data[3];
  const std::size_t n = size - 4 < CANFD_MAX_DLEN ? size - 4 : CANFD_MAX_DLEN;
  std::memcpy(f.data, data + 4, n);
  if ((flags & 1u) && f.len >= 2 && f.len <= CANFD_MAX_DLEN) {
    const std::uint8_t idb[2] = {static_cast<std::uint8_t>(f.can_id & 0xFF),
                                 static_cast<std::uint8_t>((f.can_id >> 8) & 0x07)};
    const std::uint16_t crc =
        pedalwave::drivers::crc16_ccitt(f.data, f.len - 2u, pedalwave::drivers::crc16_ccitt(idb, 2));
    f.data[f.len - 2] = static_cast<std::uint8_t>(crc & 0xFF);
    f.data[f.len - 1] = static_cast<std::uint8_t>(crc >> 8);
  }
  can::FdCommandGroup g{};
  if (can::decode_fd_command(f, g) != can::CodecStatus::kOk) return 0;
  PW_FUZZ_CHECK(g.count >= 1 && g.count <= can::kFdJointsPerFrame);
  PW_FUZZ_CHECK(g.group >= 0 && g.group < can::kMaxFdGroups);
  PW_FUZZ_CHECK(f.len == can::fd_command_len(g.count));
  canfd_frame e{};
  if (can::encode_fd_command(g, e) == can::CodecStatus::kOk) {
    PW_FUZZ_CHECK(e.len == f.len);
    PW_FUZZ_CHECK(std::memcmp(e.data, f.data, 2 + 10u * static_cast<unsigned>(g.count)) == 0);
    can::FdCommandGroup h{};
    PW_FUZZ_CHECK(can::decode_fd_command(e, h) == can::CodecStatus::kOk);
    PW_FUZZ_CHECK(h.count == g.count && h.counter == g.counter && h.torque_off == g.torque_off);
  }
  return 0;
}
