#include "pedalwave/telemetry/liveness.hpp"

#include <stdexcept>
#include <string>

namespace pedalwave::telemetry {

SilenceTracker::SilenceTracker(std::int64_t timeout_ns) : timeout_ns_(timeout_ns) {
  if (timeout_ns <= 0) {
    throw std::invalid_argument("silence timeout = " + std::to_string(timeout_ns) +
                                " ns: expected > 0");
  }
}

SilenceTracker::Transition SilenceTracker::on_sample(std::int64_t now_ns) {
  last_ns_ = now_ns;
  if (!heard_) {
    heard_ = true;
    return Transition::kFirstContact;
  }
  if (silent_) {
    silent_ = false;
    return Transition::kCameBack;
  }
  return Transition::kNone;
}

SilenceTracker::Transition SilenceTracker::check(std::int64_t now_ns) {
  if (heard_ && !silent_ && now_ns - last_ns_ > timeout_ns_) {
    silent_ = true;
    ++silences_;
    return Transition::kWentSilent;
  }
  return Transition::kNone;
}

}  // namespace pedalwave::telemetry
