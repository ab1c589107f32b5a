// Running cyclictest (rt-tests) as a child process and reading its histogram output.
#pragma once

#include <cstdint>
#include <string>
#include <sys/types.h>
#include <vector>

namespace pedalwave::rtbench {

// Parsed `cyclictest -q -h N` output for one thread (bins of 1 µs, values truncated to µs).
struct CyclictestHistogram {
  std::vector<std::uint64_t> bins;  // bins[i] = samples with latency in [i, i+1) µs
  std::uint64_t overflows = 0;      // samples ≥ N µs
  std::uint64_t total = 0;          // in-histogram + overflows
  std::int64_t min_us = -1, avg_us = -1, max_us = -1;  // cyclictest's own summary [µs]
  bool ok = false;
  std::string error;

  // Upper bound of the q-quantile [µs]: the bin index holding rank ceil(q·total); a rank in the
  // overflow bin reports max_us. −1 when empty.
  std::int64_t percentile_us(double q) const;
};

CyclictestHistogram parse_cyclictest(const std::string& text);

struct CyclictestRun {
  pid_t pid = -1;
  std::string out_path, err_path, command;
  std::string start_error;  // non-empty: it did not start
};

// Starts cyclictest in the background with one measurement thread.
CyclictestRun start_cyclictest(const std::string& exe, int priority, int interval_us, int seconds,
                               int hist_us, int cpu, bool mlock);
// Waits for it and parses; on failure ok = false with the reason (exit status + stderr).
CyclictestHistogram finish_cyclictest(CyclictestRun& run);

}  // namespace pedalwave::rtbench
