// Checksums used by the module protocols (drivers/PROTOCOL.md). Pure, allocation-free, noexcept.
//   crc8_j1850   CRC-8/SAE-J1850: poly 0x1D, init 0xFF, no reflection, xorout 0xFF
//                (check value over "123456789" = 0x4B). Classic CAN frames (end-to-end guard).
//   crc16_ccitt  CRC-16/CCITT-FALSE (IBM-3740): poly 0x1021, init 0xFFFF, no reflection, xorout 0
//                (check 0x29B1). CAN FD command frames.
//   crc16_dxl    CRC-16 of DYNAMIXEL Protocol 2.0 (= CRC-16/BUYPASS): poly 0x8005, init 0,
//                no reflection, xorout 0 (check 0xFEE8).
// Each takes an optional running value so a checksum can span several buffers: pass the result of
// the previous call as `crc` (for crc8_j1850 the running value is the internal register, see
// crc8_j1850_update/crc8_j1850_final).
#pragma once

#include <cstddef>
#include <cstdint>

namespace pedalwave::drivers {

// CRC-8/SAE-J1850 in two steps: update from the register (start at kCrc8Init), then finalize.
inline constexpr std::uint8_t kCrc8Init = 0xFF;
std::uint8_t crc8_j1850_update(std::uint8_t reg, const std::uint8_t* data, std::size_t n) noexcept;
inline std::uint8_t crc8_j1850_final(std::uint8_t reg) noexcept {
  return static_cast<std::uint8_t>(reg ^ 0xFFu);
}
inline std::uint8_t crc8_j1850(const std::uint8_t* data, std::size_t n) noexcept {
  return crc8_j1850_final(crc8_j1850_update(kCrc8Init, data, n));
}

// CRC-16/CCITT-FALSE; start with crc = 0xFFFF.
std::uint16_t crc16_ccitt(const std::uint8_t* data, std::size_t n,
                          std::uint16_t crc = 0xFFFF) noexcept;

// DYNAMIXEL Protocol 2.0 CRC-16; start with crc = 0.
std::uint16_t crc16_dxl(const std::uint8_t* data, std::size_t n, std::uint16_t crc = 0) noexcept;

}  // namespace pedalwave::drivers
