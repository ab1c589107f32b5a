#include "pedalwave/drivers/crc.hpp"

#include <array>

namespace pedalwave::drivers {
namespace {

// MSB-first (non-reflected) table for an 8-bit CRC with polynomial `poly`.
constexpr std::array<std::uint8_t, 256> make_table8(std::uint8_t poly) {
  std::array<std::uint8_t, 256> t{};
  for (unsigned i = 0; i < 256; ++i) {
    unsigned r = i;
    for (int b = 0; b < 8; ++b) r = (r & 0x80u) ? ((r << 1) ^ poly) : (r << 1);
    t[i] = static_cast<std::uint8_t>(r & 0xFFu);
  }
  return t;
}

// MSB-first table for a 16-bit CRC with polynomial `poly`.
constexpr std::array<std::uint16_t, 256> make_table16(std::uint16_t poly) {
  std::array<std::uint16_t, 256> t{};
  for (unsigned i = 0; i < 256; ++i) {
    unsigned r = i << 8;
    for (int b = 0; b < 8; ++b) r = (r & 0x8000u) ? ((r << 1) ^ poly) : (r << 1);
    t[i] = static_cast<std::uint16_t>(r & 0xFFFFu);
  }
  return t;
}

constexpr auto kTable8J1850 = make_table8(0x1D);
constexpr auto kTable16Ccitt = make_table16(0x1021);
constexpr auto kTable16Dxl = make_table16(0x8005);

std::uint16_t crc16_msb(const std::array<std::uint16_t, 256>& table, const std::uint8_t* data,
                        std::size_t n, std::uint16_t crc) noexcept {
  for (std::size_t i = 0; i < n; ++i) {
    const unsigned idx = ((crc >> 8) ^ data[i]) & 0xFFu;
    crc = static_cast<std::uint16_t>((crc << 8) ^ table[idx]);
  }
  return crc;
}

}  // namespace

std::uint8_t crc8_j1850_update(std::uint8_t reg, const std::uint8_t* data, std::size_t n) noexcept {
  for (std::size_t i = 0; i < n; ++i) reg = kTable8J1850[reg ^ data[i]];
  return reg;
}

std::uint16_t crc16_ccitt(const std::uint8_t* data, std::size_t n, std::uint16_t crc) noexcept {
  return crc16_msb(kTable16Ccitt, data, n, crc);
}

std::uint16_t crc16_dxl(const std::uint8_t* data, std::size_t n, std::uint16_t crc) noexcept {
  return crc16_msb(kTable16Dxl, data, n, crc);
}

}  // namespace pedalwave::drivers
