// Fuzzes decode_feedback (classic CAN feedback frame). Input: id (2 bytes), len, 8 data bytes,
// flags. Bit 0 of the flags byte patches a correct CRC-8 in, so the decoder's post-CRC logic is
// reached. Properties: never crashes; a decoded frame re-encodes to the same bytes.
#include <cstdint>
#include <cstring>

#include "fuzz_common.hpp"
#include "pedalwave/drivers/can_protocol.hpp"
#include "pedalwave/drivers/crc.hpp"

namespace can = pedalwave::drivers::can;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 12) return 0;
  can_frame f{};
  f.can_id = static_cast<canid_t>(data[0] | (data[1] << 8) | ((data[11] & 0xE0u) << 24));
  f.len = data[2];
  std::memcpy(f.data, data + 3, 8);
  if ((data[11] & 1u) && f.len == 8) {
    const std::uint8_t idb[2] = {static_cast<std::uint8_t>(f.can_id & 0xFF),
                                 static_cast<std::uint8_t>((f.can_id >> 8) & 0x07)};
    std::uint8_t reg = pedalwave::drivers::crc8_j1850_update(pedalwave::drivers::kCrc8Init, idb, 2);
    reg = pedalwave::drivers::crc8_j1850_update(reg, f.data, 7);
    f.data[7] = pedalwave::drivers::crc8_j1850_final(reg);
  }
  int node = 0;
  can::FeedbackFrame fb{};
  if (can::decode_feedback(f, node, fb) != can::CodecStatus::kOk) return 0;
  PW_FUZZ_CHECK(node >= 1 && node <= can::kMaxNode);
  can_frame g{};
  const can::CodecStatus s = can::encode_feedback(node, fb, g);
  // −32768 is never sent; a received −32768 saturates to −32767 on re-encoding.
  if (s == can::CodecStatus::kOk) {
    PW_FUZZ_CHECK(g.can_id == (f.can_id & CAN_SFF_MASK));
    PW_FUZZ_CHECK(g.len == 8);
    PW_FUZZ_CHECK(std::memcmp(g.data, f.data, 8) == 0);
  }
  return 0;
}
