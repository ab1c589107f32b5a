// The host's estimate of one module's clock (drivers/PROTOCOL.md §1.1): maps the module's free-
// running, wrapping microsecond counter onto CLOCK_MONOTONIC, with its offset and its drift.
//
// Each cycle gives one pair (m_k, h_k): the module's stamp of its sample (unwrapped, µs) and a
// host time no later than the sample (the SYNC left the host at h_k − wire time; it cannot have
// been sampled before it arrived). So x_k = h_k − 1000·m_k is a LOWER bound of the true offset
// o(m) = host − 1000·m, which drifts linearly: o(m) = a + b·m, b = drift [ns/µs = 1e3 ppm].
// Host delays (scheduling, queues) only ever make x_k smaller, so the least-delayed samples lie
// on the line: per block of kBlock samples the largest x_k is kept, and a least-squares line
// through the last kBlocks block maxima gives (a, b). Until two blocks exist the mapping is the
// running maximum with b = 0.
//
// The times handed out follow that estimate continuously: each sample's host time is the previous
// one plus the module-clock interval corrected for the estimated drift, plus a correction toward
// the estimate of at most kSlew of the interval (20 ppm). So differences of mapped times — what
// the observer integrates over — are exact to the clock's resolution and kSlew·dt even while the
// estimate converges or a block moves it; absolute times converge at kSlew (a 1 ms correction
// takes 50 s). Nothing downstream needs them sooner; the observer's residual does need the
// intervals: an interval error ε·dt misplaces ε·dt·(τ + k_p β_ref + k_d β̇_ref − k_p β) of the
// module law's impulse, ≈ ε·k_d·β̇ of torque (runtime/observer/README.md §1.2). At the former
// 1000 ppm that was 0.015 N·m per rad/s: at 100 Hz, where the estimate converges over seconds
// (blocks of 1.28 s), the walk's residual carried it for the first seconds and crossed the
// threshold (VM runs: actuator_torque at 2.6 s in every 60 s walk). At 20 ppm: ≤ 7.5e-4 N·m.
// update() and to_host() are O(1) (the fit: kBlocks points, once per block), allocation-free and
// noexcept.
#pragma once

#include <array>
#include <cstdint>

namespace pedalwave::drivers {

class ModuleClock {
 public:
  static constexpr int kBlock = 128;  // samples per envelope block [-]
  static constexpr int kBlocks = 16;  // blocks in the line fit [-]
  static constexpr double kSlew = 2e-5;  // largest correction per unit of interval [-]
  // The largest rate error a module clock may have (PROTOCOL.md §1.1: a crystal, tens of ppm;
  // 1000 ppm allows for any crystal or MEMS oscillator) [-]. The drift estimate is bounded by it,
  // and a block maximum off the line by more than it (plus kLineTolNs) could move it is a change
  // of the least delay, not drift: far above, the fit starts again from that block; far below,
  // the block is left out (kLooseBlocks in a row: the clock stepped, start again).
  static constexpr double kMaxDrift = 1e-3;
  static constexpr double kLineTolNs = 50e3;
  static constexpr int kLooseBlocks = 3;

  void reset() noexcept { *this = ModuleClock{}; }
  // One sample stamped `module_us` (the module's clock, wrapping at 2³²) that cannot have happened
  // before host time `lower_ns` (CLOCK_MONOTONIC) [ns]. Returns the sample's host time [ns].
  std::int64_t update(std::uint32_t module_us, std::int64_t lower_ns) noexcept;
  // Host time [ns] of module time `module_us`, taken as the one within ±2³¹ µs of the last update,
  // on the same continuous mapping as the last update's result.
  std::int64_t to_host(std::uint32_t module_us) const noexcept;
  bool started() const noexcept { return started_; }
  bool locked() const noexcept { return blocks_ >= 2; }  // drift estimated
  // Module clock rate error estimate [ppm]: x = host − 1000·m falls by 1000·ε per µs of a clock
  // running 1 + ε fast.
  double drift_ppm() const noexcept { return -b_ * 1e3; }
  // Host time minus the lower bound of the last sample [ns] (how far the estimate places the
  // sample after the earliest possible instant; ≥ 0 when the estimate is consistent).
  std::int64_t last_margin_ns() const noexcept { return last_margin_ns_; }

 private:
  std::int64_t unwrap(std::uint32_t us) const noexcept {
    return last_m_ + static_cast<std::int32_t>(us - last_raw_);
  }
  double host_of(std::int64_t m) const noexcept {
    return 1000.0 * static_cast<double>(m) + a_ + b_ * static_cast<double>(m - m_ref_);
  }
  void close_block() noexcept;

  bool started_ = false;
  std::uint32_t last_raw_ = 0;    // last stamp as received [µs]
  std::int64_t last_m_ = 0;       // last stamp, unwrapped (0 = the first) [µs]
  std::int64_t base_ns_ = 0;      // host time of the first lower bound [ns] (x is relative to it)
  // Current block: its best (largest) x and where.
  int in_block_ = 0;
  double block_x_ = 0.0;
  std::int64_t block_m_ = 0;
  // Maxima of the last blocks (ring).
  std::array<double, kBlocks> bx_{};
  std::array<std::int64_t, kBlocks> bm_{};
  int blocks_ = 0, head_ = 0;
  int loose_ = 0;  // blocks in a row far below the line [-]
  // The fit starts again from the next block (the drift estimate b_ kept).
  void restart_fit() noexcept { blocks_ = head_ = loose_ = 0; }
  // Mapping host − base = 1000·m + a + b·(m − m_ref) [ns].
  double a_ = 0.0, b_ = 0.0;
  std::int64_t m_ref_ = 0;
  std::int64_t last_margin_ns_ = 0;
  // The continuous output mapping: host − base of module time out_m_ [ns].
  bool out_started_ = false;
  double out_ = 0.0;
  std::int64_t out_m_ = 0;
};

}  // namespace pedalwave::drivers
