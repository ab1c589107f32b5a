// The telemetry messages as received by a subscriber: plain C++ mirrors of the IDL types in
// the ROS 2 messages of ros2/pedalwave/msg (one struct per topic), owning their data. Per-joint vectors have N-1 entries.
// These live on the monitor / recorder side only (non-real-time: they allocate).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace pedalwave::telemetry {

// Reception metadata, filled by the subscriber.
struct MessageInfo {
  std::int64_t recv_ns = 0;           // receiver's CLOCK_MONOTONIC at take() [ns]
  std::int64_t source_time_ns = 0;    // DDS source timestamp, writer's CLOCK_REALTIME [ns]
  std::uint64_t publication = 0;      // DDS instance handle of the writer (changes on restart)
};

struct JointStateMsg {                // rt<ns>/pedalwave/joint_state
  std::uint64_t seq = 0;              // cycle number [-]
  std::int64_t stamp_ns = 0;          // robot's CLOCK_MONOTONIC at cycle wake-up [ns]
  double t = 0.0;                     // controller time [s]
  std::vector<double> beta;           // [rad], (N-1)
  std::vector<double> beta_dot;       // [rad/s], (N-1)
  std::vector<double> alpha;          // [rad], (N-1)
  std::vector<double> deflection;     // [rad], (N-1)
  std::vector<double> tau_sea;        // [N·m], (N-1)
  std::int64_t ros_stamp_ns = 0;      // header.stamp: ROS time (CLOCK_REALTIME unless configured) [ns]
};

struct ControllerStateMsg {           // rt<ns>/pedalwave/controller_state
  std::uint64_t seq = 0;              // [-]
  std::int64_t stamp_ns = 0;          // [ns]
  double t = 0.0;                     // [s]
  std::uint8_t mode = 0;              // runtime::Mode
  std::string mode_name;
  std::vector<double> alpha_d;        // α^d [rad], (N-1)
  std::vector<double> eta;            // Π = [η_j] [rad], (N-1)
  std::vector<double> u;              // commanded torque [N·m], (N-1)
  std::int64_t ros_stamp_ns = 0;      // header.stamp: ROS time (CLOCK_REALTIME unless configured) [ns]
};

struct ObserverStateMsg {             // rt<ns>/pedalwave/observer_state
  std::uint64_t seq = 0;              // [-]
  std::int64_t stamp_ns = 0;          // [ns]
  std::vector<double> residual;       // [N·m], (N-1)
  std::vector<double> tau_ext;        // [N·m], (N-1)
  std::array<double, 6> body{};       // θ_N [rad], p_x [m], p_z [m], then their rates
  std::uint32_t fault_flags = 0;      // bit (1 << FaultClass)
  std::int16_t fault_joint = -1;      // 0-based, −1 none
  double forward_speed = 0.0;         // [m/s]
  std::int64_t ros_stamp_ns = 0;      // header.stamp: ROS time (CLOCK_REALTIME unless configured) [ns]
};

struct LoopTimingMsg {                // rt<ns>/pedalwave/loop_timing
  std::uint64_t seq = 0;              // [-]
  std::int64_t stamp_ns = 0;          // [ns]
  std::int32_t wake_latency_ns = 0;   // [ns]
  std::int32_t t_read_ns = 0;         // [ns]
  std::int32_t t_observe_ns = 0;      // [ns]
  std::int32_t t_control_ns = 0;      // [ns]
  std::int32_t t_write_ns = 0;        // [ns]
  std::uint32_t overruns = 0;         // cumulative [-]
  std::uint64_t ring_drops = 0;       // cumulative [-]
  std::int64_t ros_stamp_ns = 0;      // header.stamp: ROS time (CLOCK_REALTIME unless configured) [ns]
};

struct ModeEventMsg {                 // rt<ns>/pedalwave/mode_event
  std::uint64_t seq = 0;              // [-]
  std::int64_t stamp_ns = 0;          // [ns]
  std::uint8_t from = 0, to = 0;      // runtime::Mode
  std::string from_name, to_name, text;
  double value = 0.0;                 // evidence (a command's id for command outcomes)
  std::uint8_t severity = 0;          // runtime::Severity
  std::uint64_t event_seq = 0;        // 1, 2, ... on this topic, no gaps [-]
  std::int64_t ros_stamp_ns = 0;      // header.stamp: ROS time (CLOCK_REALTIME unless configured) [ns]
};

