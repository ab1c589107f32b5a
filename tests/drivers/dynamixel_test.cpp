// DYNAMIXEL Protocol 2.0 codec: stuffing, packet building and parsing, malformed input, register
// blocks.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "pedalwave/drivers/crc.hpp"
#include "pedalwave/drivers/dynamixel.hpp"
#include "pedalwave/drivers/wire.hpp"

namespace pd = pedalwave::drivers;
namespace dxl = pedalwave::drivers::dxl;
using dxl::DxlStatus;

TEST(Dynamixel, StuffingExampleAndRoundTrip) {
  // "FF FF FD" → "FF FF FD FD" (e-Manual, Packet Process).
  const std::uint8_t in[] = {0x01, 0xFF, 0xFF, 0xFD, 0x02, 0xFF, 0xFF, 0xFF, 0xFD};
  const std::uint8_t expect[] = {0x01, 0xFF, 0xFF, 0xFD, 0xFD, 0x02, 0xFF, 0xFF, 0xFF, 0xFD, 0xFD};
  std::array<std::uint8_t, 32> out{};
  std::size_t n = 0;
  ASSERT_EQ(dxl::stuff(in, out, n), DxlStatus::kOk);
  ASSERT_EQ(n, sizeof expect);
  EXPECT_EQ(std::memcmp(out.data(), expect, n), 0);
  std::array<std::uint8_t, 32> back{};
  std::size_t m = 0;
  ASSERT_EQ(dxl::unstuff(std::span<const std::uint8_t>(out.data(), n), back, m), DxlStatus::kOk);
  ASSERT_EQ(m, sizeof in);
  EXPECT_EQ(std::memcmp(back.data(), in, m), 0);

  // Random data biased towards FF/FD round-trips and never contains an unstuffed pattern.
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> pick(0, 3), any(0, 255);
  for (int rep = 0; rep < 2000; ++rep) {
    std::vector<std::uint8_t> v(static_cast<std::size_t>(any(rng) % 40));
    for (auto& b : v) {
      const int p = pick(rng);
      b = p == 0 ? 0xFF : p == 1 ? 0xFD : static_cast<std::uint8_t>(any(rng));
    }
    std::array<std::uint8_t, 128> s{};
    std::array<std::uint8_t, 128> un{};
    ASSERT_EQ(dxl::stuff(v, s, n), DxlStatus::kOk);
    EXPECT_LE(n, v.size() + v.size() / 3);  // worst-case bound used by the bus budget
    ASSERT_EQ(dxl::unstuff(std::span<const std::uint8_t>(s.data(), n), un, m), DxlStatus::kOk);
    ASSERT_EQ(m, v.size());
    EXPECT_TRUE(std::equal(v.begin(), v.end(), un.begin()));
  }
}

TEST(Dynamixel, UnstuffRejectsMissingStuffByte) {
  std::array<std::uint8_t, 16> out{};
  std::size_t n = 0;
  const std::uint8_t bad1[] = {0xFF, 0xFF, 0xFD, 0x00};
  EXPECT_EQ(dxl::unstuff(bad1, out, n), DxlStatus::kMalformed);
  const std::uint8_t bad2[] = {0x10, 0xFF, 0xFF, 0xFD};  // pattern at the very end
  EXPECT_EQ(dxl::unstuff(bad2, out, n), DxlStatus::kMalformed);
  const std::uint8_t big[] = {1, 2, 3, 4};
  std::array<std::uint8_t, 3> small{};
  EXPECT_EQ(dxl::unstuff(big, small, n), DxlStatus::kOverflow);
}

TEST(Dynamixel, ParseStatusPacketWithStuffedPayload) {
  // A feedback block whose bytes contain FF FF FD: β = −1 LSB (FF FF), β̇ low byte FD.
  std::uint8_t block[dxl::kFeedbackBlockSize] = {0xFF, 0xFF, 0xFD, 0x01, 0, 0, 0x08, 0x2A};
  std::array<std::uint8_t, 64> buf{};
  std::size_t n = 0;
  ASSERT_EQ(dxl::build_status(4, 0, block, buf, n), DxlStatus::kOk);
  EXPECT_EQ(n, 7 + 2 + dxl::kFeedbackBlockSize + 1 + 2);  // one stuffing byte
  dxl::Packet p{};
  std::size_t used = 0;
  ASSERT_EQ(dxl::parse_packet(std::span<const std::uint8_t>(buf.data(), n), p, used),
            DxlStatus::kOk);
  EXPECT_EQ(used, n);
  EXPECT_EQ(p.id, 4);
  EXPECT_EQ(p.instruction, dxl::kInstStatus);
  EXPECT_EQ(p.error, 0);
  ASSERT_EQ(p.param_count, dxl::kFeedbackBlockSize);
  EXPECT_EQ(std::memcmp(p.params.data(), block, dxl::kFeedbackBlockSize), 0);
}

