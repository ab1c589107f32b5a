// Fuzzes the DYNAMIXEL 2.0 packet parser as the serial driver uses it: a byte stream parsed packet
// after packet. Bit 0 of the first byte asks for a correct CRC to be patched into a packet at the
// start of the rest, so parsing beyond the CRC is reached. Properties: never crashes; progress is
// made or more bytes are needed; consumed ≤ available; a parsed status packet rebuilds to a packet
// that parses to the same content.
#include <array>
#include <cstdint>
#include <cstring>
#include <vector>

#include "fuzz_common.hpp"
#include "pedalwave/drivers/crc.hpp"
#include "pedalwave/drivers/dynamixel.hpp"

namespace dxl = pedalwave::drivers::dxl;

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 1) return 0;
  std::vector<std::uint8_t> buf(data + 1, data + size);
  if ((data[0] & 1u) && buf.size() >= dxl::kHeaderSize + 3) {
    const std::uint8_t hdr[4] = {0xFF, 0xFF, 0xFD, 0x00};
    std::memcpy(buf.data(), hdr, 4);
    const std::size_t len = buf.size() - dxl::kHeaderSize;
    buf[5] = static_cast<std::uint8_t>(len & 0xFF);
    buf[6] = static_cast<std::uint8_t>(len >> 8);
    const std::uint16_t crc = pedalwave::drivers::crc16_dxl(buf.data(), buf.size() - 2);
    buf[buf.size() - 2] = static_cast<std::uint8_t>(crc & 0xFF);
    buf[buf.size() - 1] = static_cast<std::uint8_t>(crc >> 8);
  }
  static dxl::Packet p;
  static dxl::Packet q;
  std::size_t pos = 0;
  while (pos < buf.size()) {
    std::size_t used = 0;
    const dxl::DxlStatus s =
        dxl::parse_packet(std::span<const std::uint8_t>(buf.data() + pos, buf.size() - pos), p, used);
    PW_FUZZ_CHECK(used <= buf.size() - pos);
    if (s == dxl::DxlStatus::kNeedMore) {
      PW_FUZZ_CHECK(used == 0);
      break;
    }
    PW_FUZZ_CHECK(used > 0);
    if (s == dxl::DxlStatus::kOk && p.instruction == dxl::kInstStatus) {
      std::array<std::uint8_t, dxl::kMaxPacket + 512> out{};
      std::size_t n = 0;
      if (dxl::build_status(p.id, p.error,
                            std::span<const std::uint8_t>(p.params.data(), p.param_count), out,
                            n) == dxl::DxlStatus::kOk) {
        std::size_t u2 = 0;
        PW_FUZZ_CHECK(dxl::parse_packet(std::span<const std::uint8_t>(out.data(), n), q, u2) ==
                      dxl::DxlStatus::kOk);
        PW_FUZZ_CHECK(u2 == n && q.id == p.id && q.error == p.error &&
                      q.param_count == p.param_count &&
                      std::memcmp(q.params.data(), p.params.data(), p.param_count) == 0);
      }
    }
    pos += used;
  }
  return 0;
}
