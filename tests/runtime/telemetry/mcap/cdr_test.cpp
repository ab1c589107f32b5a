// CdrWriter against hand-worked XCDR1 little-endian layouts: the encapsulation header, alignment
// counted after it, strings with their NUL, sequences with their counts, fixed arrays without.
#include <gtest/gtest.h>

#include <array>
#include <string>
#include <vector>

#include "pedalwave/mcap/cdr.hpp"

using pedalwave::mcap::CdrWriter;

namespace {

std::vector<int> ints(std::span<const std::byte> b) {
  std::vector<int> v;
  for (auto x : b) v.push_back(static_cast<int>(x));
  return v;
}

// std_msgs/msg/String "hello".
TEST(Cdr, StringMessage) {
  CdrWriter cdr;
  cdr.write_string("hello");
  EXPECT_EQ(ints(cdr.bytes()), (std::vector<int>{0, 1, 0, 0, 6, 0, 0, 0, 'h', 'e', 'l', 'l', 'o', 0}));
  cdr.reset();
  cdr.write_string("");
  EXPECT_EQ(ints(cdr.bytes()), (std::vector<int>{0, 1, 0, 0, 1, 0, 0, 0, 0}));
}

// sensor_msgs/msg/JointState: Header{Time{int32, uint32}, string}, string[], float64[] ×3.
// Offsets (after the encapsulation header): sec 0, nanosec 4, frame_id 8..13, pad 14..15,
// name count 16, "j1" 20..26, pad 27, "j2" 28..34, pad 35, position count 36, 1.0 at 40,
// -2.5 at 48, velocity count 56, effort count 60, 0.25 at 64 (8-aligned).
TEST(Cdr, JointStateLayout) {
  CdrWriter cdr;
  cdr.write_time(1'500'000'000);
  cdr.write_string("b");
  cdr.write_sequence(std::vector<std::string>{"j1", "j2"});
  cdr.write_sequence(std::vector<double>{1.0, -2.5});
  cdr.write_sequence(std::vector<double>{});
  cdr.write_sequence(std::vector<double>{0.25});
  const std::vector<int> want = {
      0, 1, 0, 0,                                      // CDR_LE
      1, 0, 0, 0, 0x00, 0x65, 0xCD, 0x1D,              // stamp 1 s, 500000000 ns
      2, 0, 0, 0, 'b', 0, 0, 0,                        // frame_id "b", pad
      2, 0, 0, 0,                                      // name: 2
      3, 0, 0, 0, 'j', '1', 0, 0,                      // "j1", pad
      3, 0, 0, 0, 'j', '2', 0, 0,                      // "j2", pad
      2, 0, 0, 0,                                      // position: 2 (ends at 40: aligned)
      0, 0, 0, 0, 0, 0, 0xF0, 0x3F,                    // 1.0
      0, 0, 0, 0, 0, 0, 0x04, 0xC0,                    // -2.5
      0, 0, 0, 0,                                      // velocity: 0
      1, 0, 0, 0,                                      // effort: 1 (ends at 64: aligned)
      0, 0, 0, 0, 0, 0, 0xD0, 0x3F};                   // 0.25
  EXPECT_EQ(ints(cdr.bytes()), want);
  EXPECT_EQ(cdr.payload_size(), 72u);
}

// Every primitive at an unaligned position: padding to its own size, values little-endian.
TEST(Cdr, PrimitivesAlignToTheirSize) {
  CdrWriter cdr;
  cdr.write_bool(true);                 // 0
  cdr.write_i16(-2);                    // pad 1, 2..3
  cdr.write_u8(0xAB);                   // 4
  cdr.write_i32(-3);                    // pad 5..7, 8..11
  cdr.write_i8(-1);                     // 12
  cdr.write_u64(0x0102030405060708ull); // pad 13..15, 16..23
  cdr.write_f32(1.0f);                  // 24..27
  cdr.write_u16(0x1234);                // 28..29
  cdr.write_f64(-0.0);                  // pad 30..31, 32..39
  const std::vector<int> want = {0, 1, 0, 0,
                                 1, 0, 0xFE, 0xFF,
                                 0xAB, 0, 0, 0, 0xFD, 0xFF, 0xFF, 0xFF,
                                 0xFF, 0, 0, 0,
                                 8, 7, 6, 5, 4, 3, 2, 1,
                                 0, 0, 0x80, 0x3F,
                                 0x34, 0x12, 0, 0,
                                 0, 0, 0, 0, 0, 0, 0, 0x80};
  EXPECT_EQ(ints(cdr.bytes()), want);
}

// Fixed arrays have no count; sequences of one-byte types are not padded.
TEST(Cdr, ArraysAndByteSequences) {
  CdrWriter cdr;
  const std::array<float, 2> f = {0.5f, 2.0f};
  cdr.write_u8(9);
  cdr.write_array(std::span<const float>(f));
  cdr.write_sequence(std::vector<std::uint8_t>{1, 2, 3});
  cdr.write_sequence(std::vector<std::uint8_t>{1, 0});
  EXPECT_EQ(ints(cdr.bytes()), (std::vector<int>{0, 1, 0, 0, 9, 0, 0, 0, 0, 0, 0, 0x3F, 0, 0, 0, 0x40,
                                                 3, 0, 0, 0, 1, 2, 3, 0, 2, 0, 0, 0, 1, 0}));
}

// Time from nanoseconds: the nanosecond part is always in [0, 1e9).
TEST(Cdr, TimeSplitsNanosecondsTowardMinusInfinity) {
  CdrWriter cdr;
  cdr.write_time(-1);
  EXPECT_EQ(ints(cdr.bytes()), (std::vector<int>{0, 1, 0, 0, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF, 0xC9, 0x9A, 0x3B}));
  cdr.reset();
  cdr.write_time(1'700'000'000'123'456'789);
  // 1700000000 = 0x6553F100, 123456789 = 0x075BCD15
  EXPECT_EQ(ints(cdr.bytes()), (std::vector<int>{0, 1, 0, 0, 0x00, 0xF1, 0x53, 0x65, 0x15, 0xCD, 0x5B, 0x07}));
}

}  // namespace
