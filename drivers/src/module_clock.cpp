#include "pedalwave/drivers/module_clock.hpp"

#include <algorithm>
#include <cmath>

namespace pedalwave::drivers {

std::int64_t ModuleClock::update(std::uint32_t module_us, std::int64_t lower_ns) noexcept {
  if (!started_) {
    started_ = true;
    last_raw_ = module_us;
    last_m_ = 0;
    base_ns_ = lower_ns;
    in_block_ = 0;
  }
  const std::int64_t m = unwrap(module_us);
  last_raw_ = module_us;
  last_m_ = m;
  // Lower bound of the offset at m (relative to base_ns_).
  const double x = static_cast<double>(lower_ns - base_ns_) - 1000.0 * static_cast<double>(m);
  if (in_block_ == 0 || x > block_x_) {
    block_x_ = x;
    block_m_ = m;
  }
  ++in_block_;
  if (blocks_ == 0) {
    // Not one block yet: the running maximum, no drift.
    if (in_block_ == 1 || x > a_ + b_ * static_cast<double>(m - m_ref_)) {
      a_ = x;
      m_ref_ = m;
    }
  }
  if (in_block_ >= kBlock) close_block();
  // Continuous output: the drift-corrected interval, plus a bounded step toward the estimate.
  const double target = host_of(m);
  if (!out_started_) {
    out_started_ = true;
    out_ = target;
  } else {
    const double dm = static_cast<double>(m - out_m_);
    double next = out_ + (1000.0 + b_) * dm;
    const double lim = kSlew * 1000.0 * std::abs(dm);
    next += std::clamp(target - next, -lim, lim);
    out_ = next;
  }
  out_m_ = m;
  const std::int64_t host = base_ns_ + std::llround(out_);
  last_margin_ns_ = host - lower_ns;
  return host;
}

void ModuleClock::close_block() noexcept {
  in_block_ = 0;
  if (blocks_ > 0) {
    // Against the line so far: a block maximum off it by more than the largest drift could move
    // it is a change of the least delay, not drift (the VM's modules' thread ran every SYNC
    // ≥ 58 ms late for seconds: fitted through, the drift came out at 7000–19000 ppm).
    const double dev = block_x_ - (a_ + b_ * static_cast<double>(block_m_ - m_ref_));
    const double tol = kLineTolNs + kMaxDrift * 1000.0 * static_cast<double>(block_m_ - m_ref_);
    if (dev > tol) {
      // Far above: the blocks before were all late (their bounds loose). Start the fit again
      // from this one, the drift estimate kept.
      restart_fit();
    } else if (dev < -tol) {
      // Far below: this block was all late, its bound is loose; left out of the fit. If it
      // persists, the clock itself stepped (a module restarted): start again from here.
      if (++loose_ < kLooseBlocks) return;
      restart_fit();
    } else {
      loose_ = 0;
    }
  }
  bx_[static_cast<std::size_t>(head_)] = block_x_;
  bm_[static_cast<std::size_t>(head_)] = block_m_;
  head_ = (head_ + 1) % kBlocks;
  if (blocks_ < kBlocks) ++blocks_;
  if (blocks_ < 2) {
    a_ = block_x_;
    m_ref_ = block_m_;
    return;
  }
  // Least squares x = a + b (m − m_ref) through the block maxima, m_ref = the newest.
  const std::int64_t ref = block_m_;
  double sm = 0, sx = 0, smm = 0, smx = 0;
  for (int i = 0; i < blocks_; ++i) {
    const double dm = static_cast<double>(bm_[static_cast<std::size_t>(i)] - ref);
    const double xi = bx_[static_cast<std::size_t>(i)];
    sm += dm;
    sx += xi;
    smm += dm * dm;
    smx += dm * xi;
  }
  const double n = blocks_;
  const double det = n * smm - sm * sm;
  if (!(det > 0)) return;
  b_ = std::clamp((n * smx - sm * sx) / det, -kMaxDrift * 1000.0, kMaxDrift * 1000.0);
  a_ = (sx - b_ * sm) / n;
  m_ref_ = ref;
  // The line may sit below the best block bound by the envelope's noise; never below any bound
  // of the newest block (those are proven): lift it to the newest maximum if needed.
  const double at_newest = a_;
  if (block_x_ > at_newest) a_ = block_x_;
}

std::int64_t ModuleClock::to_host(std::uint32_t module_us) const noexcept {
  const double dm = static_cast<double>(unwrap(module_us) - out_m_);
  return base_ns_ + std::llround(out_ + (1000.0 + b_) * dm);
}

}  // namespace pedalwave::drivers