struct FaultEventMsg {                // rt<ns>/pedalwave/fault_event
  std::uint64_t seq = 0;              // [-]
  std::int64_t stamp_ns = 0;          // [ns]
  std::uint8_t fault_class = 0;       // runtime::FaultClass
  std::string class_name;
  std::uint8_t severity = 0;          // runtime::Severity
  std::string severity_name;
  std::int16_t joint = -1;            // 0-based, −1 none
  double value = 0.0;                 // evidence value
  double threshold = 0.0;             // threshold crossed
  std::uint8_t mode = 0;              // mode after the event (runtime::Mode)
  std::string text;
  std::uint64_t event_seq = 0;        // 1, 2, ... on this topic, no gaps [-]
  std::int64_t ros_stamp_ns = 0;      // header.stamp: ROS time (CLOCK_REALTIME unless configured) [ns]
};

struct DescriptionMsg {               // rt<ns>/pedalwave/robot_description
  int links = 0;                      // N [-]
  double link_length = 0.0;           // 2l [m]
  double link_mass = 0.0;             // m_l [kg]
  double rotor_mass = 0.0;            // m_r [kg]
  double rotor_inertia = 0.0;         // I_r [kg·m²]
  double gear_ratio = 0.0;            // n [-]
  std::vector<double> spring_stiffness;  // K_j [N·m/rad], (N-1)
  double rate_hz = 0.0;               // control rate [Hz]
  double joint_state_rate_hz = 0.0;   // published rates [Hz]
  double controller_state_rate_hz = 0.0;
  double observer_state_rate_hz = 0.0;
  double loop_timing_rate_hz = 0.0;
  std::string name, driver;
  std::string ros_namespace;          // "/snake1"
};

// CommandAck status (pedalwave/msg/CommandAck constants).
enum class AckStatus : std::uint8_t { kRejected = 0, kQueued = 1, kExecuted = 2 };
const char* to_string(AckStatus s) noexcept;   // "rejected", "queued", "executed"

struct CommandAckMsg {                // rt/pedalwave/command_ack
  std::uint64_t id = 0;               // echoed command id
  std::uint8_t kind = 0;              // runtime::OperatorCommandKind
  AckStatus status = AckStatus::kRejected;
  std::int64_t stamp_ns = 0;          // robot's CLOCK_MONOTONIC [ns]
  std::string reason;
  std::string robot;                  // the robot answering
  bool final() const noexcept { return status != AckStatus::kQueued; }
};

struct OperatorCommandMsg {           // rt/pedalwave/command (as seen by a listener/recorder)
  std::uint8_t kind = 0;
  std::uint64_t id = 0;
  double amplitude = 0.0, omega = 0.0, eta = 0.0;  // [rad], [rad/s], [rad]
  std::string sender;
  std::string target;                 // robot name or "*"
};

// ---- The standard ROS 2 topics (SubscriberConfig::standard_topics) ----

struct RosJointStatesMsg {            // rt<ns>/joint_states, sensor_msgs/msg/JointState
  std::int64_t stamp_ns = 0;          // header.stamp [ns]
  std::string frame_id;
  std::vector<std::string> name;      // "joint_1", ... (N-1)
  std::vector<double> position;       // α [rad]
  std::vector<double> velocity;       // α̇ [rad/s]
  std::vector<double> effort;         // SEA torque [N·m]
};

struct DiagnosticStatusMsg {          // diagnostic_msgs/msg/DiagnosticStatus
  std::uint8_t level = 0;             // 0 OK, 1 WARN, 2 ERROR, 3 STALE
  std::string name, message, hardware_id;
  std::vector<std::pair<std::string, std::string>> values;
};
struct DiagnosticArrayMsg {           // rt/diagnostics, diagnostic_msgs/msg/DiagnosticArray
  std::int64_t stamp_ns = 0;
  std::vector<DiagnosticStatusMsg> status;
};

struct TransformMsg {                 // geometry_msgs/msg/TransformStamped
  std::int64_t stamp_ns = 0;
  std::string parent, child;          // header.frame_id, child_frame_id
  std::array<double, 3> translation{};  // [m]
  std::array<double, 4> rotation{0, 0, 0, 1};  // quaternion x, y, z, w
};
struct TfMsg {                        // rt/tf, tf2_msgs/msg/TFMessage
  std::vector<TransformMsg> transforms;
};

}  // namespace pedalwave::telemetry
