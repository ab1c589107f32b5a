// pedalwave_soak's pieces without processes (tools/soak/soak.cpp) on a fake report.json written in
// the schema of the runtime's --report-json: verdict, histogram tables, summary, /proc/<pid>/status
// parsing and the runtime configuration written from a template.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <string>

#include "soak.hpp"

namespace sk = pedalwave::soak;
using sk::Json;

namespace {

// A healthy 8 s run at 500 Hz, in the runtime's report schema.
const char* kReport = R"({
  "name": "serial-robot", "config": "out/soak/runtime.yaml", "driver": "serial", "rate_hz": 500, "duration_s": 8,
  "exit": {"reason": "cycle_limit", "final_mode": "SAFE_STOP", "fault": "none", "joint": null, "signal": 0},
  "events": [
    {"t": 0.0, "cycle": 0, "kind": "mode", "class": "none", "severity": "info", "joint": null, "value": 0,
     "threshold": 0, "text": "READY -> RUNNING", "reaction": "none"},
    {"t": 8.0, "cycle": 4000, "kind": "mode", "class": "none", "severity": "info", "joint": null, "value": 0,
     "threshold": 0, "text": "RUNNING -> SAFE_STOP", "reaction": "torque off"}
  ],
  "events_dropped": 0,
  "loop": {"cycles": 4000, "overruns": 2, "skipped_periods": 1, "max_skipped": 1, "cycle_drops": 0, "event_drops": 0},
  "timing_us": {
    "wake": {"count": 4000, "min": 3.1, "p50": 12.5, "p90": 20.1, "p99": 45.2, "p999": 230, "max": 812, "overflows": 1,
             "bins": [[0, 10, 1500], [10, 20, 2000], [20, 50, 480], [50, 100, 15], [100, 500, 4], [500, 1000, 0]]},
    "read": {"count": 4000, "min": 50, "p50": 120, "p90": 150, "p99": 210, "p999": 300, "max": 340, "overflows": 0,
             "bins": [[0, 50, 0], [50, 100, 900], [100, 200, 3050], [200, 400, 50]]},
    "observe": {"count": 4000, "min": 4, "p50": 7, "p90": 9, "p99": 11, "p999": 14, "max": 20, "overflows": 0,
                "bins": [[0, 10, 3900], [10, 20, 100]]},
    "control": {"count": 4000, "min": 1, "p50": 2, "p90": 3, "p99": 4, "p999": 5, "max": 6, "overflows": 0,
                "bins": [[0, 10, 4000]]}
  },
  "driver_counters": {"frames_tx": 12005, "frames_rx": 20000, "missing": 0, "late": 0, "duplicate": 0, "out_of_order": 0,
             "checksum": 0, "malformed": 0, "bus_errors": 0, "tx_dropped": 0, "rx_dropped": 0},
  "settings": {"stale_timeout_s": 0.02, "read_budget": 0.5, "observer": true, "telemetry": false}
})";

Json soak_with(const Json& report, int runtime_exit) {
  const sk::Verdict v = sk::judge(report, runtime_exit, false);
  Json reasons = Json::array();
  for (const auto& r : v.reasons) reasons.push(r);
  Json mem_rt = Json::array(), mem_vr = Json::array();
  for (int k = 0; k < 3; ++k) {
    mem_rt.push(Json::object().set("t_s", 4.0 * k).set("rss_kB", 10240 + 1024 * (k > 0)).set("hwm_kB", 11264)
                    .set("size_kB", 300000).set("threads", 6));
    mem_vr.push(Json::object().set("t_s", 4.0 * k).set("rss_kB", 8192).set("hwm_kB", 8192).set("size_kB", 90000)
                    .set("threads", 3));
  }
  return Json::object()
      .set("settings", Json::object().set("duration_s", 8).set("scene", "flat_high_friction.yaml").set("telemetry", "off"))
      .set("machine", Json::object().set("nproc", 2).set("kernel", "Linux 6.1.0"))
      .set("load", Json::object().set("children", 1).set("duty", 1).set("cpu_s", 7.9))
      .set("memory_warmup_s", 2)
      .set("memory", Json::object().set("runtime", mem_rt).set("virtual_robot", mem_vr))
      .set("runtime", Json::object().set("exit_code", runtime_exit))
      .set("virtual_robot", Json::object().set("exit_code", 0).set("report", Json(Json::Array{"  SYNCs 4000", "  replies sent 20000"})))
      .set("report", report)
      .set("verdict", Json::object().set("code", v.code).set("reasons", reasons));
}

}  // namespace

