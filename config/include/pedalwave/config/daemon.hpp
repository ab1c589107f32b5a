// The runtime daemon's configuration file (config/runtime/*.yaml) → the parameter structs of every
// component it wires: the loop (runtime::RuntimeConfig), the controller
// (control::GaitControllerParams), the driver (simulated plant, SocketCAN or serial servo bus), the
// observer switch and the telemetry (DDS). Validated before anything starts: bad YAML → file,
// line, key, value and what was expected; a rate the bus cannot sustain → refused with the numbers
// (the drivers' budget checks run here, at load time).
#pragma once

#include <string>

#include "pedalwave/config/yaml_reader.hpp"
#include "pedalwave/control/gait_controller.hpp"
#include "pedalwave/drivers/serial_driver.hpp"
#include "pedalwave/drivers/sim_driver.hpp"
#include "pedalwave/drivers/socketcan_driver.hpp"
#include "pedalwave/model/scene.hpp"
#include "pedalwave/runtime/runtime.hpp"

namespace pedalwave::config {

enum class DriverKind : std::uint8_t { kSim, kSocketCan, kSerial };
const char* to_string(DriverKind k);

struct DriverSelection {
  DriverKind kind = DriverKind::kSim;
  // kSim: the scene file (relative paths are relative to the daemon config) and the plant clock.
  std::string scene_path;
  model::Scene scene;
  drivers::SimDriverOptions sim;
  drivers::SocketCanConfig can;
  drivers::SerialConfig serial;
};

struct TelemetrySection {
  bool enabled = false;
  // Domain and discovery: what the file gives (the daemon resolves them with --domain and the
  // ROS 2 environment, telemetry::resolve_domain). Unset: ROS_DOMAIN_ID / CYCLONEDDS_URI /
  // ROS_LOCALHOST_ONLY, else domain 0 and Cyclone's choice of interface with multicast discovery.
  bool has_domain_id = false;
  std::uint32_t domain_id = 0;        // DDS domain [-] (when has_domain_id)
  bool has_interface = false;
  std::string interface;              // network interface (when has_interface)
  bool localhost_only = false;        // lo with unicast discovery on 127.0.0.1: nothing leaves the host
  std::vector<std::string> peers;     // extra unicast discovery peers
  std::string ros_namespace;          // the robot's ROS namespace; "" = "/" + name (sanitized)
  bool realtime_stamps = true;        // ROS header stamps: CLOCK_REALTIME (false: CLOCK_MONOTONIC)
  bool standard_topics = true;        // joint_states, /diagnostics, robot_description, /tf
  int decimation_state = 10;          // joint/controller/observer state every n cycles [-]
  int decimation_timing = 10;         // loop timing every n cycles [-]
  bool commands = true;               // accept operator commands (e-stop always honoured)
  double amplitude_max = 1.2;         // kSetGait bounds: A_p ≤ [rad]
  double omega_max = 12.0;            // ω ≤ [rad/s]
  double eta_min = -3.2, eta_max = 3.2;  // η range [rad]
  // Record every topic to this MCAP file ("" = no recording; "{time}" = the UTC start time).
  std::string record;
};

// DDS Security for the telemetry and command topics (README "Securing a robot"): the file's
// `security:` section. Absent: the ROS 2 environment decides (ROS_SECURITY_ENABLE=true,
// ROS_SECURITY_KEYSTORE, ROS_SECURITY_ENCLAVE_OVERRIDE, ROS_SECURITY_STRATEGY), else off.
struct SecuritySection {
  bool present = false;               // the file has a security: section
  bool enable = true;                 // enable: false turns security off whatever the environment says
  std::string keystore;               // SROS2 keystore folder (relative: to the config file); "" = ROS_SECURITY_KEYSTORE
  std::string enclave;                // enclave path, e.g. /pedalwave/snake1; "" = ROS_SECURITY_ENCLAVE_OVERRIDE, else /pedalwave/<name>
  std::string strategy;               // "enforce" | "permissive"; "" = ROS_SECURITY_STRATEGY, else enforce
};

struct DaemonConfig {
  std::string source;                 // the file
  std::string name = "pedalwave";
  double duration = 0.0;              // stop (safe stop) after this long [s]; 0 = until a signal
  model::Params robot;                // the robot the controller is tuned for (sim: the scene's)
  runtime::RuntimeConfig runtime;
  control::GaitControllerParams controller;
  DriverSelection driver;
  bool observer = true;
  int observer_missing_cycles = 3;    // consecutive missing replies → module_silent [-]
  double observer_missing_time = 0.0; // a bus: missing replies for this long → module_silent [s] (derived)
  // How the loop's timeouts were chosen (given or derived from the rate and the bus), for the
  // start report: read deadline, stale_timeout, module-silent window.
  std::string timing_note;
  TelemetrySection telemetry;
  SecuritySection security;
  std::string log_file;               // events log; empty = stderr
};

inline constexpr double kMaxDuration = 1e7;  // longest run a file or --duration may ask for [s]

// Why `duration` [s] is no run time at `rate_hz`, as the "expected …" of a message ("" = fine):
// finite, in [0, kMaxDuration], and 0 (until a signal) or at least one period (within 1e-9 of a
// period for float rounding; less is no whole cycle, and 0 cycles would mean "forever").
std::string duration_problem(double duration, double rate_hz);

DaemonConfig load_daemon_config(const std::string& path);
DaemonConfig parse_daemon_config(const std::string& text, const std::string& name,
                                 const std::string& base_dir);

}  // namespace pedalwave::config
