// MonitorState: what the monitor knows about the robot, built from the received messages (a
// TelemetryListener), and its rendering as a text screen (optionally ANSI, for a live view that
// refreshes in place). Tracks silence (SilenceTracker on all high-rate topics), restarts (the
// joint_state publisher changed or seq went backwards), per-topic receive rates and a log of
// notices (silent / back / restart / fault / mode / command ack).
// Times are the monitor's CLOCK_MONOTONIC [ns], passed in. Joints are printed 1-based ("joint 1" =
// the first joint = CAN node / DYNAMIXEL id 1); the messages' joint fields are 0-based.
#pragma once

#include <cstdint>
#include <deque>
#include <optional>
#include <string>
#include <vector>

#include "pedalwave/telemetry/liveness.hpp"
#include "pedalwave/telemetry/subscriber.hpp"

namespace pedalwave::telemetry {

class MonitorState final : public TelemetryListener {
 public:
  // silence_timeout_ns > 0: how long without any high-rate sample before "silent".
  explicit MonitorState(std::int64_t silence_timeout_ns, std::size_t max_notices = 10);

  void on_joint_state(const JointStateMsg&, const MessageInfo&) override;
  void on_controller_state(const ControllerStateMsg&, const MessageInfo&) override;
  void on_observer_state(const ObserverStateMsg&, const MessageInfo&) override;
  void on_loop_timing(const LoopTimingMsg&, const MessageInfo&) override;
  void on_mode_event(const ModeEventMsg&, const MessageInfo&) override;
  void on_fault_event(const FaultEventMsg&, const MessageInfo&) override;
  void on_description(const DescriptionMsg&, const MessageInfo&) override;
  void on_command_ack(const CommandAckMsg&, const MessageInfo&) override;

  // Advances time: silence detection and rate estimates (1 s windows). Call every ~100 ms.
  void tick(std::int64_t now_ns);

  // The screen. ansi: colours and clear-to-end-of-line codes (the caller homes the cursor).
  std::string render(std::int64_t now_ns, bool ansi) const;

  // Notices added since the last call (also kept in the on-screen log).
  std::vector<std::string> take_new_notices();

  const SilenceTracker& liveness() const { return silence_; }
  bool has_description() const { return description_.has_value(); }
  // At least one sample of each high-rate topic and the description: enough for --once.
  bool complete() const;
  std::uint32_t restarts() const { return restarts_; }
  // Events known lost: the sum of the forward jumps of event_seq on mode_event and fault_event.
  std::uint64_t event_gaps() const { return event_gaps_; }
  const std::optional<CommandAckMsg>& last_ack() const { return last_ack_; }
  std::uint64_t received(int topic) const { return topics_.at(static_cast<std::size_t>(topic)).count; }
  double rate_hz(int topic) const { return topics_.at(static_cast<std::size_t>(topic)).rate_hz; }
  enum Topic : int { kJoint = 0, kController, kObserver, kTiming, kTopicCount };

 private:
  struct TopicStats {
    std::uint64_t count = 0;
    std::uint64_t window_count = 0;
    std::int64_t window_start_ns = -1;   // -1: no sample yet [ns]
    double rate_hz = 0.0;
  };
  void sample_arrived(Topic t, const MessageInfo& info);
  void event_arrived(std::uint64_t& last, std::uint64_t event_seq, const MessageInfo& i,
                     const char* topic);
  void notice(std::int64_t now_ns, std::string text);

  SilenceTracker silence_;
  std::size_t max_notices_;
  std::vector<TopicStats> topics_;
  std::optional<DescriptionMsg> description_;
  std::optional<JointStateMsg> joint_;
  std::optional<ControllerStateMsg> controller_;
  std::optional<ObserverStateMsg> observer_;
  std::optional<LoopTimingMsg> timing_;
  std::optional<ModeEventMsg> last_mode_event_;
  std::deque<FaultEventMsg> faults_;          // most recent last, at most 5
  std::optional<CommandAckMsg> last_ack_;
  std::string last_mode_name_;       // newest mode heard (controller_state or a mode event)
  std::uint64_t last_mode_seq_ = 0, last_fault_seq_ = 0;   // event_seq of the last event
  std::uint64_t event_gaps_ = 0;
  std::deque<std::string> notices_;
  std::vector<std::string> new_notices_;
  std::uint64_t publication_ = 0;
  std::uint32_t restarts_ = 0;
  std::int64_t last_now_ns_ = 0;
  std::int64_t start_ns_ = -1;    // first time seen, for "+12.3 s" notice stamps [ns]
};

}  // namespace pedalwave::telemetry
