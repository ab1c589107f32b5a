#include "pedalwave/telemetry/mcap_recorder.hpp"

#include <time.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cctype>
#include <numeric>
#include <stdexcept>

#include "pedalwave/telemetry/ros2_definitions.hpp"
#include "pedalwave/interface/clock.hpp"

namespace pedalwave::telemetry {

bool is_mcap_path(std::string_view path) {
  constexpr std::string_view ext = ".mcap";
  if (path.size() <= ext.size()) return false;
  const std::string_view tail = path.substr(path.size() - ext.size());
  return std::equal(tail.begin(), tail.end(), ext.begin(), [](char a, char b) {
    return std::tolower(static_cast<unsigned char>(a)) == b;
  });
}

McapRecorder::McapRecorder(const std::string& path, const std::vector<TopicInfo>& topics,
                           McapRecorderOptions options)
    : path_(path) {
  mcap::WriterOptions wo;
  wo.compression = options.compression;
  wo.chunk_size = options.chunk_size;
  wo.library = "pedalwave_monitor (pedalwave-mcap)";
  writer_ = std::make_unique<mcap::Writer>(path, wo);
  for (const TopicInfo& t : topics) {
    const mcap::QosProfile qos{.reliable = t.reliable, .transient_local = t.transient_local,
                               .depth = t.depth};
    channels_.push_back(writer_->add_ros2_channel(t.topic, t.type, ros2msg_schema(t.type),
                                                  mcap::offered_qos_profiles_yaml(qos, options.qos_style)));
    counts_.push_back(0);
  }
}

McapRecorder::~McapRecorder() = default;  // the Writer's destructor finishes the file

void McapRecorder::on_raw(std::size_t topic, std::span<const std::byte> cdr, const MessageInfo& info) {
  if (!error_.empty() || !writer_->is_open()) return;
  const auto now = static_cast<mcap::Timestamp>(clock_ns(CLOCK_REALTIME));
  mcap::Message m;
  m.channel = channels_.at(topic);
  m.sequence = static_cast<std::uint32_t>(counts_[topic] + 1);
  m.log_time = now;
  m.publish_time = info.source_time_ns > 0 ? static_cast<mcap::Timestamp>(info.source_time_ns) : now;
  m.data = cdr;
  try {
    writer_->write(m);
    ++counts_[topic];
  } catch (const std::exception& e) {
    error_ = e.what();
  }
}

void McapRecorder::flush() {
  if (error_.empty() && writer_->is_open()) {
    try {
      writer_->flush();
    } catch (const std::exception& e) {
      error_ = e.what();
    }
  }
}

void McapRecorder::close() { writer_->close(); }

std::uint64_t McapRecorder::messages() const {
  return std::accumulate(counts_.begin(), counts_.end(), std::uint64_t{0});
}

RecordingThread::RecordingThread(const SubscriberConfig& config, const std::string& path,
                                 McapRecorderOptions options)
    : subscriber_(std::make_unique<TelemetrySubscriber>(config)),
      recorder_(std::make_unique<McapRecorder>(path, subscriber_->topics(), options)) {
  subscriber_->add_raw_listener(*recorder_);
  thread_ = std::thread([this] {
    while (!stop_.load()) subscriber_->poll(std::chrono::milliseconds(20));
  });
}

RecordingThread::~RecordingThread() { stop(); }

std::string RecordingThread::stop() {
  if (stopped_) return error_;
  stopped_ = true;
  stop_ = true;
  if (thread_.joinable()) thread_.join();
  while (subscriber_->poll(std::chrono::milliseconds(0)) > 0) {
  }
  try {
    recorder_->close();
  } catch (const std::exception& e) {
    error_ = e.what();
  }
  if (error_.empty()) error_ = recorder_->error();
  return error_;
}

std::string expand_time(const std::string& pattern, std::int64_t unix_s) {
  const auto t = static_cast<time_t>(unix_s);
  tm utc{};
  gmtime_r(&t, &utc);
  char stamp[32];
  std::strftime(stamp, sizeof stamp, "%Y%m%dT%H%M%SZ", &utc);
  std::string out = pattern;
  for (std::size_t k = out.find("{time}"); k != std::string::npos; k = out.find("{time}", k))
    out.replace(k, 6, stamp);
  return out;
}

}  // namespace pedalwave::telemetry
