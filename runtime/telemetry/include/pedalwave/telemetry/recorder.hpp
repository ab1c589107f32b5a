// CsvRecorder: writes every received telemetry message to CSV, ONE FILE PER TOPIC.
// For a path "run.csv" (or "run") the files are run.<topic>.csv, topic in joint_state,
// controller_state, observer_state, loop_timing, mode_event, fault_event, robot_description,
// command, command_ack. All files are created by the constructor (an unwritable path throws
// std::runtime_error there, not mid-run); each gets its header line with its first message.
// Every row starts with recv_ns (receiver CLOCK_MONOTONIC [ns]) and source_time_ns (writer's DDS
// source timestamp, CLOCK_REALTIME [ns]). Per-joint columns are <field>_<j>, j = 1..N-1 (1-based, as the ROS joint
// names joint_1 …; the values of `joint` / `fault_joint` stay 0-based indices, −1 none), with N
// taken from the topic's first message; a later message with another joint count (robot restarted
// with other parameters) is padded/truncated to the header and counted in width_mismatches().
// Written with the project's CSV writer (pedalwave::csv): doubles in shortest round-trip form
// (csv::Numbers::kFixed: fixed from 1e-4 to 1e16, exponent form outside), integers in decimal,
// free-text fields always quoted ("" escapes "), enum names as they are.
#pragma once

#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "pedalwave/csv/csv.hpp"

#include "pedalwave/telemetry/subscriber.hpp"

namespace pedalwave::telemetry {

class CsvRecorder final : public TelemetryListener {
 public:
  explicit CsvRecorder(const std::string& path);
  ~CsvRecorder() override;
  CsvRecorder(const CsvRecorder&) = delete;
  CsvRecorder& operator=(const CsvRecorder&) = delete;

  // The file a topic ("joint_state", ...) is written to.
  std::string file_for(const std::string& topic) const;
  std::uint64_t rows(const std::string& topic) const;   // data rows written so far
  std::uint64_t width_mismatches() const { return width_mismatches_; }
  void flush();

  void on_joint_state(const JointStateMsg&, const MessageInfo&) override;
  void on_controller_state(const ControllerStateMsg&, const MessageInfo&) override;
  void on_observer_state(const ObserverStateMsg&, const MessageInfo&) override;
  void on_loop_timing(const LoopTimingMsg&, const MessageInfo&) override;
  void on_mode_event(const ModeEventMsg&, const MessageInfo&) override;
  void on_fault_event(const FaultEventMsg&, const MessageInfo&) override;
  void on_description(const DescriptionMsg&, const MessageInfo&) override;
  void on_command(const OperatorCommandMsg&, const MessageInfo&) override;
  void on_command_ack(const CommandAckMsg&, const MessageInfo&) override;

 private:
  struct File {
    csv::Writer w;                // created by the constructor; header with the first message
    int joints = 0;               // per-joint column count fixed by the header
  };
  File& file(const char* topic);
  csv::Writer& start(File& f, int joints, std::vector<std::string> (*header)(int));

  std::string stem_;
  std::map<std::string, File> files_;
  std::uint64_t width_mismatches_ = 0;
};

}  // namespace pedalwave::telemetry
