#include "pedalwave/runtime/histogram.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace pedalwave::runtime {

std::size_t LatencyHistogram::bin_of(std::int64_t ns) noexcept {
  if (ns < 0) ns = 0;
  if (ns < kFineEnd) return static_cast<std::size_t>(ns / kFineWidth);
  if (ns < kCoarseEnd) return kFineBins + static_cast<std::size_t>((ns - kFineEnd) / kCoarseWidth);
  return kBins - 1;
}

std::int64_t LatencyHistogram::bin_lower(std::size_t bin) noexcept {
  if (bin < kFineBins) return static_cast<std::int64_t>(bin) * kFineWidth;
  if (bin < kFineBins + kCoarseBins) return kFineEnd + static_cast<std::int64_t>(bin - kFineBins) * kCoarseWidth;
  return kCoarseEnd;
}

std::int64_t LatencyHistogram::bin_upper(std::size_t bin) noexcept {
  if (bin < kFineBins + kCoarseBins) return bin_lower(bin + 1);
  return INT64_MAX;
}

void LatencyHistogram::record(std::int64_t ns) noexcept {
  if (ns < 0) ++negatives_;
  ++bins_[bin_of(ns)];
  ++count_;
  max_ = std::max(max_, ns);
  min_ = std::min(min_, ns);
  sum_ += ns;
}

void LatencyHistogram::merge(const LatencyHistogram& o) noexcept {
  for (std::size_t i = 0; i < kBins; ++i) bins_[i] += o.bins_[i];
  count_ += o.count_;
  negatives_ += o.negatives_;
  max_ = std::max(max_, o.max_);
  min_ = std::min(min_, o.min_);
  sum_ += o.sum_;
}

std::int64_t LatencyHistogram::percentile(double q) const noexcept {
  if (count_ == 0) return 0;
  q = std::clamp(q, 0.0, 1.0);
  auto rank = static_cast<std::uint64_t>(std::ceil(q * static_cast<double>(count_)));
  rank = std::clamp<std::uint64_t>(rank, 1, count_);
  std::uint64_t seen = 0;
  for (std::size_t i = 0; i < kBins; ++i) {
    seen += bins_[i];
    if (seen >= rank) return std::min(bin_upper(i), max_);
  }
  return max_;
}

void LoopMetrics::merge(const LoopMetrics& o) noexcept {
  wake.merge(o.wake);
  read.merge(o.read);
  observe.merge(o.observe);
  control.merge(o.control);
  write.merge(o.write);
  cycle.merge(o.cycle);
  cycles += o.cycles;
  overruns += o.overruns;
  skipped_periods += o.skipped_periods;
  max_skipped = std::max(max_skipped, o.max_skipped);
}

std::string format_table(const LoopMetrics& m) {
  std::string out;
  char line[256];
  std::snprintf(line, sizeof line, "%-10s %10s %10s %10s %10s %10s %9s\n", "[us]", "count", "p50",
                "p99", "p99.9", "max", "overflow");
  out += line;
  auto row = [&](const char* name, const LatencyHistogram& h) {
    auto us = [](std::int64_t ns) { return static_cast<double>(ns) * 1e-3; };
    std::snprintf(line, sizeof line, "%-10s %10llu %10.1f %10.1f %10.1f %10.1f %9llu\n", name,
                  static_cast<unsigned long long>(h.count()), us(h.percentile(0.5)),
                  us(h.percentile(0.99)), us(h.percentile(0.999)), us(h.max()),
                  static_cast<unsigned long long>(h.overflows()));
    out += line;
  };
  row("wake", m.wake);
  row("read", m.read);
  row("observe", m.observe);
  row("control", m.control);
  row("write", m.write);
  row("cycle", m.cycle);
  std::snprintf(line, sizeof line, "cycles %llu, overruns %llu, skipped periods %llu (max %u at once)\n",
                static_cast<unsigned long long>(m.cycles), static_cast<unsigned long long>(m.overruns),
                static_cast<unsigned long long>(m.skipped_periods), m.max_skipped);
  out += line;
  return out;
}

}  // namespace pedalwave::runtime
