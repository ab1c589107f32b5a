// CRC-32 as MCAP uses it (the IEEE 802.3 / zlib CRC: reflected polynomial 0xEDB88320, initial value
// and final XOR 0xFFFFFFFF; crc32("123456789") == 0xCBF43926), one-shot and incremental.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string_view>

namespace pedalwave::mcap {

// A running CRC-32: update() any number of times, value() at any point (does not end the run).
class Crc32 {
 public:
  void update(std::span<const std::byte> bytes) noexcept;
  void update(const void* data, std::size_t size) noexcept;
  [[nodiscard]] std::uint32_t value() const noexcept { return state_ ^ 0xFFFFFFFFu; }
  void reset() noexcept { state_ = 0xFFFFFFFFu; }

 private:
  std::uint32_t state_ = 0xFFFFFFFFu;  // the register before the final XOR
};

// The CRC-32 of a whole buffer.
[[nodiscard]] std::uint32_t crc32(std::span<const std::byte> bytes) noexcept;
[[nodiscard]] std::uint32_t crc32(std::string_view text) noexcept;

}  // namespace pedalwave::mcap
