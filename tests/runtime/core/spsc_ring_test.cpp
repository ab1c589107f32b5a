// SpscRing: order, wrap-around, drop-when-full accounting, allocation-freedom and a two-thread
// stress test. The stress test is the one to run under ThreadSanitizer:
//   cmake -S . -B build/tsan -G Ninja -DPEDALWAVE_TSAN=ON -DPEDALWAVE_TOOLS=OFF -DPEDALWAVE_BENCH=OFF
//   cmake --build build/tsan --target test_runtime_ring && build/tsan/tests/runtime/core/test_runtime_ring
// (CI runs ASan+UBSan; TSan is a separate, manual build because the two cannot be combined.)
#include <gtest/gtest.h>

#include <atomic>
#include <cstdint>
#include <thread>

#include "alloc_counter.hpp"
#include "pedalwave/runtime/spsc_ring.hpp"

namespace {

using pedalwave::runtime::SpscRing;

struct Item {
  std::uint64_t seq;
  std::uint64_t check;  // = seq * 2654435761 (detects torn copies)
};

TEST(SpscRing, PopsInPushOrder) {
  SpscRing<int, 8> r;
  for (int i = 0; i < 5; ++i) EXPECT_TRUE(r.push(i));
  EXPECT_EQ(r.size(), 5u);
  int v = -1;
  for (int i = 0; i < 5; ++i) {
    ASSERT_TRUE(r.pop(v));
    EXPECT_EQ(v, i);
  }
  EXPECT_FALSE(r.pop(v));
  EXPECT_EQ(v, 4) << "pop on empty must leave the output untouched";
  EXPECT_TRUE(r.empty());
}

TEST(SpscRing, WrapsAroundManyTimes) {
  SpscRing<std::uint32_t, 4> r;
  std::uint32_t next_in = 0, next_out = 0, v = 0;
  // Push 3, pop 2, repeatedly: indices pass the capacity boundary many times.
  for (int round = 0; round < 1000; ++round) {
    for (int i = 0; i < 3 && r.size() < 4; ++i) ASSERT_TRUE(r.push(next_in++));
    for (int i = 0; i < 2; ++i) {
      ASSERT_TRUE(r.pop(v));
      ASSERT_EQ(v, next_out++);
    }
  }
  while (r.pop(v)) ASSERT_EQ(v, next_out++);
  EXPECT_EQ(next_in, next_out);
  EXPECT_EQ(r.drops(), 0u);
}

TEST(SpscRing, FullRingDropsNewestAndCounts) {
  SpscRing<int, 4> r;
  for (int i = 0; i < 4; ++i) EXPECT_TRUE(r.push(i));
  EXPECT_FALSE(r.push(100));
  EXPECT_FALSE(r.push(101));
  EXPECT_EQ(r.drops(), 2u);
  EXPECT_EQ(r.size(), 4u);
  int v = 0;
  ASSERT_TRUE(r.pop(v));
  EXPECT_EQ(v, 0) << "the oldest element survives a drop";
  EXPECT_TRUE(r.push(4)) << "one slot freed, push succeeds again";
  EXPECT_EQ(r.drops(), 2u);
  for (int want : {1, 2, 3, 4}) {
    ASSERT_TRUE(r.pop(v));
    EXPECT_EQ(v, want);
  }
  EXPECT_EQ(r.pushed(), 5u);
}

TEST(SpscRing, PushAndPopAllocateNothing) {
  auto r = std::make_unique<SpscRing<Item, 64>>();
  Item it{};
  pedalwave::test::AllocationScope scope;
  for (std::uint64_t i = 0; i < 1000; ++i) {
    r->push({i, i});
    if (i % 3 == 0) r->pop(it);
  }
  EXPECT_EQ(scope.count(), 0u);
  EXPECT_GT(r->drops(), 0u);
}

TEST(SpscRing, TwoThreadStressKeepsOrderAndAccountsEveryItem) {
  constexpr std::uint64_t kN = 2'000'000;
  auto r = std::make_unique<SpscRing<Item, 256>>();
  std::atomic<bool> done{false};
  std::uint64_t accepted = 0;
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < kN; ++i) {
      if (r->push({i, i * 2654435761u})) ++accepted;
    }
    done.store(true, std::memory_order_release);
  });
  std::uint64_t received = 0, last = 0, torn = 0, out_of_order = 0;
  bool first = true;
  Item it{};
  for (;;) {
    if (r->pop(it)) {
      ++received;
      if (it.check != it.seq * 2654435761u) ++torn;
      if (!first && it.seq <= last) ++out_of_order;
      last = it.seq;
      first = false;
    } else if (done.load(std::memory_order_acquire)) {
      if (!r->pop(it)) break;  // drained after the producer finished
      ++received;
      if (it.check != it.seq * 2654435761u) ++torn;
      if (it.seq <= last) ++out_of_order;
      last = it.seq;
    }
  }
  producer.join();
  EXPECT_EQ(torn, 0u);
  EXPECT_EQ(out_of_order, 0u);
  EXPECT_EQ(received, accepted);
  EXPECT_EQ(accepted + r->drops(), kN) << "every push is either delivered or counted as dropped";
}

}  // namespace
