// CRC-32 (IEEE, as MCAP uses it): the standard check values, and incremental = one-shot.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "pedalwave/mcap/crc32.hpp"

using namespace pedalwave::mcap;

TEST(Crc32, CheckValues) {
  EXPECT_EQ(crc32(std::string_view("123456789")), 0xCBF43926u);  // the CRC catalogue's check value
  EXPECT_EQ(crc32(std::string_view("")), 0u);
  EXPECT_EQ(crc32(std::string_view("The quick brown fox jumps over the lazy dog")), 0x414FA339u);
  // The summary CRC of an MCAP file without summary records: the footer's first 25 bytes
  // (op 2, length 20, two zero offsets) — the value the spec's discussion quotes (1875167664).
  std::vector<std::byte> footer(25, std::byte{0});
  footer[0] = std::byte{0x02};
  footer[1] = std::byte{20};
  EXPECT_EQ(crc32(footer), 1875167664u);
}

TEST(Crc32, IncrementalEqualsOneShot) {
  std::vector<std::byte> data(1000);
  for (std::size_t i = 0; i < data.size(); ++i) data[i] = static_cast<std::byte>((i * 131u) & 0xFFu);
  Crc32 c;
  c.update(std::span<const std::byte>(data).subspan(0, 1));
  c.update(std::span<const std::byte>(data).subspan(1, 499));
  const auto mid = c.value();  // value() does not end the run
  c.update(std::span<const std::byte>(data).subspan(500));
  EXPECT_EQ(c.value(), crc32(data));
  EXPECT_EQ(mid, crc32(std::span<const std::byte>(data).subspan(0, 500)));
  c.reset();
  EXPECT_EQ(c.value(), 0u);
}
