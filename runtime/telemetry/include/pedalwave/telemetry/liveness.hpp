// SilenceTracker: "is the robot still talking?" for the monitor. Fed with the arrival time of
// every sample and polled with the current time; reports each transition once.
// Times are the monitor's CLOCK_MONOTONIC [ns] (passed in, never read here: testable).
#pragma once

#include <cstdint>

namespace pedalwave::telemetry {

class SilenceTracker {
 public:
  enum class Transition : std::uint8_t {
    kNone = 0,
    kFirstContact,  // first sample ever
    kWentSilent,    // no sample for longer than the timeout
    kCameBack,      // a sample after having been silent
  };

  // timeout_ns > 0, else std::invalid_argument naming the value.
  explicit SilenceTracker(std::int64_t timeout_ns);

  Transition on_sample(std::int64_t now_ns);   // a sample arrived at now_ns
  Transition check(std::int64_t now_ns);       // time passes (call at least every timeout/2)

  bool heard() const noexcept { return heard_; }     // at least one sample so far
  bool silent() const noexcept { return silent_; }   // currently silent
  std::int64_t last_sample_ns() const noexcept { return last_ns_; }
  std::int64_t timeout_ns() const noexcept { return timeout_ns_; }
  std::uint32_t silences() const noexcept { return silences_; }  // times it went silent

 private:
  std::int64_t timeout_ns_;
  std::int64_t last_ns_ = 0;
  bool heard_ = false;
  bool silent_ = false;
  std::uint32_t silences_ = 0;
};

}  // namespace pedalwave::telemetry
