// Checksums against their published check values and against the ROBOTIS e-Manual examples.
#include <gtest/gtest.h>

#include <cstring>
#include <vector>

#include "pedalwave/drivers/crc.hpp"
#include "pedalwave/drivers/dynamixel.hpp"

namespace pd = pedalwave::drivers;

namespace {
const std::uint8_t kCheck[] = {'1', '2', '3', '4', '5', '6', '7', '8', '9'};
}

// Catalogue check values ("123456789") of the three CRCs we use.
TEST(Crc, CheckValues) {
  EXPECT_EQ(pd::crc8_j1850(kCheck, 9), 0x4B);
  EXPECT_EQ(pd::crc16_ccitt(kCheck, 9), 0x29B1);
  EXPECT_EQ(pd::crc16_dxl(kCheck, 9), 0xFEE8);
}

TEST(Crc, IncrementalEqualsOneShot) {
  const std::uint8_t r = pd::crc8_j1850_update(pd::kCrc8Init, kCheck, 4);
  EXPECT_EQ(pd::crc8_j1850_final(pd::crc8_j1850_update(r, kCheck + 4, 5)), 0x4B);
  EXPECT_EQ(pd::crc16_dxl(kCheck + 4, 5, pd::crc16_dxl(kCheck, 4)), 0xFEE8);
  EXPECT_EQ(pd::crc16_ccitt(kCheck + 3, 6, pd::crc16_ccitt(kCheck, 3)), 0x29B1);
}

// ROBOTIS e-Manual, "DYNAMIXEL Protocol 2.0", section Ping, Example 1
// (https://emanual.robotis.com/docs/en/dxl/protocol2/#ping): ping instruction packet to ID 1
//   FF FF FD 00 01 03 00 01 19 4E        (CRC 0x4E19, sent low byte first)
// and the status packet of ID 1 (XM430-W210, model 1030, firmware 38)
//   FF FF FD 00 01 07 00 55 00 06 04 26 65 5D
TEST(Crc, DynamixelPingExampleFromRobotisManual) {
  const std::uint8_t ping[] = {0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x03, 0x00, 0x01, 0x19, 0x4E};
  EXPECT_EQ(pd::crc16_dxl(ping, 8), 0x4E19);
  const std::uint8_t status[] = {0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x07, 0x00,
                                 0x55, 0x00, 0x06, 0x04, 0x26, 0x65, 0x5D};
  EXPECT_EQ(pd::crc16_dxl(status, 12), 0x5D65);

  // Our builders reproduce both packets byte for byte.
  std::array<std::uint8_t, 64> out{};
  std::size_t n = 0;
  ASSERT_EQ(pd::dxl::build_instruction(1, pd::dxl::kInstPing, {}, out, n), pd::dxl::DxlStatus::kOk);
  ASSERT_EQ(n, sizeof ping);
  EXPECT_EQ(std::memcmp(out.data(), ping, n), 0);
  const std::uint8_t p3[] = {0x06, 0x04, 0x26};
  ASSERT_EQ(pd::dxl::build_status(1, 0, p3, out, n), pd::dxl::DxlStatus::kOk);
  ASSERT_EQ(n, sizeof status);
  EXPECT_EQ(std::memcmp(out.data(), status, n), 0);
}

// Same manual, section Sync Read, Example: read 4 bytes at 132 from IDs 1 and 2
//   FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA
// and section Sync Write, Example: write 4 bytes at 116 (150 to ID 1, 170 to ID 2)
//   FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87
TEST(Crc, DynamixelSyncExamplesFromRobotisManual) {
  const std::uint8_t sync_read[] = {0xFF, 0xFF, 0xFD, 0x00, 0xFE, 0x09, 0x00, 0x82,
                                    0x84, 0x00, 0x04, 0x00, 0x01, 0x02, 0xCE, 0xFA};
  const std::uint8_t sync_write[] = {0xFF, 0xFF, 0xFD, 0x00, 0xFE, 0x11, 0x00, 0x83,
                                     0x74, 0x00, 0x04, 0x00, 0x01, 0x96, 0x00, 0x00,
                                     0x00, 0x02, 0xAA, 0x00, 0x00, 0x00, 0x82, 0x87};
  std::array<std::uint8_t, 64> out{};
  std::size_t n = 0;
  const std::uint8_t ids[] = {1, 2};
  ASSERT_EQ(pd::dxl::build_sync_read(132, 4, ids, out, n), pd::dxl::DxlStatus::kOk);
  ASSERT_EQ(n, sizeof sync_read);
  EXPECT_EQ(std::memcmp(out.data(), sync_read, n), 0);
  const std::uint8_t data[] = {0x96, 0, 0, 0, 0xAA, 0, 0, 0};
  ASSERT_EQ(pd::dxl::build_sync_write(116, 4, ids, data, out, n), pd::dxl::DxlStatus::kOk);
  ASSERT_EQ(n, sizeof sync_write);
  EXPECT_EQ(std::memcmp(out.data(), sync_write, n), 0);
}