TEST(SoakVerdict, HealthyRunPassesAndEachFailureIsNamed) {
  const Json report = Json::parse(kReport);
  EXPECT_EQ(sk::judge(report, 0, false).code, sk::kExitPass);
  EXPECT_TRUE(sk::judge(report, 0, false).reasons.empty());

  // A fault event, an early stop, a non-zero exit, no report, an interruption: each fails, named.
  Json faulty = Json::parse(kReport);
  Json events = faulty["events"];
  events.push(Json::object().set("t", 3.2).set("kind", "fault").set("class", "encoder_stuck").set("joint", 3));
  faulty.set("events", events);
  auto v = sk::judge(faulty, 0, false);
  EXPECT_EQ(v.code, sk::kExitFault);
  ASSERT_EQ(v.reasons.size(), 1u);
  EXPECT_EQ(v.reasons[0], "1 fault event(s) in the report");

  Json early = Json::parse(kReport);
  early.set("exit", Json::object().set("reason", "fault").set("fault", "stale_sensors"));
  v = sk::judge(early, 4, false);  // pedalwave_runtime's exit status for a fault
  EXPECT_EQ(v.code, sk::kExitFault);
  ASSERT_EQ(v.reasons.size(), 3u);
  EXPECT_EQ(v.reasons[0], "the runtime exited with code 4");
  EXPECT_NE(v.reasons[1].find("'fault'"), std::string::npos);
  EXPECT_NE(v.reasons[2].find("stale_sensors"), std::string::npos);

  v = sk::judge(Json(), 0, false);
  EXPECT_EQ(v.code, sk::kExitFail);
  EXPECT_NE(v.reasons.at(0).find("no report"), std::string::npos);
  EXPECT_EQ(sk::judge(report, 0, true).code, sk::kExitFail);
  EXPECT_EQ(sk::judge(report, -1, false).reasons.at(0), "the runtime was killed by a signal");
}

// Issue 15: the soak's exit status says how the run it drove ended, with the codes of every tool
// and the runtime's own mapping (a fault 4, an e-stop 5 — not 1, which is an internal error).
TEST(SoakVerdict, TheExitStatusSaysHowTheRunEnded) {
  auto ended = [](const std::string& reason, const std::string& fault) {
    Json r = Json::parse(kReport);
    r.set("exit", Json::object().set("reason", reason).set("fault", fault));
    return r;
  };
  EXPECT_EQ(sk::kExitFault, 4);
  EXPECT_EQ(sk::kExitEmergencyStop, 5);
  EXPECT_EQ(sk::judge(ended("fault", "implausible"), 4, false).code, 4);
  EXPECT_EQ(sk::judge(ended("emergency_stop", "none"), 5, false).code, 5);
  // Stopped early by a signal it did not send, or interrupted: no verdict on a whole run.
  EXPECT_EQ(sk::judge(ended("signal", "none"), 0, false).code, 1);
  EXPECT_EQ(sk::judge(ended("signal", "none"), 0, true).code, 1);
  // The runtime refused its configuration (no report): bad input.
  EXPECT_EQ(sk::judge(Json(), 2, false).code, 2);
  EXPECT_EQ(sk::judge(Json(), -1, false).code, 1);  // killed, no report
  EXPECT_EQ(sk::judge(Json::parse(kReport), 0, false).code, 0);
}

TEST(SoakSummary, HistogramRowsSpanTheNonEmptyBinsWithLogBars) {
  const Json report = Json::parse(kReport);
  const std::string h = sk::histogram_table(report["timing_us"]["wake"], 40);
  // Rows from the first to the last non-empty bin; the largest bin has the full bar, a bin of one
  // count still shows one '#'.
  EXPECT_NE(h.find("0 … 10"), std::string::npos) << h;
  EXPECT_NE(h.find("100 … 500"), std::string::npos) << h;
  EXPECT_EQ(h.find("500 … 1000"), std::string::npos) << "empty trailing bin left out\n" << h;
  EXPECT_NE(h.find(std::string(40, '#')), std::string::npos) << h;
  EXPECT_EQ(h.find(std::string(41, '#')), std::string::npos) << h;
  EXPECT_NE(h.find("+ 1 above the last bin (max 812 µs)"), std::string::npos) << h;
  const std::string r = sk::histogram_table(report["timing_us"]["read"], 40);
  EXPECT_EQ(r.find("0 … 50"), std::string::npos) << "empty leading bin left out\n" << r;
  EXPECT_TRUE(sk::histogram_table(Json::object(), 40).empty());

  // Many bins are merged into at most max_rows rows.
  Json many = Json::object();
  Json bins = Json::array();
  for (int k = 0; k < 100; ++k) bins.push(Json(Json::Array{k, k + 1, 1}));
  many.set("bins", bins);
  const std::string m = sk::histogram_table(many, 20, 10);
  EXPECT_NE(m.find("0 … 10 "), std::string::npos) << m;
  EXPECT_NE(m.find("90 … 100"), std::string::npos) << m;
  EXPECT_EQ(std::count(m.begin(), m.end(), '\n'), 12) << "header, rule and 10 rows\n" << m;
}

