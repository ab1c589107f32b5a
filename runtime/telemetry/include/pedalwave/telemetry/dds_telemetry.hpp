// DdsTelemetry: the runtime's TelemetrySink on Cyclone DDS. Converts CycleSample / EventSample /
// RobotDescription into the IDL messages of idl/Telemetry.idl and writes them; listens to operator
// commands, validates them and hands the accepted ones to the executable's handler.
//
// Threads: on_description / on_cycle / on_event are called by ONE non-real-time thread (the
// runtime's telemetry consumer draining its wait-free rings); never from the real-time cycle.
// The command handler is called on DdsTelemetry's own command thread.
//
// Topics and QoS (README.md has the table and the reasons); <ns> is the robot's ROS namespace:
//   rt<ns>/pedalwave/joint_state, controller_state, observer_state, loop_timing
//       best-effort, volatile, keep-last(4): a slow or dead reader can never stall the writer;
//       a monitor that falls behind loses samples, the robot does not.
//       Each decimated: published when CycleSample::seq % decimation == 0.
//   rt<ns>/pedalwave/mode_event, fault_event
//       reliable, transient-local, keep-last(100): a late monitor gets the last 100 of each.
//       A write blocks at most 10 ms for history space, then the event is dropped and counted.
//       event_seq counts each topic's messages 1, 2, ... (gap-checkable).
//   rt<ns>/pedalwave/robot_description
//       reliable, transient-local, keep-last(1): a late monitor gets the current description.
//   rt/pedalwave/command (in), rt/pedalwave/command_ack (out), shared by all robots
//       reliable, volatile, keep-last(16): a restarted robot never replays old commands.
//   Standard ROS 2 topics (TelemetryConfig::standard_topics), converted here on the telemetry
//   thread: rt<ns>/joint_states (sensor_msgs/JointState, at the joint_state decimation),
//   rt/tf (tf2_msgs/TFMessage, same rate), rt/diagnostics (diagnostic_msgs/DiagnosticArray,
//   every diagnostics_period_s and at once on a fault or mode change): ROS default QoS
//   (reliable, volatile, keep-last 10); rt<ns>/robot_description (std_msgs/String, the URDF):
//   reliable, transient-local, keep-last(1), as robot_state_publisher does.
//
// Event mapping: an EventSample with fault != kNone is published on fault_event; one with
// from != to on mode_event (both when both hold); one with neither is a mode_event with
// from == to (an informational note).
//
// Commands: a command whose target is neither this robot's name nor "*" is ignored (no ack,
// counted). The others are checked with validate_command(); a refused one gets a final ack
// REJECTED with the reason. An accepted one is passed to the handler (which pushes into the
// runtime's wait-free mailbox and returns false if that is full → REJECTED) and acked QUEUED; its
// final ack comes from the runtime's own outcome event, seen by on_event (the event that carries
// the command id as its value: "start walking…", "set gait rejected…"; the SAFE_STOP transition
// "operator emergency stop" for an e-stop): EXECUTED, or REJECTED with the runtime's text. No
// outcome within command_outcome_timeout_s → REJECTED "no outcome".
// Without a handler every command (even emergency stop) is rejected with "no command handler".
#pragma once

#include <cstdint>
#include <functional>
#include <memory>

#include "pedalwave/interface/telemetry_sink.hpp"
#include "pedalwave/telemetry/config.hpp"

namespace pedalwave::telemetry {

// Called on the command thread with a validated command. Returns true if the command was queued
// for the runtime, false if it could not be (e.g. mailbox full: the command is then rejected).
using CommandHandler = std::function<bool(const runtime::OperatorCommand&)>;

struct TelemetryStats {
  std::uint64_t joint_state = 0;         // messages written [-]
  std::uint64_t controller_state = 0;
  std::uint64_t observer_state = 0;
  std::uint64_t loop_timing = 0;
  std::uint64_t mode_events = 0;
  std::uint64_t fault_events = 0;
  std::uint64_t descriptions = 0;
  std::uint64_t write_errors = 0;        // dds_write failures (message dropped) [-]
  std::uint64_t commands_accepted = 0;    // passed the checks and queued for the runtime
  std::uint64_t commands_rejected = 0;    // final ack REJECTED (any stage)
  std::uint64_t commands_executed = 0;    // final ack EXECUTED
  std::uint64_t commands_ignored = 0;     // addressed to another robot
  std::uint64_t standard_messages = 0;    // joint_states + tf + diagnostics + URDF written
};

class DdsTelemetry final : public runtime::TelemetrySink {
 public:
  // Validates `config` (throws std::invalid_argument), creates the participant, topics, writers
  // and the command reader, and starts the command thread. Throws std::runtime_error if DDS
  // fails (e.g. the interface cannot be used).
  explicit DdsTelemetry(const TelemetryConfig& config, CommandHandler on_command = {});
  ~DdsTelemetry() override;  // stops the command thread, then deletes the participant
  DdsTelemetry(const DdsTelemetry&) = delete;
  DdsTelemetry& operator=(const DdsTelemetry&) = delete;

  void on_description(const runtime::RobotDescription& d) override;
  void on_cycle(const runtime::CycleSample& s) override;
  void on_event(const runtime::EventSample& e) override;

  TelemetryStats stats() const;           // any thread
  const TelemetryConfig& config() const;
  // Number of remote/local readers matched on joint_state (for "is a monitor listening?").
  int joint_state_readers() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace pedalwave::telemetry
