// The daemon's end-of-run JSON report (pedalwave_runtime --report-json FILE), read by soak tools.
//
// Schema (every key always present; hand-written JSON, strings escaped, invalid UTF-8 replaced by
// U+FFFD, non-finite numbers written as null):
// {
//  "name": str, "config": str (path), "driver": "sim"|"socketcan"|"serial", "rate_hz": num,
//  "duration_s": num (time the loop covered: cycles / rate_hz [s]),
//  "exit": {"reason": str, "final_mode": str, "fault": str (class or "none"),
//           "joint": int 1-based or null, "signal": int},
//  "events": [{"t": num (s since the run start, the READY transition; CONFIGURED is before it, < 0),
//              "cycle": int, "kind": "fault"|"warning"|"mode"|"operator", "class": str or "none",
//              "severity": str, "joint": int 1-based or null, "value": num (evidence; for an
//              operator command its id; null if not finite), "threshold": num,
//              "text": str, "reaction": "continue"|"hold"|"safe_stop"|"none"}],
//  "events_dropped": int (events the bounded log did not keep),
//  "loop": {"cycles", "overruns", "skipped_periods", "max_skipped", "cycle_drops", "event_drops"},
//  "timing_us": {"wake"|"read"|"observe"|"control"|"write"|"cycle":
//                {"count": int, "min", "p50", "p90", "p99", "p999", "max": num [µs],
//                 "overflows": int, "bins": [[lo_us, hi_us, count], … non-empty bins only; the
//                 overflow bin's hi_us is the exact max]}},
//  "driver_counters": {"frames_tx", "frames_rx", "missing", "late", "duplicate", "out_of_order",
//                      "checksum", "malformed", "bus_errors", "tx_dropped", "rx_dropped"},
//  "settings": {"stale_timeout_s": num, "read_budget": num, "observer": bool, "telemetry": bool}
// }
// Every key is unique (plain JSON readers: Python's json, jq): "driver" is the bus kind,
// "driver_counters" its counters.
#pragma once

#include <ostream>
#include <string>
#include <string_view>

#include "pedalwave/config/daemon.hpp"
#include "pedalwave/interface/io.hpp"
#include "pedalwave/runtime/histogram.hpp"
#include "pedalwave/runtime/run_events.hpp"
#include "pedalwave/runtime/runtime.hpp"

namespace pedalwave::app {

struct RunReportInput {
  const config::DaemonConfig& cfg;
  const runtime::RunResult& run;
  const runtime::LoopMetrics& metrics;
  const runtime::EventLog& events;
  const drivers::DriverCounters& counters;
  bool observer = false;   // the observer ran
  bool telemetry = false;  // DDS telemetry ran
};

// JSON string literal of s, quotes included: ", \ and control characters escaped, invalid UTF-8
// bytes replaced by U+FFFD (EventSample texts are cut at a fixed length, maybe inside a character).
std::string json_string(std::string_view s);
// JSON number: the shortest text that reads back as v; null when not finite.
std::string json_number(double v);

// The whole report, one line, newline-terminated.
void write_run_report(std::ostream& out, const RunReportInput& in);

}  // namespace pedalwave::app
