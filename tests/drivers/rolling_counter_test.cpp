// Rolling-counter classification (fresh / duplicate / late / out-of-order) including wrap-around.
#include <gtest/gtest.h>

#include "pedalwave/drivers/rolling_counter.hpp"

namespace pd = pedalwave::drivers;
using pd::FrameAge;

namespace {
// Drives one module through host cycles; returns the classification of `echo` in cycle `cycle`.
struct Host {
  pd::RollingCounterState s;
  unsigned modulus;
  std::uint64_t cycle = 0;
  unsigned sync = 0;
  void next() {
    ++cycle;
    sync = (sync + 1) & 0xFF;
    pd::begin_cycle(s);
  }
  FrameAge rx(unsigned echo) { return pd::classify_frame(s, echo, sync, cycle, modulus); }
};
}  // namespace

TEST(RollingCounter, CleanSequenceIsFreshAcrossWrap) {
  for (unsigned m : {16u, 256u}) {
    Host h{{}, m};
    for (int i = 0; i < 600; ++i) {  // several wraps of both counter widths
      h.next();
      EXPECT_EQ(h.rx(h.sync), FrameAge::kFresh) << "m=" << m << " i=" << i;
    }
  }
}

TEST(RollingCounter, DuplicateLateOutOfOrder) {
  Host h{{}, 16};
  h.next();
  ASSERT_EQ(h.rx(h.sync), FrameAge::kFresh);
  EXPECT_EQ(h.rx(h.sync), FrameAge::kDuplicate);  // same counter twice in a cycle
  h.next();
  EXPECT_EQ(h.rx(h.sync - 1), FrameAge::kDuplicate);  // module repeats last cycle's counter
  h.next();                                            // frame of this cycle missing...
  h.next();
  EXPECT_EQ(h.rx(h.sync - 1), FrameAge::kLate);  // ...the previous cycle's arrives one cycle late
  EXPECT_EQ(h.rx(h.sync), FrameAge::kFresh);     // then the current one
  h.next();
  EXPECT_EQ(h.rx(h.sync - 3), FrameAge::kOutOfOrder);  // went backwards
}

TEST(RollingCounter, BackwardsCounterNeverAliasesToFresh) {
  // A module whose counter decreases by one per SYNC meets the host's counter every 8 cycles
  // (mod 16); the backwards step must still be classified out-of-order.
  Host h{{}, 16};
  h.next();
  ASSERT_EQ(h.rx(h.sync), FrameAge::kFresh);
  unsigned echo = h.sync;
  for (int i = 0; i < 64; ++i) {
    h.next();
    echo = (echo - 1) & 0x0F;
    EXPECT_EQ(h.rx(echo), FrameAge::kOutOfOrder) << i;
  }
  // Repeating counter: duplicate every cycle, even when it equals the host's counter mod 16.
  Host r{{}, 16};
  r.next();
  ASSERT_EQ(r.rx(r.sync), FrameAge::kFresh);
  const unsigned stuck = r.sync;
  for (int i = 0; i < 40; ++i) {
    r.next();
    EXPECT_EQ(r.rx(stuck), FrameAge::kDuplicate) << i;
  }
  // Recovery after a long repeat: the 4-bit distance to the stale counter is ambiguous, so the
  // first frame may be refused (out-of-order), never more than one; the next one is fresh.
  r.next();
  const FrameAge first = r.rx(r.sync);
  EXPECT_TRUE(first == FrameAge::kFresh || first == FrameAge::kOutOfOrder);
  r.next();
  EXPECT_EQ(r.rx(r.sync), FrameAge::kFresh);
  // Recovery after a short repeat (< M/2 cycles) is fresh at once.
  Host q{{}, 16};
  q.next();
  ASSERT_EQ(q.rx(q.sync), FrameAge::kFresh);
  const unsigned s2 = q.sync;
  for (int i = 0; i < 5; ++i) {
    q.next();
    EXPECT_EQ(q.rx(s2), FrameAge::kDuplicate);
  }
  q.next();
  EXPECT_EQ(q.rx(q.sync), FrameAge::kFresh);
}

TEST(RollingCounter, LongSilenceForgetsHistory) {
  Host h{{}, 16};
  h.next();
  ASSERT_EQ(h.rx(h.sync), FrameAge::kFresh);
  for (int i = 0; i < 16; ++i) h.next();  // 16 cycles without frames: counter is equal mod 16
  EXPECT_EQ(h.rx(h.sync), FrameAge::kFresh);
}
