#include <gtest/gtest.h>

#include "pedalwave/runtime/loop_clock.hpp"

namespace {

using namespace pedalwave::runtime;

constexpr std::int64_t P = 1'000'000;  // 1 ms

TEST(NextDeadline, OnTimeCycleAdvancesOnePeriod) {
  const NextDeadline n = next_deadline(10 * P, P, 10 * P + P / 3);
  EXPECT_FALSE(n.overrun);
  EXPECT_EQ(n.skipped, 0u);
  EXPECT_EQ(n.deadline_ns, 11 * P);
}

TEST(NextDeadline, EndingExactlyOnTheNextDeadlineIsNotAnOverrun) {
  const NextDeadline n = next_deadline(10 * P, P, 11 * P);
  EXPECT_FALSE(n.overrun);
  EXPECT_EQ(n.deadline_ns, 11 * P);
}

TEST(NextDeadline, OverrunSkipsWholePeriodsToTheFirstGridPointAfterTheEnd) {
  // Ended 0.2 periods after the next deadline: that deadline is skipped, the one after is used.
  NextDeadline n = next_deadline(10 * P, P, 11 * P + P / 5);
  EXPECT_TRUE(n.overrun);
  EXPECT_EQ(n.skipped, 1u);
  EXPECT_EQ(n.deadline_ns, 12 * P);
  // Ended 3.5 periods after the wake-up: deadlines 11, 12, 13 are gone, the next is 14.
  n = next_deadline(10 * P, P, 13 * P + P / 2);
  EXPECT_EQ(n.skipped, 3u);
  EXPECT_EQ(n.deadline_ns, 14 * P);
  // Never a deadline in the past (no burst to catch up), always on the grid (no drift).
  for (std::int64_t end = 10 * P; end < 30 * P; end += 7919) {
    n = next_deadline(10 * P, P, end);
    EXPECT_GE(n.deadline_ns, end);
    EXPECT_EQ(n.deadline_ns % P, 0);
    EXPECT_LE(n.deadline_ns - end, P);
  }
}

TEST(LoopClock, LockstepAdvancesExactlyToEachDeadline) {
  LoopClock c(ClockMode::kLockstep, 5 * P);
  EXPECT_EQ(c.now(), 5 * P);
  EXPECT_TRUE(c.sleep_until(6 * P));
  EXPECT_EQ(c.now(), 6 * P);
  c.advance(P / 4);
  EXPECT_EQ(c.now(), 6 * P + P / 4);
  EXPECT_TRUE(c.sleep_until(6 * P)) << "a deadline in the past returns at once";
  EXPECT_EQ(c.now(), 6 * P + P / 4) << "and never moves the clock back";
}

TEST(LoopClock, RealtimeSleepNeverWakesBeforeTheDeadline) {
  LoopClock c(ClockMode::kRealtime, 0);
  c.advance(10 * P);  // no-op in real time
  std::int64_t deadline = monotonic_ns() + P;
  for (int i = 0; i < 20; ++i) {
    ASSERT_TRUE(c.sleep_until(deadline));
    EXPECT_GE(c.now(), deadline);
    deadline += P / 2;
  }
}

}  // namespace