TEST(Dynamixel, ParserHandlesGarbagePartialAndBadPackets) {
  std::array<std::uint8_t, 64> pkt{};
  std::size_t n = 0;
  const std::uint8_t params[] = {1, 2, 3};
  ASSERT_EQ(dxl::build_status(1, 0, params, pkt, n), DxlStatus::kOk);
  dxl::Packet p{};
  std::size_t used = 0;

  // Garbage before the header is reported and skipped.
  std::vector<std::uint8_t> s = {0x00, 0x13, 0xFF};
  s.insert(s.end(), pkt.begin(), pkt.begin() + static_cast<long>(n));
  ASSERT_EQ(dxl::parse_packet(s, p, used), DxlStatus::kGarbage);
  EXPECT_EQ(used, 3u);  // 00 13 FF, then FF FF FD 00 starts the packet
  s.erase(s.begin(), s.begin() + static_cast<long>(used));
  ASSERT_EQ(dxl::parse_packet(s, p, used), DxlStatus::kOk);
  EXPECT_EQ(used, n);
  // Garbage ending in a possible header prefix keeps the prefix for the next read.
  const std::uint8_t tail[] = {0x42, 0x42, 0xFF, 0xFF, 0xFD};
  ASSERT_EQ(dxl::parse_packet(tail, p, used), DxlStatus::kGarbage);
  EXPECT_EQ(used, 2u);

  // Every strict prefix of a packet needs more bytes (a short read), never fails.
  for (std::size_t k = 0; k < n; ++k) {
    EXPECT_EQ(dxl::parse_packet(std::span<const std::uint8_t>(pkt.data(), k), p, used),
              DxlStatus::kNeedMore)
        << k;
    EXPECT_EQ(used, 0u);
  }
  // Any single-bit error after the length field fails the CRC.
  for (std::size_t byte = dxl::kHeaderSize; byte < n; ++byte)
    for (int bit = 0; bit < 8; ++bit) {
      auto c = pkt;
      c[byte] ^= static_cast<std::uint8_t>(1u << bit);
      EXPECT_EQ(dxl::parse_packet(std::span<const std::uint8_t>(c.data(), n), p, used),
                DxlStatus::kChecksum);
      EXPECT_EQ(used, n);
    }
  // Impossible length (< 3) is malformed and resynchronizes byte-wise.
  auto c = pkt;
  c[5] = 2;
  c[6] = 0;
  EXPECT_EQ(dxl::parse_packet(std::span<const std::uint8_t>(c.data(), n), p, used),
            DxlStatus::kMalformed);
  EXPECT_EQ(used, 1u);
  // Oversized length.
  c = pkt;
  c[5] = 0xFF;
  c[6] = 0xFF;
  EXPECT_EQ(dxl::parse_packet(std::span<const std::uint8_t>(c.data(), n), p, used),
            DxlStatus::kMalformed);
}

TEST(Dynamixel, BadStuffingWithValidCrcIsMalformed) {
  // Hand-made packet with "FF FF FD 00" inside the parameters (not stuffed), CRC computed right.
  std::array<std::uint8_t, 32> b = {0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x00, 0x00,
                                    dxl::kInstStatus, 0x00, 0xFF, 0xFF, 0xFD, 0x05};
  const std::size_t body = 6;  // inst, err, 4 params
  pd::wire::put_u16(b.data() + 5, static_cast<std::uint16_t>(body + 2));
  const std::uint16_t crc = pd::crc16_dxl(b.data(), dxl::kHeaderSize + body);
  pd::wire::put_u16(b.data() + dxl::kHeaderSize + body, crc);
  dxl::Packet p{};
  std::size_t used = 0;
  EXPECT_EQ(dxl::parse_packet(std::span<const std::uint8_t>(b.data(), dxl::kHeaderSize + body + 2),
                              p, used),
            DxlStatus::kMalformed);
}

