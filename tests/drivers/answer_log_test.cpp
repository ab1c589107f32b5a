// Answers placed among the host's cycles (drivers/answer_log.hpp): the SYNC each answered and the
// command its module had applied, from 4- or 8-bit counters.
#include "pedalwave/drivers/answer_log.hpp"

#include <gtest/gtest.h>

#include <cstdint>

namespace pd = pedalwave::drivers;

namespace {
// A host that ran cycles 1…n, each a SYNC and a command with Command::seq = 1000 + cycle.
pd::CycleLog host_log(std::uint64_t n) {
  pd::CycleLog log;
  for (std::uint64_t k = 1; k <= n; ++k) {
    log.sync(k, static_cast<std::int64_t>(k) * 10'000'000);
    log.command(k, 1000 + k);
  }
  return log;
}
}  // namespace

// A module answering SYNC k has applied the command of cycle k − 1 (commands follow their SYNC;
// the module handles frames in order), or an older one if commands were lost: the newest cycle
// before k with the tag's residue.
TEST(CycleLog, TheAppliedCommandIsTheNewestBeforeTheAnsweredSyncWithItsTag) {
  const pd::CycleLog log = host_log(100);
  EXPECT_EQ(log.applied(50, 49 % 16, 16), 1049u);
  EXPECT_EQ(log.applied(50, 47 % 16, 16), 1047u) << "two commands lost on the way";
  EXPECT_EQ(log.applied(50, 50 % 16, 16), 1034u) << "tag 50 mod 16: the newest before 50 is 34";
  EXPECT_EQ(log.applied(50, 49 % 256, 256), 1049u);
  EXPECT_EQ(log.applied(50, 60, 256), pd::kUnknownSeq) << "cycle 60 − 256 is before the first";
  EXPECT_EQ(log.applied(1, 0, 16), pd::kUnknownSeq);
  EXPECT_EQ(log.sync_lower(42), 420'000'000);
  EXPECT_EQ(log.sync_lower(101), 0) << "not sent yet";
  // A cycle that wrote no command (the loop's write was skipped) is no command's cycle.
  pd::CycleLog gap = host_log(100);
  gap.sync(101, 1);
  gap.sync(102, 2);
  EXPECT_EQ(gap.applied(102, 101 % 16, 16), pd::kUnknownSeq);
  // Older than the log's 256 cycles: unknown, not the entry that replaced it.
  const pd::CycleLog old = host_log(400);
  EXPECT_EQ(old.sync_lower(100), 0);
  EXPECT_EQ(old.applied(300, 299 % 16, 16), 1299u);
}

// Answers in step (each cycle's own, or the previous one's arriving late): one number each.
TEST(AnswerTrack, AnswersInStepArePlacedForSure) {
  pd::AnswerTrack t;
  for (std::uint64_t c = 1; c <= 100; ++c) {
    if (c % 7 == 0) {  // the answer to c comes late, next cycle
      t.end_cycle(c, false);
      continue;
    }
    if (c % 7 == 1 && c > 1) {
      EXPECT_EQ(t.take((c - 1) % 16, 16, c), c - 1);
    }
    EXPECT_EQ(t.take(c % 16, 16, c), c);
    EXPECT_TRUE(t.sure()) << c;
    t.end_cycle(c, true);
  }
  EXPECT_EQ(t.take(100 % 16, 16, 101), 0u) << "the same answer again";
  EXPECT_EQ(t.take(98 % 16, 16, 101), 0u) << "backward";
}

// The module's thread held for 17 cycles while the host ran (the VM under load): it answers its
// backlog afterwards, all at once. The first answer is the 17 cycles old SYNC's; "the newest SYNC
// with that counter" would have been one 16 cycles younger, and its tag a command 16 cycles off.
// The track follows the answers in order but is unsure (another SYNC 16 cycles apart fits as
// well) until the module answers in step for kInStep cycles.
TEST(AnswerTrack, AHeldModulesBacklogIsFollowedInOrderAndUnsureUntilInStep) {
  pd::AnswerTrack t;
  for (std::uint64_t c = 1; c <= 40; ++c) {
    ASSERT_EQ(t.take(c % 16, 16, c), c);
    t.end_cycle(c, true);
  }
  for (std::uint64_t c = 41; c <= 56; ++c) t.end_cycle(c, false);  // held: SYNCs 41…57 queue
  // Cycle 57: the backlog's answers 41…50 arrive (the wire paces them), 51…57 in cycle 58.
  for (std::uint64_t x = 41; x <= 50; ++x) {
    EXPECT_EQ(t.take(x % 16, 16, 57), x);
    EXPECT_FALSE(t.sure()) << x << " or " << x + 16;
  }
  t.end_cycle(57, false);
  for (std::uint64_t x = 51; x <= 58; ++x) EXPECT_EQ(t.take(x % 16, 16, 58), x);
  EXPECT_FALSE(t.sure()) << "the answer to 58 came in a burst: not yet in step";
  t.end_cycle(58, true);
  for (std::uint64_t c = 59; c < 59 + pd::AnswerTrack::kInStep; ++c) {
    EXPECT_FALSE(t.sure());
    EXPECT_EQ(t.take(c % 16, 16, c), c);
    t.end_cycle(c, true);
  }
  EXPECT_TRUE(t.sure());
  EXPECT_EQ(t.take(62 % 16, 16, 62), 62u);
  EXPECT_TRUE(t.sure());
}

// The other way a track loses its place: the module answered, but 20 answers were lost. Followed
// in order, its next answer (to SYNC 61) reads as SYNC 45's; unsure, it is re-anchored at the
// cycle it answers in step with.
TEST(AnswerTrack, LostAnswersAreReanchoredWhenTheModuleAnswersInStep) {
  pd::AnswerTrack t;
  for (std::uint64_t c = 1; c <= 40; ++c) {
    t.take(c % 16, 16, c);
    t.end_cycle(c, true);
  }
  for (std::uint64_t c = 41; c <= 60; ++c) t.end_cycle(c, false);
  for (std::uint64_t c = 61; c < 61 + pd::AnswerTrack::kInStep; ++c) {
    t.take(c % 16, 16, c);
    EXPECT_FALSE(t.sure()) << c;
    t.end_cycle(c, true);
  }
  EXPECT_TRUE(t.sure());
  EXPECT_EQ(t.take(64 % 16, 16, 64), 64u);
}

// A module first heard after more cycles than its counter spans cannot be placed for sure.
TEST(AnswerTrack, AFirstAnswerAfterMoreThanTheCounterSpansIsUnsure) {
  pd::AnswerTrack early, late;
  EXPECT_EQ(early.take(3, 16, 3), 3u);
  EXPECT_TRUE(early.sure());
  EXPECT_EQ(late.take(40 % 16, 16, 40), 40u);
  EXPECT_FALSE(late.sure());
}
