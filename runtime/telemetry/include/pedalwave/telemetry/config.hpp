// Telemetry configuration: which DDS domain and network interface, how much of the loop rate each
// state topic carries, and whether (and within which bounds) operator commands are accepted.
// validate() throws std::invalid_argument naming the item, the value and what was expected; the
// DdsTelemetry and TelemetrySubscriber constructors call it.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace pedalwave::telemetry {

// Where the participants live. Shared by the robot side (TelemetryConfig) and the monitor side
// (SubscriberConfig).
struct DomainConfig {
  std::uint32_t domain_id = 0;       // DDS domain id [-], 0..232 (RTPS port arithmetic)
  // Network interface the participant binds to. "lo" (default, the demo) has no multicast on
  // Linux, so discovery goes by unicast to 127.0.0.1 (plus `peers`). Any other name keeps
  // Cyclone's multicast discovery (plus `peers` if given). "" lets Cyclone choose.
  std::string interface = "lo";
  std::vector<std::string> peers;    // extra unicast discovery peers (IPv4 addresses / host names)
};

// Publish every k-th cycle on each high-rate topic (by CycleSample::seq % k == 0), k >= 1.
// At 1 kHz, k = 1 is 1000 samples/s, k = 10 is 100 samples/s.
struct Decimation {
  int joint_state = 1;        // rt/pedalwave/joint_state [-]
  int controller_state = 1;   // rt/pedalwave/controller_state [-]
  int observer_state = 1;     // rt/pedalwave/observer_state [-]
  int loop_timing = 1;        // rt/pedalwave/loop_timing [-]
};

// Bounds an operator kSetGait command must satisfy (closed intervals, finite numbers).
struct CommandBounds {
  double amplitude_min = 0.0;   // A_p lower bound [rad]
  double amplitude_max = 1.2;   // A_p upper bound [rad]
  double omega_min = 0.0;       // ω lower bound [rad/s]
  double omega_max = 12.0;      // ω upper bound [rad/s]
  double eta_min = 0.0;         // nominal η lower bound [rad]
  double eta_max = 1.6;         // nominal η upper bound [rad]
};

struct TelemetryConfig {
  std::uint32_t domain_id = 0;       // see DomainConfig
  std::string interface = "lo";      // see DomainConfig
  std::vector<std::string> peers;    // see DomainConfig
  Decimation decimation;
  // false: every command but emergency stop is rejected (with that reason published);
  // emergency stop is always honoured.
  bool enable_commands = true;
  CommandBounds command_bounds;

  DomainConfig domain() const { return {domain_id, interface, peers}; }
  void validate() const;  // throws std::invalid_argument
};

struct SubscriberConfig {
  std::uint32_t domain_id = 0;       // see DomainConfig
  std::string interface = "lo";      // see DomainConfig
  std::vector<std::string> peers;    // see DomainConfig
  // Reader history per high-rate topic (keep-last depth): how many samples may arrive between two
  // polls before the oldest are overwritten. 256 covers 250 ms at 1 kHz.
  int state_history_depth = 256;     // [-], 1..10000
  std::string sender = "pedalwave_monitor";  // written into OperatorCommand_::sender (<= 31 chars)

  DomainConfig domain() const { return {domain_id, interface, peers}; }
  void validate() const;  // throws std::invalid_argument
};

void validate(const DomainConfig& d);  // throws std::invalid_argument

// The Cyclone DDS 0.10 configuration XML for `d` (passed to dds_create_domain). Exposed for the
// README and for tests.
std::string cyclone_config_xml(const DomainConfig& d);

}  // namespace pedalwave::telemetry
