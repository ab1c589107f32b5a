// The non-real-time side of the hand-off: one thread that drains the runtime's cycle and event
// rings, calls every TelemetrySink, and logs events through an spdlog asynchronous logger. It
// never blocks the producer (the rings are wait-free; a slow sink only makes the ring drop and
// count). Sinks are called from this thread only, in ring order. Every event it drains also goes
// into a bounded EventLog (run_events.hpp) for the end-of-run summary and report.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "pedalwave/runtime/histogram.hpp"
#include "pedalwave/runtime/run_events.hpp"
#include "pedalwave/runtime/runtime.hpp"
#include "pedalwave/interface/telemetry_sink.hpp"

namespace pedalwave::runtime {

struct ConsumerConfig {
  double poll_period = 0.002;                 // sleep when both rings are empty [s], (0, 1]
  std::string log_file;                       // events log file; empty = stderr
  std::string logger_name = "pedalwave.runtime";  // spdlog logger name (not registered globally)
  bool log_events = true;                     // log every EventSample (info/warn/error by severity)
};

// "run ended: cycle_limit (final mode SAFE_STOP)", then every listed event of the run (faults,
// warnings, holds, operator commands, e-stop; one format_event() line each, with the count of
// events not kept), "cycles 12000, overruns 3 (5 periods skipped), ring drops: cycle 0, event 0",
// the RT setup, format_table(), and last format_exit_line().
std::string format_summary(const RunResult& r, const LoopMetrics& m, const EventLog& events);

class TelemetryConsumer {
 public:
  // sinks are not owned and must outlive the consumer. Throws std::invalid_argument on a bad
  // config, spdlog's exception if the log file cannot be opened.
  TelemetryConsumer(Runtime& runtime, std::vector<TelemetrySink*> sinks, ConsumerConfig cfg = {});
  ~TelemetryConsumer();  // stop()s if still running
  TelemetryConsumer(const TelemetryConsumer&) = delete;
  TelemetryConsumer& operator=(const TelemetryConsumer&) = delete;

  // Calls on_description() on every sink, then starts the draining thread.
  void start();
  // Drains whatever is left, joins the thread and flushes the log. With a result, also logs the
  // summary (cycles, overruns, ring drops, percentile table) and returns its text. Idempotent.
  std::string stop(const RunResult* result = nullptr);

  std::uint64_t cycles_consumed() const noexcept { return cycles_.load(std::memory_order_relaxed); }
  std::uint64_t events_consumed() const noexcept { return events_.load(std::memory_order_relaxed); }
  std::uint64_t sink_errors() const noexcept { return sink_errors_.load(std::memory_order_relaxed); }
  // Every event drained so far, bounded (read after stop(), never while the thread runs).
  const EventLog& events() const noexcept { return event_log_; }

 private:
  void loop();
  bool drain_once();  // true if anything was consumed
  void log_event(const EventSample& e);

  struct Log;  // spdlog lives behind this (PRIVATE dependency)
  Runtime& rt_;
  std::vector<TelemetrySink*> sinks_;
  ConsumerConfig cfg_;
  std::unique_ptr<Log> log_;
  EventLog event_log_;
  std::thread thread_;
  std::atomic<bool> running_{false};
  std::atomic<std::uint64_t> cycles_{0};
  std::atomic<std::uint64_t> events_{0};
  std::atomic<std::uint64_t> sink_errors_{0};
};

}  // namespace pedalwave::runtime