TEST(Dynamixel, RegisterBlocksRoundTrip) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < 1000; ++i) {
    dxl::CommandBlock c{30 * u(rng), 3 * u(rng), 30 * u(rng), 300 + 300 * u(rng), 30 + 30 * u(rng),
                        i % 2 == 0, static_cast<std::uint8_t>(i)};
    std::uint8_t raw[dxl::kCommandBlockSize];
    EXPECT_EQ(dxl::encode_command_block(c, raw), 0);
    dxl::CommandBlock d{};
    dxl::decode_command_block(raw, d);
    EXPECT_NEAR(d.tau, c.tau, pd::wire::kTauLsb / 2 + 1e-12);
    EXPECT_NEAR(d.beta_ref, c.beta_ref, pd::wire::kBetaLsb / 2 + 1e-12);
    EXPECT_NEAR(d.beta_dot_ref, c.beta_dot_ref, pd::wire::kBetaDotLsb / 2 + 1e-12);
    EXPECT_NEAR(d.kp, c.kp, pd::wire::kKpLsb / 2 + 1e-12);
    EXPECT_NEAR(d.kd, c.kd, pd::wire::kKdLsb / 2 + 1e-12);
    EXPECT_EQ(d.torque_off, c.torque_off);
    EXPECT_EQ(d.counter, c.counter);

    dxl::FeedbackBlock f{{3 * u(rng), 30 * u(rng), 0.6 * u(rng),
                          static_cast<std::uint16_t>(i % 2 ? pd::kStatusSaturated : 0)},
                         static_cast<std::uint8_t>(255 - i % 256)};
    std::uint8_t rf[dxl::kFeedbackBlockSize];
    EXPECT_EQ(dxl::encode_feedback_block(f, rf), 0);
    dxl::FeedbackBlock g{};
    dxl::decode_feedback_block(rf, g);
    EXPECT_NEAR(g.sample.beta, f.sample.beta, pd::wire::kBetaLsb / 2 + 1e-12);
    EXPECT_NEAR(g.sample.beta_dot, f.sample.beta_dot, pd::wire::kBetaDotLsb / 2 + 1e-12);
    EXPECT_NEAR(g.sample.deflection, f.sample.deflection, pd::wire::kDeflectionLsb / 2 + 1e-12);
    EXPECT_EQ(g.sample.status, f.sample.status);
    EXPECT_EQ(g.echo, f.echo);
  }
}

// Read and Write as the e-Manual's Protocol 2.0 examples, byte for byte (no npm package
// implementing Protocol 2.0 from ROBOTIS exists to test against: `npm view dynamixel` is a 404).
TEST(Dynamixel, ReadAndWriteMatchTheEManualExamples) {
  std::array<std::uint8_t, 32> out{};
  std::size_t n = 0;
  // READ ID 1, Present Position (132), 4 bytes.
  ASSERT_EQ(dxl::build_read(1, 132, 4, out, n), DxlStatus::kOk);
  const std::uint8_t read[] = {0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x07, 0x00,
                               0x02, 0x84, 0x00, 0x04, 0x00, 0x1D, 0x15};
  ASSERT_EQ(n, sizeof read);
  EXPECT_EQ(std::memcmp(out.data(), read, n), 0);
  // WRITE ID 1, Goal Position (116) = 512.
  const std::uint8_t value[] = {0x00, 0x02, 0x00, 0x00};
  ASSERT_EQ(dxl::build_write(1, 116, value, out, n), DxlStatus::kOk);
  const std::uint8_t write[] = {0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x09, 0x00, 0x03,
                                0x74, 0x00, 0x00, 0x02, 0x00, 0x00, 0xCA, 0x89};
  ASSERT_EQ(n, sizeof write);
  EXPECT_EQ(std::memcmp(out.data(), write, n), 0);
}

