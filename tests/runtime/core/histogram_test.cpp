#include <gtest/gtest.h>

#include <memory>
#include <random>

#include "alloc_counter.hpp"
#include "pedalwave/runtime/histogram.hpp"

namespace {

using pedalwave::runtime::LatencyHistogram;

TEST(LatencyHistogram, BinLayoutIsContiguous) {
  for (std::size_t b = 0; b + 1 < LatencyHistogram::kBins; ++b) {
    ASSERT_EQ(LatencyHistogram::bin_upper(b), LatencyHistogram::bin_lower(b + 1)) << "bin " << b;
    ASSERT_EQ(LatencyHistogram::bin_of(LatencyHistogram::bin_lower(b)), b);
    ASSERT_EQ(LatencyHistogram::bin_of(LatencyHistogram::bin_upper(b) - 1), b);
  }
  EXPECT_EQ(LatencyHistogram::bin_of(99), 0u);
  EXPECT_EQ(LatencyHistogram::bin_of(100'000), LatencyHistogram::kFineBins);
  EXPECT_EQ(LatencyHistogram::bin_of(6'000'000), LatencyHistogram::kBins - 1);
}

TEST(LatencyHistogram, PercentilesOfAKnownSetAreWithinOneBin) {
  auto h = std::make_unique<LatencyHistogram>();
  // 1000 samples: 1 µs, 2 µs, …, 1000 µs.
  for (int i = 1; i <= 1000; ++i) h->record(i * 1000);
  EXPECT_EQ(h->count(), 1000u);
  EXPECT_EQ(h->min(), 1000);
  EXPECT_EQ(h->max(), 1'000'000);
  EXPECT_DOUBLE_EQ(h->mean(), 500.5 * 1000);
  // The exact q-quantile is the ceil(q·n)-th sample; ours is the upper edge of its bin.
  auto near = [](std::int64_t got, std::int64_t exact) {
    EXPECT_GE(got, exact);
    EXPECT_LE(got - exact, LatencyHistogram::kCoarseWidth);
  };
  near(h->percentile(0.5), 500'000);
  near(h->percentile(0.99), 990'000);
  near(h->percentile(0.999), 999'000);
  EXPECT_EQ(h->percentile(1.0), 1'000'000) << "p100 is the exact max";
}

TEST(LatencyHistogram, FineBinsResolveSubMicrosecond) {
  LatencyHistogram h;
  for (int i = 0; i < 99; ++i) h.record(250);
  h.record(40'000);
  EXPECT_EQ(h.percentile(0.5), 300);  // 250 ns lies in [200, 300)
  EXPECT_EQ(h.percentile(0.99), 300);
  EXPECT_EQ(h.percentile(0.999), 40'000) << "clamped to the exact max";
}

TEST(LatencyHistogram, OverflowKeepsExactMax) {
  LatencyHistogram h;
  h.record(10);
  h.record(7'345'678);
  h.record(12'000'001);
  EXPECT_EQ(h.overflows(), 2u);
  EXPECT_EQ(h.max(), 12'000'001);
  EXPECT_EQ(h.percentile(0.99), 12'000'001);
  // Rank 2 of 3 (7.3 ms) lies in the overflow bin: reported as the exact max (conservative).
  EXPECT_EQ(h.percentile(0.5), 12'000'001);
  EXPECT_EQ(h.percentile(0.3), 100) << "rank 1 (10 ns) is in the first fine bin";
}

TEST(LatencyHistogram, NegativeValuesAreClampedAndCounted) {
  LatencyHistogram h;
  h.record(-500);
  h.record(150);
  EXPECT_EQ(h.negatives(), 1u);
  EXPECT_EQ(h.min(), -500);
  EXPECT_EQ(h.percentile(0.5), 100) << "the negative sample sits in bin 0";
}

TEST(LatencyHistogram, MergeEqualsRecordingEverythingInOne) {
  auto a = std::make_unique<LatencyHistogram>();
  auto b = std::make_unique<LatencyHistogram>();
  auto all = std::make_unique<LatencyHistogram>();
  std::mt19937_64 rng(7);
  std::lognormal_distribution<double> d(9.0, 1.5);  // ~8 µs median, long tail into overflow
  for (int i = 0; i < 20000; ++i) {
    const auto v = static_cast<std::int64_t>(d(rng));
    (i % 2 ? *a : *b).record(v);
    all->record(v);
  }
  a->merge(*b);
  EXPECT_EQ(a->count(), all->count());
  EXPECT_EQ(a->max(), all->max());
  EXPECT_EQ(a->min(), all->min());
  EXPECT_EQ(a->overflows(), all->overflows());
  for (double q : {0.1, 0.5, 0.9, 0.99, 0.999, 1.0}) EXPECT_EQ(a->percentile(q), all->percentile(q)) << q;
}

TEST(LatencyHistogram, RecordAllocatesNothing) {
  auto h = std::make_unique<LatencyHistogram>();
  pedalwave::test::AllocationScope scope;
  for (std::int64_t i = 0; i < 100000; ++i) h->record(i * 97);
  EXPECT_EQ(scope.count(), 0u);
}

TEST(LoopMetrics, TableNamesEveryStage) {
  auto m = std::make_unique<pedalwave::runtime::LoopMetrics>();
  m->wake.record(12'000);
  m->cycles = 1;
  const std::string t = pedalwave::runtime::format_table(*m);
  for (const char* s : {"wake", "read", "observe", "control", "write", "cycle", "p99.9", "12.0"})
    EXPECT_NE(t.find(s), std::string::npos) << s << "\n" << t;
}

}  // namespace

TEST(LatencyHistogram, BinCountsSumToTheCountAndSitWhereTheValuesFall) {
  LatencyHistogram h;
  h.record(250);         // fine bin [200, 300)
  h.record(250);
  h.record(150'500);     // coarse bin [150, 151) µs
  h.record(9'000'000);   // overflow
  std::uint64_t sum = 0;
  for (std::size_t b = 0; b < LatencyHistogram::kBins; ++b) sum += h.bin_count(b);
  EXPECT_EQ(sum, h.count());
  EXPECT_EQ(h.bin_count(LatencyHistogram::bin_of(250)), 2u);
  EXPECT_EQ(LatencyHistogram::bin_lower(LatencyHistogram::bin_of(250)), 200);
  EXPECT_EQ(h.bin_count(LatencyHistogram::bin_of(150'500)), 1u);
  EXPECT_EQ(h.bin_count(LatencyHistogram::kBins - 1), h.overflows());
  EXPECT_EQ(h.bin_count(LatencyHistogram::kBins), 0u) << "out of range: 0, no UB";
}