TEST(SoakSummary, PrintsExitEventsLoopTimingMemoryAndVerdict) {
  const std::string s = sk::summary(soak_with(Json::parse(kReport), 0));
  for (const char* want :
       {"exit: cycle_limit (final mode SAFE_STOP, fault none", "events (2):", "RUNNING -> SAFE_STOP",
        "fault events (false alarms on a healthy run): 0, warnings: 0", "4000 cycles, overruns 2, skipped periods 1",
        "run: serial-robot, driver serial, 500 Hz", "bus: frames_tx 12005", "p99.9", "wake [µs]:", "read [µs]:", "observe [µs]:", "control [µs]:",
        "memory (/proc/<pid>/status):", "runtime", "virtual_robot", "+1", "SYNCs 4000",
        "verdict: PASS"})
    EXPECT_NE(s.find(want), std::string::npos) << "missing '" << want << "' in\n" << s;

  Json bad = soak_with(Json(), 1);
  bad.set("report_error", "report.json: cannot be opened");
  const std::string f = sk::summary(bad);
  EXPECT_NE(f.find("no report from the runtime (report.json: cannot be opened)"), std::string::npos) << f;
  EXPECT_NE(f.find("verdict: FAIL"), std::string::npos) << f;
  EXPECT_NE(f.find("  - the runtime exited with code 1"), std::string::npos) << f;
}

TEST(SoakMemory, ParsesProcStatus) {
  const auto s = sk::parse_proc_status(
      "Name:\tpedalwave_runti\nState:\tS (sleeping)\nVmPeak:\t  400000 kB\nVmSize:\t  300123 kB\n"
      "VmHWM:\t   12000 kB\nVmRSS:\t   11500 kB\nThreads:\t6\n");
  ASSERT_TRUE(s);
  EXPECT_EQ(s->rss_kB, 11500);
  EXPECT_EQ(s->hwm_kB, 12000);
  EXPECT_EQ(s->size_kB, 300123);
  EXPECT_EQ(s->threads, 6);
  EXPECT_FALSE(sk::parse_proc_status("Name:\tkthreadd\nThreads:\t1\n"));
  const auto self = sk::read_proc_status(::getpid(), 1.5);
  ASSERT_TRUE(self);
  EXPECT_GT(self->rss_kB, 0);
  EXPECT_GE(self->threads, 1);
  EXPECT_EQ(self->t_s, 1.5);
  EXPECT_EQ(sk::to_json({*self})[0]["rss_kB"].number(), static_cast<double>(self->rss_kB));
}

TEST(SoakConfig, PointsTheSerialDriverAtTheLinkAndRefusesOtherDrivers) {
  const std::string y = sk::soak_runtime_config(PEDALWAVE_SERIAL_YAML, "/tmp/soak/tty", 250, false);
  EXPECT_NE(y.find("device: /tmp/soak/tty"), std::string::npos) << y;
  EXPECT_NE(y.find("rate_hz: 250"), std::string::npos) << y;
  EXPECT_NE(y.find("enabled: false"), std::string::npos) << y;
  EXPECT_NE(y.find("type: serial"), std::string::npos) << y;
  // The shipped hardware configuration waits for an operator's start; the soak starts it.
  EXPECT_NE(y.find("auto_start: true"), std::string::npos) << y;
  const std::string on = sk::soak_runtime_config(PEDALWAVE_SERIAL_YAML, "/tmp/soak/tty", 0, true);
  EXPECT_NE(on.find("rate_hz: 500"), std::string::npos) << "template's rate kept\n" << on;
  EXPECT_NE(on.find("interface: lo"), std::string::npos) << on;
  try {
    (void)sk::soak_runtime_config(PEDALWAVE_DEMO_YAML, "/tmp/soak/tty", 0, false);
    FAIL() << "the sim driver was accepted";
  } catch (const sk::UsageError& e) {
    EXPECT_NE(std::string(e.what()).find("driver.type is 'sim', expected 'serial'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("demo.yaml"), std::string::npos) << e.what();
  }
  EXPECT_THROW((void)sk::soak_runtime_config("/nonexistent/serial.yaml", "x", 0, false), sk::UsageError);
}
