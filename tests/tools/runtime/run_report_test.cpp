// The daemon's JSON report writer (tools/runtime/run_report.hpp): strings escaped, invalid UTF-8
// replaced, non-finite numbers null, joints 1-based, the schema's keys in place.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <memory>
#include <sstream>

#include "pedalwave/config/daemon.hpp"
#include "run_report.hpp"

using namespace pedalwave;

TEST(RunReport, StringsAreEscapedAndAlwaysValidUtf8) {
  EXPECT_EQ(app::json_string("plain"), "\"plain\"");
  EXPECT_EQ(app::json_string("a\"b\\c"), "\"a\\\"b\\\\c\"");
  EXPECT_EQ(app::json_string("line\nnext\ttab\r"), "\"line\\nnext\\ttab\\r\"");
  EXPECT_EQ(app::json_string(std::string_view("\x01\x1f", 2)), "\"\\u0001\\u001f\"");
  EXPECT_EQ(app::json_string("τ → N·m"), "\"τ → N·m\"") << "valid UTF-8 passes through";
  // A text cut inside "→" (E2 86 92): the stray bytes become U+FFFD, never invalid JSON.
  EXPECT_EQ(app::json_string(std::string_view("x\xE2\x86", 3)), "\"x\\ufffd\\ufffd\"");
  EXPECT_EQ(app::json_string(std::string_view("\xC0\xAF", 2)), "\"\\ufffd\\ufffd\"") << "overlong";
}

TEST(RunReport, NumbersRoundTripAndNonFiniteIsNull) {
  EXPECT_EQ(app::json_number(0.031), "0.031");
  EXPECT_EQ(app::json_number(3.0), "3");
  EXPECT_EQ(app::json_number(-1e-7), "-1e-07");
  EXPECT_EQ(std::stod(app::json_number(0.1 + 0.2)), 0.1 + 0.2);
  EXPECT_EQ(app::json_number(std::numeric_limits<double>::quiet_NaN()), "null");
  EXPECT_EQ(app::json_number(-std::numeric_limits<double>::infinity()), "null");
}

TEST(RunReport, EventsCarryOneBasedJointsAndTheReaction) {
  config::DaemonConfig cfg;
  cfg.source = "dir/my \"robot\".yaml";
  cfg.runtime.rt.rate_hz = 1000.0;
  runtime::RunResult run;
  run.reason = runtime::ExitReason::kFault;
  run.final_mode = runtime::Mode::kSafeStop;
  run.fault = runtime::FaultClass::kEncoderStuck;
  run.fault_joint = 0;
  run.cycles = 2500;
  auto metrics = std::make_unique<runtime::LoopMetrics>();
  metrics->wake.record(1'500);
  metrics->wake.record(9'000'000);  // overflow bin: hi = the exact max
  runtime::EventLog events;
  runtime::EventSample ready;
  ready.from = runtime::Mode::kConfigured;
  ready.to = runtime::Mode::kReady;
  events.add(ready, cfg.runtime.reactions);
  runtime::EventSample e;
  e.seq = 2499;
  e.t_ns = 2'499'000'000;
  e.from = e.to = runtime::Mode::kRunning;
  e.fault = runtime::FaultClass::kEncoderStuck;
  e.severity = runtime::Severity::kStop;
  e.joint = 0;
  e.value = std::numeric_limits<double>::quiet_NaN();
  e.threshold = 0.5;
  events.add(e, cfg.runtime.reactions);
  drivers::DriverCounters counters;
  counters.late = 3;
  std::ostringstream os;
  app::write_run_report(os, {.cfg = cfg, .run = run, .metrics = *metrics, .events = events,
                             .counters = counters, .observer = true, .telemetry = false});
  const std::string j = os.str();
  EXPECT_NE(j.find("\"config\":\"dir/my \\\"robot\\\".yaml\""), std::string::npos) << j;
  EXPECT_NE(j.find("\"duration_s\":2.5"), std::string::npos) << j;
  EXPECT_NE(j.find("\"exit\":{\"reason\":\"fault\",\"final_mode\":\"SAFE_STOP\",\"fault\":\"encoder_stuck\",\"joint\":1,\"signal\":0}"),
            std::string::npos) << j;
  EXPECT_NE(j.find("{\"t\":2.499,\"cycle\":2499,\"kind\":\"fault\",\"class\":\"encoder_stuck\","
                   "\"severity\":\"stop\",\"joint\":1,\"value\":null,\"threshold\":0.5,\"text\":\"\","
                   "\"reaction\":\"safe_stop\"}"),
            std::string::npos) << j;
  EXPECT_NE(j.find("\"kind\":\"mode\",\"class\":\"none\",\"severity\":\"info\",\"joint\":null"),
            std::string::npos) << j;
  EXPECT_NE(j.find("\"bins\":[[1.5,1.6,1],[5000,9000,1]]"), std::string::npos) << j;
  EXPECT_NE(j.find("\"late\":3"), std::string::npos) << j;
  EXPECT_NE(j.find("\"settings\":{\"stale_timeout_s\":0.02,\"read_budget\":0.5,\"observer\":true,\"telemetry\":false}"),
            std::string::npos) << j;
  EXPECT_EQ(j.back(), '\n');
}
