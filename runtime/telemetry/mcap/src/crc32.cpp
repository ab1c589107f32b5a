#include "pedalwave/mcap/crc32.hpp"

#include <array>

namespace pedalwave::mcap {
namespace {

// Byte-wise table of the reflected polynomial, built at compile time.
constexpr std::array<std::uint32_t, 256> make_table() {
  std::array<std::uint32_t, 256> table{};
  for (std::uint32_t n = 0; n < 256; ++n) {
    std::uint32_t c = n;
    for (int k = 0; k < 8; ++k) c = (c & 1u) ? (0xEDB88320u ^ (c >> 1)) : (c >> 1);
    table[n] = c;
  }
  return table;
}
constexpr auto kTable = make_table();

}  // namespace

void Crc32::update(const void* data, std::size_t size) noexcept {
  const auto* p = static_cast<const unsigned char*>(data);
  std::uint32_t c = state_;
  for (std::size_t i = 0; i < size; ++i) c = kTable[(c ^ p[i]) & 0xFFu] ^ (c >> 8);
  state_ = c;
}

void Crc32::update(std::span<const std::byte> bytes) noexcept { update(bytes.data(), bytes.size()); }

std::uint32_t crc32(std::span<const std::byte> bytes) noexcept {
  Crc32 c;
  c.update(bytes);
  return c.value();
}

std::uint32_t crc32(std::string_view text) noexcept {
  Crc32 c;
  c.update(text.data(), text.size());
  return c.value();
}

}  // namespace pedalwave::mcap
