// McapRecorder: records every topic a TelemetrySubscriber takes into one MCAP file (rosbag2's
// default storage, what Foxglove and `ros2 bag` open) with pedalwave::mcap.
//
// One channel per topic (TelemetrySubscriber::topics(): the pedalwave topics and, with
// standard_topics, joint_states, robot_description, /tf, /diagnostics), created up front: topic =
// the ROS name ("/demo/joint_states"), message encoding `cdr`, metadata `offered_qos_profiles` (the
// robot's writer QoS, in rosbag2's YAML). One `ros2msg` schema per type: the .msg text of the
// interface packages compiled into the library (ros2_definitions.hpp) with its dependencies.
// Messages are the bytes taken from DDS unchanged (RawMessageListener: XCDR1 with the encapsulation
// header, as rmw_cyclonedds hands them to rosbag2); log_time = the receiver's CLOCK_REALTIME at
// take() [ns since the Unix epoch], publish_time = the writer's DDS source timestamp.
// Chunked (McapRecorderOptions::chunk_size) and compressed (zstd by default), with the summary and
// index sections (written by close() or the destructor); what a crash leaves is every completed
// chunk (pedalwave/mcap/writer.hpp).
//
// Runs where poll() runs (the monitor's main thread, the daemon's recorder thread): never on the
// real-time thread. Not thread-safe.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <thread>
#include <string>
#include <string_view>
#include <vector>

#include "pedalwave/mcap/ros2msg.hpp"
#include "pedalwave/mcap/writer.hpp"
#include "pedalwave/telemetry/subscriber.hpp"

namespace pedalwave::telemetry {

// True when `path` ends in ".mcap" (any case): --record picks MCAP over CSV by the extension.
bool is_mcap_path(std::string_view path);

struct McapRecorderOptions {
  mcap::Compression compression = mcap::Compression::zstd;
  std::uint64_t chunk_size = 1024 * 1024;                 // [bytes] uncompressed per chunk
  mcap::QosYamlStyle qos_style = mcap::QosYamlStyle::names;  // integers: for Humble / Iron `ros2 bag`
};

class McapRecorder final : public RawMessageListener {
 public:
  // Creates the file and its schemas and channels. Throws std::runtime_error naming the file when
  // it cannot be created, std::invalid_argument for a topic whose type has no definition.
  McapRecorder(const std::string& path, const std::vector<TopicInfo>& topics,
               McapRecorderOptions options = {});
  ~McapRecorder() override;
  McapRecorder(const McapRecorder&) = delete;
  McapRecorder& operator=(const McapRecorder&) = delete;

  void on_raw(std::size_t topic, std::span<const std::byte> cdr, const MessageInfo&) override;

  // Closes the open chunk (what was recorded survives a crash from now on).
  void flush();
  // Writes the summary and closes the file; idempotent. Throws std::runtime_error on an I/O error.
  void close();

  const std::string& path() const { return path_; }
  std::uint64_t messages(std::size_t topic) const { return counts_.at(topic); }
  std::uint64_t messages() const;
  const mcap::WriterStats& stats() const { return writer_->stats(); }
  // The first write error ("" = none): the recording stopped there, the file keeps what it had.
  const std::string& error() const { return error_; }

 private:
  std::string path_;
  std::unique_ptr<mcap::Writer> writer_;
  std::vector<mcap::ChannelId> channels_;   // by topic index
  std::vector<std::uint64_t> counts_;
  std::string error_;
};

// The daemon's recorder (config key telemetry.record): a TelemetrySubscriber of its own in the
// robot's process (same domain: Cyclone hands the robot's messages to it locally, the serialized
// samples as written, no network) feeding a McapRecorder, polled on a thread of its own — never the
// real-time loop's, never the telemetry publisher's (a slow disk delays only this thread; what it
// cannot take in time, a best-effort topic's reader history overwrites, the events' does not).
class RecordingThread {
 public:
  // Opens the file (throws as McapRecorder) and starts the thread.
  RecordingThread(const SubscriberConfig& config, const std::string& path,
                  McapRecorderOptions options = {});
  ~RecordingThread();  // stop()
  RecordingThread(const RecordingThread&) = delete;
  RecordingThread& operator=(const RecordingThread&) = delete;

  // Stops the thread, takes what has arrived since, writes the summary and closes the file.
  // Returns the first error ("" = none). Idempotent.
  std::string stop();
  const std::string& path() const { return recorder_->path(); }
  std::uint64_t messages() const { return recorder_->messages(); }  // after stop()
  std::size_t topics() const { return subscriber_->topics().size(); }

 private:
  std::unique_ptr<TelemetrySubscriber> subscriber_;
  std::unique_ptr<McapRecorder> recorder_;
  std::atomic<bool> stop_{false};
  std::thread thread_;
  bool stopped_ = false;
  std::string error_;
};

// `pattern` with every "{time}" replaced by the UTC time `unix_s` as 20260101T120000Z (a file per
// daemon start: a restarted service does not overwrite the recording of the run before).
std::string expand_time(const std::string& pattern, std::int64_t unix_s);

}  // namespace pedalwave::telemetry