// The control table's access rules, by the table alone.
TEST(Dynamixel, ControlTableRules) {
  bool eeprom = false;
  // Reads: any range inside the table without a write-only byte; gaps read as 0.
  EXPECT_EQ(dxl::check_read(0, 12), 0);
  EXPECT_EQ(dxl::check_read(dxl::kRegFeedback, dxl::kFeedbackBlockSize), 0);
  EXPECT_EQ(dxl::check_read(dxl::kRegCommand, dxl::kCommandBlockSize), 0);
  EXPECT_EQ(dxl::check_read(1, 1), 0);  // half a register is readable
  EXPECT_EQ(dxl::check_read(dxl::kRegSyncCounter, 1), dxl::kErrAccess);
  EXPECT_EQ(dxl::check_read(130, 6), dxl::kErrAccess);
  EXPECT_EQ(dxl::check_read(0, 0), dxl::kErrDataLength);
  // Writes: whole writable registers, values in range.
  const std::uint8_t cmd[dxl::kCommandBlockSize] = {};
  EXPECT_EQ(dxl::check_write(dxl::kRegCommand, cmd, eeprom), 0);
  EXPECT_FALSE(eeprom);
  const std::uint8_t ee[] = {1, 6, 10, 0x2C, 0x01};  // ID, baud, return delay, command timeout
  EXPECT_EQ(dxl::check_write(dxl::kRegId, ee, eeprom), 0);
  EXPECT_TRUE(eeprom);
  const std::uint8_t one[] = {1}, two[] = {1, 0}, big[] = {253};
  EXPECT_EQ(dxl::check_write(dxl::kRegModelNumber, two, eeprom), dxl::kErrAccess);
  EXPECT_EQ(dxl::check_write(dxl::kRegHardwareError, one, eeprom), dxl::kErrAccess);
  EXPECT_EQ(dxl::check_write(3, one, eeprom), dxl::kErrAccess);  // gap
  EXPECT_EQ(dxl::check_write(dxl::kRegCommandTimeout, one, eeprom), dxl::kErrDataLength);
  EXPECT_EQ(dxl::check_write(dxl::kRegCommand + 1, two, eeprom), dxl::kErrDataLength);
  EXPECT_EQ(dxl::check_write(dxl::kRegId, big, eeprom), dxl::kErrDataRange);
  EXPECT_EQ(dxl::check_write(dxl::kRegTorqueEnable, two, eeprom), dxl::kErrAccess);  // 65: gap
  EXPECT_EQ(dxl::check_write(134, two, eeprom), dxl::kErrAccess);
  // Every register row lies inside the table, in order, without overlap.
  std::uint16_t end = 0;
  for (const dxl::Register& r : dxl::kRegisters) {
    if (r.size == 0) continue;
    EXPECT_GE(r.address, end) << r.name;
    end = static_cast<std::uint16_t>(r.address + r.size);
    EXPECT_EQ(dxl::register_at(r.address), &r);
  }
  EXPECT_EQ(end, dxl::kTableSize);
  EXPECT_EQ(dxl::baud_of_index(dxl::baud_index(4'000'000)), 4'000'000);
  EXPECT_EQ(dxl::baud_index(500'000), -1);
}

// The X-series' units (XM430-W350 e-Manual): 4096 counts per revolution, 0.229 rev/min, 2.69 mA.
TEST(DynamixelX, PresentValueUnitsAndGoalCurrent) {
  namespace x = dxl::x;
  std::uint8_t raw[x::kFeedbackSize]{};
  pd::wire::put_u16(raw, 32767);                                       // the tick's last value
  pd::wire::put_i16(raw + 6, -100);                                    // −269 mA
  pd::wire::put_u32(raw + 8, static_cast<std::uint32_t>(-262));        // −60 rev/min
  pd::wire::put_u32(raw + 12, 1024);                                   // a quarter turn
  x::PresentValues f{};
  x::decode_present_values(raw, x::kCurrentLsbXM430, f);
  EXPECT_EQ(f.tick, 32767);
  EXPECT_NEAR(f.current, -0.269, 1e-12);
  EXPECT_NEAR(f.velocity, -262 * 0.229 * 2 * M_PI / 60, 1e-9);
  EXPECT_NEAR(f.velocity, -2 * M_PI, 0.01);  // ≈ −1 rev/s
  EXPECT_NEAR(f.position, M_PI / 2, 1e-12);
  // Goal Current: 1 N·m through k_t = 1.78 N·m/A is 0.562 A = 209 counts; the limit saturates.
  std::uint8_t flags = 0;
  EXPECT_EQ(x::goal_current(1.0, 1.78, x::kCurrentLsbXM430, 1193, flags), 209);
  EXPECT_EQ(flags, 0);
  EXPECT_EQ(x::goal_current(-100.0, 1.78, x::kCurrentLsbXM430, 1193, flags), -1193);
  EXPECT_EQ(flags, pd::wire::kQuantClamped);
  flags = 0;
  EXPECT_EQ(x::goal_current(std::nan(""), 1.78, x::kCurrentLsbXM430, 1193, flags), 0);
  EXPECT_EQ(flags, pd::wire::kQuantNotFinite);
  // The feedback read spans Realtime Tick … Present Position, as the e-Manual's addresses.
  EXPECT_EQ(x::kFeedbackAddress, 120);
  EXPECT_EQ(x::kRegPresentCurrent, x::kRegRealtimeTick + 6);
  EXPECT_EQ(x::kRegPresentVelocity, x::kRegPresentCurrent + 2);
  EXPECT_EQ(x::kRegPresentPosition, x::kRegPresentVelocity + 4);
  EXPECT_EQ(x::kFeedbackAddress + x::kFeedbackSize, x::kRegPresentPosition + 4u);
}
