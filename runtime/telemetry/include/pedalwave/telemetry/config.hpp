// Telemetry configuration: which DDS domain and network interface, how much of the loop rate each
// state topic carries, and whether (and within which bounds) operator commands are accepted.
// validate() throws std::invalid_argument naming the item, the value and what was expected; the
// DdsTelemetry and TelemetrySubscriber constructors call it.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "pedalwave/telemetry/security.hpp"

namespace pedalwave::telemetry {

// Where the participants live. Shared by the robot side (TelemetryConfig) and the monitor side
// (SubscriberConfig).
struct DomainConfig {
  std::uint32_t domain_id = 0;       // DDS domain id [-], 0..232 (RTPS port arithmetic)
  // Network interface the participant binds to:
  //   "lo"     localhost only: Linux's lo has no multicast, so discovery goes by unicast to
  //            127.0.0.1 (plus `peers`); nothing leaves the host.
  //   "eth0".. that interface with Cyclone's multicast discovery (plus `peers` if given): what a
  //            default ROS 2 / Cyclone participant on another host uses.
  //   ""       Cyclone's own choice, exactly as a default ROS 2 / Cyclone participant makes it:
  //            the configuration in CYCLONEDDS_URI when that is set, else Cyclone's defaults
  //            (multicast SPDP on the first multicast-capable interface), plus `peers`.
  std::string interface = "lo";
  std::vector<std::string> peers;    // extra unicast discovery peers (IPv4 addresses / host names)
  // DDS Security identity of this process's participants (security.hpp); off by default.
  SecurityConfig security;
};

// What to use when several sources give a value: the command line, then the configuration file,
// then the ROS 2 environment (ROS_DOMAIN_ID, CYCLONEDDS_URI, ROS_LOCALHOST_ONLY), then the
// default. `source` names the one that won, for the start line ("ROS_DOMAIN_ID=7").
struct DomainChoice {
  DomainConfig domain;
  std::string domain_source;         // "--domain", "config", "ROS_DOMAIN_ID=7", "default"
  std::string discovery_source;      // "config", "CYCLONEDDS_URI=...", "ROS_LOCALHOST_ONLY=1", "default"
};
struct DomainRequest {
  const std::uint32_t* cli_domain = nullptr;       // --domain, if given
  const std::uint32_t* config_domain = nullptr;    // the file's domain_id, if given
  const std::string* config_interface = nullptr;   // the file's interface, if given
  bool config_localhost_only = false;              // the file's localhost_only: true
  std::vector<std::string> config_peers;
};
// `getenv` is the environment lookup (std::getenv in the executables; a map in tests). Throws
// std::invalid_argument naming the variable and its value when ROS_DOMAIN_ID is not 0..232.
DomainChoice resolve_domain(const DomainRequest& req,
                            const std::function<const char*(const char*)>& getenv);

// A ROS 2 namespace for one robot: "/" followed by tokens [A-Za-z_][A-Za-z0-9_]* separated by "/"
// ("/snake1", "/lab/snake1"), no trailing "/". Empty = the root namespace. Throws
// std::invalid_argument naming `item` otherwise.
void validate_ros_namespace(const std::string& item, const std::string& ns);
// The namespace derived from a robot name: "/" + the name with every character outside
// [A-Za-z0-9_] replaced by '_' (and a leading digit prefixed by '_'); "" for an empty name.
std::string ros_namespace_for(const std::string& robot_name);

// Which clock the ROS header stamps use. ROS time is CLOCK_REALTIME (what ros2 tools, tf and
// rosbag2 expect); kMonotonic keeps the robot's CLOCK_MONOTONIC (a robot without a synchronized
// wall clock).
enum class StampClock { kRealtime, kMonotonic };

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
  SecurityConfig security;           // see DomainConfig
  // The robot's name: commands are acted upon only when their target is this name or "*".
  // 1..63 characters.
  std::string robot_name = "pedalwave";
  // The robot's ROS namespace; every per-robot topic lives under it (rt<ns>/pedalwave/...,
  // rt<ns>/joint_states, rt<ns>/robot_description). Empty: ros_namespace_for(robot_name).
  std::string ros_namespace;
  StampClock stamp_clock = StampClock::kRealtime;
  // The standard ROS 2 topics (joint_states, diagnostics, robot_description URDF, tf).
  bool standard_topics = true;
  double diagnostics_period_s = 1.0;     // /diagnostics when nothing happens [s], > 0
  // How long a queued command may wait for the runtime's outcome before its final ack says
  // REJECTED "no outcome" [s], > 0.
  double command_outcome_timeout_s = 2.0;
  Decimation decimation;
  // false: every command but emergency stop is rejected (with that reason published);
  // emergency stop is always honoured.
  bool enable_commands = true;
  CommandBounds command_bounds;

  DomainConfig domain() const { return {domain_id, interface, peers, security}; }
  std::string effective_namespace() const;   // ros_namespace, or derived from robot_name
  void validate() const;  // throws std::invalid_argument
};

struct SubscriberConfig {
  std::uint32_t domain_id = 0;       // see DomainConfig
  std::string interface = "lo";      // see DomainConfig
  std::vector<std::string> peers;    // see DomainConfig
  SecurityConfig security;           // see DomainConfig
  // Reader history per high-rate topic (keep-last depth): how many samples may arrive between two
  // polls before the oldest are overwritten. 256 covers 250 ms at 1 kHz.
  int state_history_depth = 256;     // [-], 1..10000
  std::string sender = "pedalwave_monitor";  // written into OperatorCommand_::sender (<= 31 chars)
  // The robot to watch and command (its name, the commands' target). Its topics are under
  // ros_namespace (empty: ros_namespace_for(robot)).
  std::string robot = "pedalwave";
  std::string ros_namespace;
  // Also subscribe to the standard ROS 2 topics (joint_states, diagnostics, URDF, tf).
  bool standard_topics = false;

  DomainConfig domain() const { return {domain_id, interface, peers, security}; }
  std::string effective_namespace() const;
  void validate() const;  // throws std::invalid_argument
};

void validate(const DomainConfig& d);  // throws std::invalid_argument

// The Cyclone DDS 0.10 configuration for `d` (passed to dds_create_domain). Exposed for the
// README and for tests. For interface "" it is `cyclonedds_uri` (the CYCLONEDDS_URI value, files
// and/or XML, may be null) followed by a fragment with `peers` if any.
std::string cyclone_config_xml(const DomainConfig& d, const char* cyclonedds_uri = nullptr);

}  // namespace pedalwave::telemetry
