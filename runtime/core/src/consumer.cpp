#include "pedalwave/runtime/consumer.hpp"

#include <spdlog/async.h>
#include <spdlog/async_logger.h>
#include <spdlog/sinks/basic_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

namespace pedalwave::runtime {

struct TelemetryConsumer::Log {
  std::shared_ptr<spdlog::details::thread_pool> pool;
  std::shared_ptr<spdlog::async_logger> logger;
};

std::string format_summary(const RunResult& r, const LoopMetrics& m, const EventLog& events) {
  std::ostringstream os;
  os << "run ended: " << to_string(r.reason) << " (final mode " << to_string(r.final_mode);
  if (r.reason == ExitReason::kFault) {
    os << ", fault " << to_string(r.fault);
    if (r.fault_joint >= 0) os << " on joint " << r.fault_joint + 1;
  }
  if (r.reason == ExitReason::kSignal) os << ", signal " << r.signal;
  os << ")\n";
  const std::vector<RunEvent> all = events.events();
  std::size_t listed = 0;
  for (const RunEvent& e : all) listed += e.listed ? 1 : 0;
  os << "events: " << listed << " faults, warnings, holds and operator commands (of " << events.total()
     << " events";
  if (events.dropped() > 0) os << ", " << events.dropped() << " not kept";
  os << ")\n";
  for (const RunEvent& e : all)
    if (e.listed) os << "  " << format_event(e, events) << "\n";
  if (r.calibrated) {
    os << "deflection zeros (CALIBRATING) [rad]:";
    for (int j = 0; j < r.joints; ++j) {
      os << (j ? ", " : " ") << "joint " << j + 1 << " " << r.deflection_zero[static_cast<std::size_t>(j)];
    }
    os << "\n";
  }
  os << "cycles " << r.cycles << ", overruns " << r.overruns << " (" << r.skipped_periods
     << " periods skipped), ring drops: cycle " << r.cycle_drops << ", event " << r.event_drops << "\n"
     << "rt setup: " << r.rt.describe() << "\n"
     << format_table(m) << format_exit_line(r, events);
  return os.str();
}

TelemetryConsumer::TelemetryConsumer(Runtime& runtime, std::vector<TelemetrySink*> sinks,
                                     ConsumerConfig cfg)
    : rt_(runtime), sinks_(std::move(sinks)), cfg_(std::move(cfg)), log_(std::make_unique<Log>()) {
  if (!(cfg_.poll_period > 0.0 && cfg_.poll_period <= 1.0)) {
    throw std::invalid_argument("consumer config: poll_period = " + std::to_string(cfg_.poll_period) +
                                ", expected a period in (0, 1] s");
  }
  for (std::size_t i = 0; i < sinks_.size(); ++i) {
    if (!sinks_[i]) throw std::invalid_argument("consumer config: sinks[" + std::to_string(i) + "] = null, expected a sink");
  }
  // Own thread pool, not the global registry: several consumers (tests) can coexist. When the
  // queue is full the oldest message is overwritten — the consumer never waits on the logger.
  log_->pool = std::make_shared<spdlog::details::thread_pool>(8192, 1);
  spdlog::sink_ptr sink;
  if (cfg_.log_file.empty()) sink = std::make_shared<spdlog::sinks::stderr_color_sink_mt>();
  else sink = std::make_shared<spdlog::sinks::basic_file_sink_mt>(cfg_.log_file);
  log_->logger = std::make_shared<spdlog::async_logger>(cfg_.logger_name, std::move(sink), log_->pool,
                                                        spdlog::async_overflow_policy::overrun_oldest);
}

TelemetryConsumer::~TelemetryConsumer() {
  try {
    stop();
  } catch (...) {
  }
}

void TelemetryConsumer::start() {
  if (running_.exchange(true)) return;
  const RobotDescription& d = rt_.config().description;
  for (auto* s : sinks_) {
    try {
      s->on_description(d);
    } catch (const std::exception& e) {
      sink_errors_.fetch_add(1, std::memory_order_relaxed);
      log_->logger->error("telemetry sink on_description failed: {}", e.what());
    }
  }
  thread_ = std::thread([this] { loop(); });
}

std::string TelemetryConsumer::stop(const RunResult* result) {
  if (running_.exchange(false) && thread_.joinable()) thread_.join();
  while (drain_once()) {
  }
  std::string text;
  if (result) {
    text = format_summary(*result, rt_.metrics(), event_log_);
    log_->logger->info("summary\n{}", text);
  }
  log_->logger->flush();
  return text;
}

void TelemetryConsumer::loop() {
  const auto idle = std::chrono::duration<double>(cfg_.poll_period);
  while (running_.load(std::memory_order_relaxed)) {
    if (!drain_once()) std::this_thread::sleep_for(idle);
  }
}

bool TelemetryConsumer::drain_once() {
  bool any = false;
  EventSample e;
  while (rt_.event_ring().pop(e)) {
    any = true;
    events_.fetch_add(1, std::memory_order_relaxed);
    event_log_.add(e, rt_.config().reactions);
    if (cfg_.log_events) log_event(e);
    for (auto* s : sinks_) {
      try {
        s->on_event(e);
      } catch (const std::exception& ex) {
        sink_errors_.fetch_add(1, std::memory_order_relaxed);
        log_->logger->error("telemetry sink on_event failed: {}", ex.what());
      }
    }
  }
  // Bounded batch so events are never starved behind a long run of cycle samples.
  CycleSample c;
  for (int i = 0; i < 256 && rt_.cycle_ring().pop(c); ++i) {
    any = true;
    cycles_.fetch_add(1, std::memory_order_relaxed);
    for (auto* s : sinks_) {
      try {
        s->on_cycle(c);
      } catch (const std::exception& ex) {
        sink_errors_.fetch_add(1, std::memory_order_relaxed);
        log_->logger->error("telemetry sink on_cycle failed: {}", ex.what());
      }
    }
  }
  return any;
}

void TelemetryConsumer::log_event(const EventSample& e) {
  auto level = spdlog::level::info;
  if (e.severity == Severity::kWarning || e.severity == Severity::kDegrade) level = spdlog::level::warn;
  if (e.severity == Severity::kStop || e.to == Mode::kFault) level = spdlog::level::err;
  RunEvent r;
  r.sample = e;
  r.kind = classify(e);
  r.reaction = reaction_of(e, rt_.config().reactions);
  // Same line as the summary's (1-based joint), times since the run start.
  log_->logger->log(level, "{}", format_event(r, event_log_));
}

}  // namespace pedalwave::runtime
