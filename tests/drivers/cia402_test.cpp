// The CiA 402 drive state machine (cia402.hpp): statusword decoding, the host's enable sequence
// against the drive's transitions, fault reset on a rising edge, quick stop.
#include <gtest/gtest.h>

#include "pedalwave/drivers/cia402.hpp"

namespace c4 = pedalwave::drivers::cia402;

TEST(Cia402, StatuswordsOfRealDrives) {
  // Typical statuswords (bit 4 voltage enabled, bit 9 remote set): 0x0250, 0x0231, 0x0233, 0x0237.
  EXPECT_EQ(c4::decode_statusword(0x0250), c4::State::kSwitchOnDisabled);
  EXPECT_EQ(c4::decode_statusword(0x0231), c4::State::kReadyToSwitchOn);
  EXPECT_EQ(c4::decode_statusword(0x0233), c4::State::kSwitchedOn);
  EXPECT_EQ(c4::decode_statusword(0x0237), c4::State::kOperationEnabled);
  EXPECT_EQ(c4::decode_statusword(0x0217), c4::State::kQuickStopActive);
  EXPECT_EQ(c4::decode_statusword(0x0218), c4::State::kFault);
  EXPECT_EQ(c4::decode_statusword(0x021F), c4::State::kFaultReactionActive);
  EXPECT_EQ(c4::decode_statusword(0x0000), c4::State::kNotReadyToSwitchOn);
  EXPECT_EQ(c4::decode_statusword(0x0001), c4::State::kUnknown);  // ready without quick-stop bit 5
  for (auto s : {c4::State::kNotReadyToSwitchOn, c4::State::kSwitchOnDisabled,
                 c4::State::kReadyToSwitchOn, c4::State::kSwitchedOn, c4::State::kOperationEnabled,
                 c4::State::kQuickStopActive, c4::State::kFaultReactionActive, c4::State::kFault})
    EXPECT_EQ(c4::decode_statusword(c4::statusword_bits(s)), s) << c4::to_string(s);
}

TEST(Cia402, TheHostEnablesADriveFromEveryState) {
  for (auto start : {c4::State::kNotReadyToSwitchOn, c4::State::kSwitchOnDisabled,
                     c4::State::kReadyToSwitchOn, c4::State::kSwitchedOn,
                     c4::State::kOperationEnabled, c4::State::kQuickStopActive,
                     c4::State::kFaultReactionActive, c4::State::kFault}) {
    SCOPED_TRACE(c4::to_string(start));
    c4::State s = start;
    std::uint16_t prev = c4::kCwEnableOperation;  // a fault reset needs an edge: bit 7 was 0
    int steps = 0;
    while (s != c4::State::kOperationEnabled && steps < 10) {
      const std::uint16_t cw = c4::controlword_to_enable(s, prev);
      s = c4::drive_transition(s, cw, prev);
      prev = cw;
      ++steps;
    }
    EXPECT_EQ(s, c4::State::kOperationEnabled);
    EXPECT_LE(steps, 6);  // fault: reset, shutdown, switch on, enable (+ fault reaction, disable)
  }
  // The usual path: 0x06, 0x07, 0x0F.
  EXPECT_EQ(c4::controlword_to_enable(c4::State::kSwitchOnDisabled, 0), 0x0006);
  EXPECT_EQ(c4::controlword_to_enable(c4::State::kReadyToSwitchOn, 0x06), 0x0007);
  EXPECT_EQ(c4::controlword_to_enable(c4::State::kSwitchedOn, 0x07), 0x000F);
}

TEST(Cia402, FaultResetNeedsARisingEdgeAndQuickStopHolds) {
  // Bit 7 held high is no new reset: the drive stays in Fault; the host drops it first.
  EXPECT_EQ(c4::drive_transition(c4::State::kFault, 0x80, 0x80), c4::State::kFault);
  EXPECT_EQ(c4::controlword_to_enable(c4::State::kFault, 0x80), 0x0000);
  EXPECT_EQ(c4::drive_transition(c4::State::kFault, 0x80, 0x00), c4::State::kSwitchOnDisabled);
  // Quick stop from Operation Enabled, then disable voltage.
  EXPECT_EQ(c4::drive_transition(c4::State::kOperationEnabled, c4::kCwQuickStop, 0x0F),
            c4::State::kQuickStopActive);
  EXPECT_EQ(c4::drive_transition(c4::State::kQuickStopActive, c4::kCwQuickStop, 0x02),
            c4::State::kQuickStopActive);
  EXPECT_EQ(c4::drive_transition(c4::State::kQuickStopActive, c4::kCwDisableVoltage, 0x02),
            c4::State::kSwitchOnDisabled);
  // Shutdown and disable operation from Operation Enabled.
  EXPECT_EQ(c4::drive_transition(c4::State::kOperationEnabled, c4::kCwShutdown, 0x0F),
            c4::State::kReadyToSwitchOn);
  EXPECT_EQ(c4::drive_transition(c4::State::kOperationEnabled, c4::kCwSwitchOn, 0x0F),
            c4::State::kSwitchedOn);
  // Enable operation straight from Ready to Switch On (3 + 4).
  EXPECT_EQ(c4::drive_transition(c4::State::kReadyToSwitchOn, c4::kCwEnableOperation, 0x06),
            c4::State::kOperationEnabled);
}
