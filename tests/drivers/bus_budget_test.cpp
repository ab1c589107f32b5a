// Bus budget: frame bit counts, fits / does-not-fit, and the content of the refusal message.
#include <gtest/gtest.h>

#include <stdexcept>
#include <string>

#include "pedalwave/drivers/bus_budget.hpp"

namespace pd = pedalwave::drivers;

namespace {
std::string refusal(const pd::CanBusSpec& s) {
  try {
    pd::check_can_bus_budget(s);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return {};
}
std::string refusal(const pd::SerialBusSpec& s) {
  try {
    pd::check_serial_bus_budget(s);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return {};
}
}  // namespace

TEST(BusBudget, ClassicFrameBitsWorstCase) {
  // 8n + 47 + ⌊(34 + 8n − 1)/4⌋: the textbook worst cases 135 (8 bytes) and 55 (0 bytes).
  EXPECT_EQ(pd::can_classic_frame_bits(8), 135);
  EXPECT_EQ(pd::can_classic_frame_bits(0), 55);
  EXPECT_EQ(pd::can_classic_frame_bits(2), 75);
  // FD: data-phase bits grow with the payload, the nominal part is constant.
  const auto a = pd::canfd_frame_bits(8), b = pd::canfd_frame_bits(64);
  EXPECT_EQ(a.nominal, b.nominal);
  EXPECT_GT(b.data, a.data + 8 * 56);
}

TEST(BusBudget, FiveJointsAtOneKilohertzClassicIsRefusedWithNumbersAndOptions) {
  pd::CanBusSpec s;
  s.joints = 5;
  s.period_s = 1e-3;
  s.bitrate = 1e6;
  const pd::BusBudget b = pd::can_bus_budget(s);
  EXPECT_FALSE(b.fits);
  EXPECT_EQ(b.frames, 1 + 5 + 5 + 5 + 1);  // SYNC, feedback, timing, commands, gains
  EXPECT_NEAR(b.bits_needed, 75 + 16 * 135, 1e-6);  // 2235
  EXPECT_NEAR(b.load, 2.235, 1e-9);
  const std::string m = refusal(s);
  ASSERT_FALSE(m.empty());
  EXPECT_NE(m.find("2235 bits"), std::string::npos) << m;
  EXPECT_NE(m.find("800 bits available"), std::string::npos) << m;
  EXPECT_NE(m.find("load 224 %"), std::string::npos) << m;
  EXPECT_NE(m.find("lower the cycle rate"), std::string::npos) << m;
  EXPECT_NE(m.find("CAN FD"), std::string::npos) << m;
  EXPECT_NE(m.find("second bus"), std::string::npos) << m;
  EXPECT_NE(m.find("≤ 1 joints per bus"), std::string::npos) << m;
}

TEST(BusBudget, FitsWhenItShould) {
  pd::CanBusSpec s;
  s.joints = 1;
  EXPECT_TRUE(pd::check_can_bus_budget(s).fits);  // 75 + 4·135 = 615 bits ≤ 800
  s.joints = 5;
  s.period_s = 4e-3;  // 250 Hz: 2235 ≤ 3200
  EXPECT_TRUE(pd::check_can_bus_budget(s).fits);
  s.period_s = 2e-3;  // 500 Hz: 2235 > 1600
  EXPECT_FALSE(pd::can_bus_budget(s).fits);
  s.period_s = 1e-3;
  s.fd = true;  // CAN FD 1 / 5 Mbit/s
  const pd::BusBudget fd = pd::check_can_bus_budget(s);
  EXPECT_TRUE(fd.fits);
  EXPECT_EQ(fd.frames, 1 + 5 + 1);
  EXPECT_LT(fd.load, 0.8);
  // CAN FD with a slow data phase does not fit, and says so.
  s.bitrate = 500e3;
  s.data_bitrate = 2e6;
  const std::string m = refusal(s);
  EXPECT_NE(m.find("CAN FD at 500 kbit/s (data phase 2 Mbit/s)"), std::string::npos) << m;
  EXPECT_NE(m.find("raise the CAN FD data bit rate"), std::string::npos) << m;
}

TEST(BusBudget, InvalidSpecIsRefusedNamingTheItem) {
  pd::CanBusSpec s;
  s.joints = 0;
  EXPECT_NE(refusal(s).find("joints = 0"), std::string::npos);
  s.joints = 3;
  s.bitrate = 0;
  EXPECT_NE(refusal(s).find("bitrate = 0"), std::string::npos);
}

TEST(BusBudget, SerialBus) {
  // 13 (sync counter) + 14+J (Sync Read) + J·31 (status: 15-byte block) + Sync Write worst case.
  EXPECT_EQ(pd::serial_bytes_per_cycle(5), 13 + 19 + 5 * 31 + (7 + 70 + 23 + 2));
  pd::SerialBusSpec s;
  s.joints = 5;
  s.baud = 4'000'000;
  s.period_s = 2e-3;
  const pd::BusBudget ok = pd::check_serial_bus_budget(s);
  EXPECT_TRUE(ok.fits);
  EXPECT_NEAR(ok.time_needed_s, 289 * 10.0 / 4e6 + 5 * 20e-6, 1e-12);
  s.period_s = 1e-3;  // 822.5 µs > 800 µs
  EXPECT_FALSE(pd::serial_bus_budget(s).fits);
  s.period_s = 2e-3;
  s.baud = 1'000'000;
  const std::string m = refusal(s);
  EXPECT_NE(m.find("289 bytes per cycle"), std::string::npos) << m;
  EXPECT_NE(m.find("load 150 %"), std::string::npos) << m;
  EXPECT_NE(m.find("raise the baud rate"), std::string::npos) << m;
  EXPECT_NE(m.find("second bus"), std::string::npos) << m;
  // Delays alone larger than the period.
  s.baud = 4'000'000;
  s.turnaround_s = 1e-3;
  EXPECT_NE(refusal(s).find("shorten the return delays"), std::string::npos);
}
