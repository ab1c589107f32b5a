// SyntheticRobot: deterministic fake telemetry (no physics) so the DDS path, the monitor and the
// recorder can be exercised and demonstrated before the runtime loop is wired in. Every field of
// sample(seq) is a distinct, non-trivial function of (seq, joint), so a receiver can regenerate
// the exact sample for a received seq and compare field by field.
#pragma once

#include <cstdint>

#include "pedalwave/interface/telemetry_sink.hpp"

namespace pedalwave::telemetry {

class SyntheticRobot {
 public:
  // joints = N-1 in 1..kMaxJoints, rate_hz > 0; else std::invalid_argument.
  SyntheticRobot(int joints, double rate_hz);

  runtime::RobotDescription description() const;
  // The cycle sample at cycle `seq` (t_ns = 1 s + seq·period; a travelling wave in β, ...).
  runtime::CycleSample sample(std::uint64_t seq) const;
  // The k-th synthetic fault event (classes and joints cycle with k), happening at cycle `seq`.
  runtime::EventSample fault_event(std::uint64_t k, std::uint64_t seq) const;
  // A mode transition at cycle `seq`.
  runtime::EventSample mode_event(runtime::Mode from, runtime::Mode to, std::uint64_t seq) const;

  int joints() const noexcept { return joints_; }
  double rate_hz() const noexcept { return rate_hz_; }

 private:
  int joints_;
  double rate_hz_;
};

}  // namespace pedalwave::telemetry
