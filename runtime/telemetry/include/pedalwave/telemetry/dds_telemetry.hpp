// DdsTelemetry: the runtime's TelemetrySink on Cyclone DDS. Converts CycleSample / EventSample /
// RobotDescription into the IDL messages of idl/Telemetry.idl and writes them; listens to operator
// commands, validates them and hands the accepted ones to the executable's handler.
//
// Threads: on_description / on_cycle / on_event are called by ONE non-real-time thread (the
// runtime's telemetry consumer draining its wait-free rings); never from the real-time cycle.
// The command handler is called on DdsTelemetry's own command thread.
//
// Topics and QoS (README.md has the table and the reasons):
//   rt/pedalwave/joint_state, controller_state, observer_state, loop_timing
//       best-effort, volatile, keep-last(4): a slow or dead reader can never stall the writer;
//       a monitor that falls behind loses samples, the robot does not.
//       Each decimated: published when CycleSample::seq % decimation == 0.
//   rt/pedalwave/mode_event, fault_event
//       reliable, transient-local, keep-last(100): a late monitor gets the last 100 of each.
//       A write blocks at most 10 ms for history space, then the event is dropped and counted.
//   rt/pedalwave/robot_description
//       reliable, transient-local, keep-last(1): a late monitor gets the current description.
//   rt/pedalwave/command (in), rt/pedalwave/command_ack (out)
//       reliable, volatile, keep-last(16): a restarted robot never replays old commands.
//
// Event mapping: an EventSample with fault != kNone is published on fault_event; one with
// from != to on mode_event (both when both hold); one with neither is a mode_event with
// from == to (an informational note).
//
// Commands: every OperatorCommand received is checked with validate_command(); accepted ones are
// passed to the handler (which pushes into the runtime's wait-free mailbox and returns false if
// that is full). Every command gets a CommandAck: accepted, or rejected with the reason.
// Without a handler every command (even emergency stop) is rejected with "no command handler".
#pragma once

#include <cstdint>
#include <functional>
#include <memory>

#include "pedalwave/runtime/telemetry_sink.hpp"
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
  std::uint64_t commands_accepted = 0;
  std::uint64_t commands_rejected = 0;
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
