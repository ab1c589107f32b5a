// The module bank's time keeping between SYNCs, without a transport: a host whose SYNC is
// overdue does not stop the emulated world (keep_up), a machine that holds the modules' own
// thread holds the simulated world with it (on_turn → ModulePlant::hold).
#include <gtest/gtest.h>

#include <cstdint>

#include "pedalwave/drivers/module_emulator.hpp"
#include "test_plant.hpp"

namespace pd = pedalwave::drivers;
using pedalwave::test::FirstOrderPlant;

namespace {

constexpr std::int64_t kMs = 1'000'000;
constexpr std::int64_t kT0 = 1'000 * kMs;

pd::EmulatorConfig config() {
  pd::EmulatorConfig ec;
  ec.joints = 2;
  ec.command_timeout_ns = 500 * kMs;
  return ec;
}

// SYNCs every `interval` (2 ms) from kT0, six of them, a live command latched after each.
void walk(pd::ModuleBank& bank, bool torque_off = false, std::int64_t interval = 2 * kMs) {
  for (int k = 0; k <= 5; ++k) {
    const std::int64_t t = kT0 + interval * k;
    bank.on_sync(static_cast<std::uint8_t>(k + 1), t);
    for (int j = 0; j < 2; ++j)
      bank.latch(j, 0.1, 0.0, 0.0, true, 1.0, 0.01, torque_off, static_cast<std::uint8_t>(k + 1),
                 t + kMs / 10);
  }
}

TEST(ModuleBank, KeepsThePlantAtWallTimeWhileTheHostsSyncIsOverdue) {
  FirstOrderPlant plant;
  pd::ModuleBank bank(config(), plant);
  walk(bank);
  const std::int64_t last = kT0 + 10 * kMs + kMs / 10;  // the last latch
  ASSERT_EQ(plant.plant_ns(), last);
  bank.keep_up(last + 3 * kMs);  // within 2 SYNC intervals: the host is on time
  EXPECT_EQ(plant.plant_ns(), last);
  // The host stalls: the front end turns every ~1 ms; the plant never lags wall time by more
  // than two SYNC intervals.
  for (std::int64_t t = last + kMs; t <= last + 300 * kMs; t += kMs) {
    bank.keep_up(t);
    EXPECT_GE(plant.plant_ns(), t - 4 * kMs) << "ns behind at " << t - last;
  }
  EXPECT_GT(bank.stats().keep_ups.load(), 50u);
  // Past the command lifetime of the last SYNC the host is away, not late: the plant waits.
  const std::int64_t reached = plant.plant_ns();
  bank.keep_up(kT0 + 10 * kMs + 501 * kMs);
  EXPECT_EQ(plant.plant_ns(), reached);
}

TEST(ModuleBank, AfterASafeStopThePlantWaitsForTheHost) {
  FirstOrderPlant plant;
  pd::ModuleBank bank(config(), plant);
  walk(bank, /*torque_off=*/true);
  const std::int64_t reached = plant.plant_ns();
  for (std::int64_t t = reached + kMs; t <= reached + 100 * kMs; t += kMs) bank.keep_up(t);
  EXPECT_EQ(plant.plant_ns(), reached);
  EXPECT_EQ(bank.stats().keep_ups.load(), 0u);
}

TEST(ModuleBank, ATurnHeldByTheMachineHoldsThePlantRatherThanIntegratingIt) {
  FirstOrderPlant plant;
  pd::ModuleBank bank(config(), plant);
  walk(bank);
  std::int64_t t = kT0 + 11 * kMs;
  bank.end_turn(t);
  bank.on_turn(t + kMs);  // a normal turn (≤ 1 ms poll)
  bank.end_turn(t + kMs);
  EXPECT_EQ(plant.held_ns(), 0);
  bank.on_turn(t + 231 * kMs);  // the machine held the thread 230 ms
  EXPECT_EQ(plant.held_ns(), 230 * kMs);
  EXPECT_EQ(bank.stats().self_stalls.load(), 1u);
  EXPECT_EQ(bank.stats().self_stall_holds.load(), 1u);
  // The next SYNC integrates only what came after the hold.
  bank.end_turn(t + 231 * kMs);
  bank.on_sync(7, t + 232 * kMs);
  EXPECT_EQ(plant.plant_ns(), t + 232 * kMs);
}

// At 100 Hz a 50 ms machine stall is 5 SYNC intervals: the host's observer integrates across
// it, so the plant must have moved with the modules' clocks. Not held: integrated at the next SYNC.
TEST(ModuleBank, AStallShorterThanTenSyncIntervalsIsIntegratedNotHeld) {
  FirstOrderPlant plant;
  pd::ModuleBank bank(config(), plant);
  walk(bank, false, 10 * kMs);  // SYNCs at 100 Hz
  const std::int64_t t = kT0 + 50 * kMs + kMs;
  bank.end_turn(t);
  bank.on_turn(t + 50 * kMs);  // the machine held the thread 50 ms
  EXPECT_EQ(plant.held_ns(), 0);
  EXPECT_EQ(bank.stats().self_stalls.load(), 1u);
  EXPECT_EQ(bank.stats().self_stall_holds.load(), 0u);
  bank.end_turn(t + 50 * kMs);
  bank.on_sync(7, t + 51 * kMs);
  EXPECT_EQ(plant.plant_ns(), t + 51 * kMs);
  EXPECT_EQ(plant.held_ns(), 0) << "the plant moved over the whole span, as the modules' clocks did";
  // 110 ms (11 intervals) is held.
  bank.end_turn(t + 52 * kMs);
  bank.on_turn(t + 162 * kMs);
  EXPECT_EQ(plant.held_ns(), 110 * kMs);
  EXPECT_EQ(bank.stats().self_stall_holds.load(), 1u);
}

// After an overrun the host's next SYNC comes early (a late cycle, then the next one on time: an
// interval of 2 ms among 10 ms ones). The usual interval is the typical one, not the shortest:
// judged against the shortest, a 26 ms machine stall in the VM at 100 Hz was held (> 10 × 2 ms)
// while the modules' clocks ran on, and the observer saw β lag β̇ by the span on every joint
// (|c| = 0.04–0.07 rad, a false encoder_jump) in an interval it bridges.
TEST(ModuleBank, ASyncThatCameEarlyAfterAnOverrunDoesNotShortenTheUsualInterval) {
  FirstOrderPlant plant;
  pd::ModuleBank bank(config(), plant);
  std::int64_t t = kT0;
  for (int k = 0; k < 16; ++k) {
    // 100 Hz, one late cycle (8 ms late) every fourth: intervals 18, 2, 10, 10 ms.
    const std::int64_t at = t + (k % 4 == 0 ? 8 * kMs : 0);
    bank.on_sync(static_cast<std::uint8_t>(k + 1), at);
    for (int j = 0; j < 2; ++j)
      bank.latch(j, 0.1, 0.0, 0.0, true, 1.0, 0.01, false, static_cast<std::uint8_t>(k + 1), at + kMs / 10);
    t += 10 * kMs;
  }
  const std::int64_t last = t - 10 * kMs + kMs / 10;
  bank.end_turn(last + kMs);
  bank.on_turn(last + 31 * kMs);  // the machine held the thread 30 ms: 3 intervals
  EXPECT_EQ(bank.stats().self_stalls.load(), 1u);
  EXPECT_EQ(bank.stats().self_stall_holds.load(), 0u) << "30 ms is 3 of the host's 10 ms intervals";
  EXPECT_EQ(plant.held_ns(), 0);
  bank.end_turn(last + 31 * kMs);
  bank.on_turn(last + 141 * kMs);  // 110 ms: 11 intervals, held
  EXPECT_EQ(plant.held_ns(), 110 * kMs);
}

}  // namespace
