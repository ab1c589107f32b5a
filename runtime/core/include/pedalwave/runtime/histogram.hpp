// Fixed-bin latency histogram (wake-up latency, per-stage compute time) and the loop's metric set.
//
// Bins (values in ns; negative values are clamped into bin 0 and counted in negatives()):
//   [0, 100 µs)      100 ns wide   (1000 bins)  — compute times and good wake-ups
//   [100 µs, 5 ms)   1 µs wide     (4900 bins)  — bad wake-ups
//   [5 ms, ∞)        one overflow bin; the exact maximum is kept separately.
// record() is O(1), allocation-free, lock-free (single writer); the object is ~47 KB, sized at
// construction. Percentiles are conservative: the upper edge of the bin that holds the rank,
// clamped to the exact maximum (so percentile(1.0) == max()).
#pragma once

#include <array>
#include <cstdint>
#include <string>

namespace pedalwave::runtime {

class LatencyHistogram {
 public:
  static constexpr std::int64_t kFineWidth = 100;            // [ns]
  static constexpr std::int64_t kFineEnd = 100'000;          // [ns]
  static constexpr std::int64_t kCoarseWidth = 1'000;        // [ns]
  static constexpr std::int64_t kCoarseEnd = 5'000'000;      // [ns]
  static constexpr std::size_t kFineBins = kFineEnd / kFineWidth;
  static constexpr std::size_t kCoarseBins = (kCoarseEnd - kFineEnd) / kCoarseWidth;
  static constexpr std::size_t kBins = kFineBins + kCoarseBins + 1;  // + overflow

  void record(std::int64_t ns) noexcept;
  void merge(const LatencyHistogram& other) noexcept;
  void reset() noexcept { *this = LatencyHistogram{}; }

  std::uint64_t count() const noexcept { return count_; }
  std::uint64_t overflows() const noexcept { return bins_[kBins - 1]; }
  std::uint64_t negatives() const noexcept { return negatives_; }
  std::int64_t max() const noexcept { return count_ ? max_ : 0; }      // exact [ns]
  std::int64_t min() const noexcept { return count_ ? min_ : 0; }      // exact [ns]
  double mean() const noexcept { return count_ ? static_cast<double>(sum_) / static_cast<double>(count_) : 0.0; }  // [ns]

  // Smallest bin upper edge e such that at least ceil(q·count) samples are < e, clamped to max();
  // q in [0, 1]. 0 when empty [ns].
  std::int64_t percentile(double q) const noexcept;

  // Samples in one bin, 0 … kBins − 1 (the last is the overflow bin) [-].
  std::uint64_t bin_count(std::size_t bin) const noexcept { return bin < kBins ? bins_[bin] : 0; }

  // Bin index of a value, and the [lower, upper) edges of a bin (upper of overflow = INT64_MAX;
  // the exact largest value in it is max()).
  static std::size_t bin_of(std::int64_t ns) noexcept;
  static std::int64_t bin_lower(std::size_t bin) noexcept;
  static std::int64_t bin_upper(std::size_t bin) noexcept;

 private:
  std::array<std::uint64_t, kBins> bins_{};
  std::uint64_t count_ = 0;
  std::uint64_t negatives_ = 0;
  std::int64_t max_ = INT64_MIN;
  std::int64_t min_ = INT64_MAX;
  std::int64_t sum_ = 0;  // [ns] (overflows after ~290 years of 1 ms samples)
};

// The metrics the loop keeps (recorded by the real-time thread; read after the loop has stopped,
// or copied out by the owner — never read concurrently with record()).
struct LoopMetrics {
  LatencyHistogram wake;     // wake-up time − deadline [ns]
  LatencyHistogram read;     // driver read [ns]
  LatencyHistogram observe;  // observer [ns]
  LatencyHistogram control;  // controller [ns]
  LatencyHistogram write;    // driver write [ns]
  LatencyHistogram cycle;    // wake-up → end of publish [ns]
  std::uint64_t cycles = 0;           // cycles run [-]
  std::uint64_t overruns = 0;         // cycles that ended after the next deadline [-]
  std::uint64_t skipped_periods = 0;  // periods skipped after overruns [-]
  std::uint32_t max_skipped = 0;      // largest skip after one overrun [-]

  void merge(const LoopMetrics& o) noexcept;
};

// A fixed-width table, one row per histogram: count, p50, p99, p99.9, max (µs), overflows.
std::string format_table(const LoopMetrics& m);

}  // namespace pedalwave::runtime
