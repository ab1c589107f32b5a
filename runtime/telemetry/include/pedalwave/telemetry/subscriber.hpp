// TelemetrySubscriber: the monitor side. Subscribes to every pedalwave topic on a domain, decodes
// the messages (messages.hpp) and hands them to listeners on the caller's thread, inside poll().
// The robot's topics are those under its namespace (SubscriberConfig::robot / ros_namespace).
// Also publishes operator commands (rt/pedalwave/command, addressed to the robot) and receives
// the acks of every robot (CommandAckMsg::robot says which).
// Reader QoS mirror the writer's (dds_telemetry.hpp): best-effort keep-last(state_history_depth)
// on the high-rate topics, reliable transient-local on events and description (so a late
// subscriber gets the description and the last 100 events), reliable volatile on command/ack.
// Not thread-safe: one thread calls poll(), send_command() and the rest.
#pragma once

#include <chrono>
#include <cstdint>
#include <cstddef>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "pedalwave/interface/telemetry_sink.hpp"
#include "pedalwave/telemetry/config.hpp"
#include "pedalwave/telemetry/messages.hpp"

namespace pedalwave::telemetry {

// Receives decoded messages. Every method has an empty default.
class TelemetryListener {
 public:
  virtual ~TelemetryListener() = default;
  virtual void on_joint_state(const JointStateMsg&, const MessageInfo&) {}
  virtual void on_controller_state(const ControllerStateMsg&, const MessageInfo&) {}
  virtual void on_observer_state(const ObserverStateMsg&, const MessageInfo&) {}
  virtual void on_loop_timing(const LoopTimingMsg&, const MessageInfo&) {}
  virtual void on_mode_event(const ModeEventMsg&, const MessageInfo&) {}
  virtual void on_fault_event(const FaultEventMsg&, const MessageInfo&) {}
  virtual void on_description(const DescriptionMsg&, const MessageInfo&) {}
  virtual void on_command(const OperatorCommandMsg&, const MessageInfo&) {}
  virtual void on_command_ack(const CommandAckMsg&, const MessageInfo&) {}
  // The standard ROS 2 topics (SubscriberConfig::standard_topics).
  virtual void on_urdf(const std::string& /*urdf*/, const MessageInfo&) {}
  virtual void on_joint_states(const RosJointStatesMsg&, const MessageInfo&) {}
  virtual void on_diagnostics(const DiagnosticArrayMsg&, const MessageInfo&) {}
  virtual void on_tf(const TfMsg&, const MessageInfo&) {}
};

// One subscribed topic as a recorder or a relay sees it: the ROS 2 name, type and the QoS the
// robot's writer offers (README.md, "QoS, and why").
struct TopicInfo {
  std::string topic;            // ROS name: "/demo/joint_states", "/diagnostics"
  std::string type;             // ROS 2 type: "sensor_msgs/msg/JointState"
  bool reliable = true;         // the writer's reliability (else best-effort)
  bool transient_local = false; // the writer's durability (else volatile)
  unsigned depth = 10;          // the writer's keep-last depth
};

// Receives every valid message as the serialized bytes taken from DDS, unchanged: CDR with its
// 4-byte encapsulation header (XCDR1, as rmw_cyclonedds and rosbag2 have them). `topic` indexes
// TelemetrySubscriber::topics(). Called inside poll(), before the decoded listeners.
class RawMessageListener {
 public:
  virtual ~RawMessageListener() = default;
  virtual void on_raw(std::size_t topic, std::span<const std::byte> cdr, const MessageInfo&) = 0;
};

class TelemetrySubscriber {
 public:
  // Validates config (throws std::invalid_argument); creates participant, readers and the command
  // writer (throws std::runtime_error if DDS fails).
  explicit TelemetrySubscriber(const SubscriberConfig& config);
  ~TelemetrySubscriber();
  TelemetrySubscriber(const TelemetrySubscriber&) = delete;
  TelemetrySubscriber& operator=(const TelemetrySubscriber&) = delete;

  // Listeners are called in the order added; they must outlive the subscriber (or be removed).
  void add_listener(TelemetryListener& l);
  void remove_listener(TelemetryListener& l);
  void add_raw_listener(RawMessageListener& l);
  void remove_raw_listener(RawMessageListener& l);
  // Every topic subscribed, in a fixed order (RawMessageListener's index).
  const std::vector<TopicInfo>& topics() const;

  // Waits up to `timeout` for data on any topic, then takes everything available from every
  // reader and dispatches it. Returns the number of messages dispatched (0 on timeout).
  std::size_t poll(std::chrono::nanoseconds timeout);

  // Publishes an operator command addressed to `target` (a robot name or "*"; default: the
  // configured robot); `id` is the caller's. Returns false if the write failed.
  bool send_command(const runtime::OperatorCommand& c);
  bool send_command(const runtime::OperatorCommand& c, const std::string& target);
  // Why send_command() of this kind always returns false ("" when it may be sent): DDS Security
  // permissions that do not allow this identity to publish the command (or e-stop) topic.
  std::string command_refusal(runtime::OperatorCommandKind kind) const;
  // Waits until a robot's command reader is matched (commands are volatile: sent before the
  // match, they are lost). Returns false on timeout.
  bool wait_for_robot(std::chrono::nanoseconds timeout);
  // Number of robot-side writers currently matched on joint_state.
  int joint_state_writers() const;

  const SubscriberConfig& config() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace pedalwave::telemetry
