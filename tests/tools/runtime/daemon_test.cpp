// The runtime daemon in simulated-plant mode, in-process: lockstep loop clock and lockstep plant,
// so runs are deterministic; configuration errors are refused before anything starts.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>

#include <unistd.h>

#include "daemon.hpp"
#include "pedalwave/config/daemon.hpp"

using namespace pedalwave;

namespace {
config::DaemonConfig lockstep(double duration) {
  auto c = config::load_daemon_config(PEDALWAVE_CONFIG_DIR "/runtime/sim_lockstep.yaml");
  c.duration = duration;
  c.runtime.max_cycles = static_cast<std::uint64_t>(duration * c.runtime.rt.rate_hz);
  return c;
}
std::string read_all(const std::filesystem::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}
// An operator console that says "stop walking" once the robot walks.
void stop_walking_once_running(runtime::Runtime& rt) {
  while (rt.mode() != runtime::Mode::kRunning && rt.mode() != runtime::Mode::kSafeStop)
    std::this_thread::yield();
  runtime::OperatorCommand c;
  c.kind = runtime::OperatorCommandKind::kStopWalking;
  c.id = 7;
  rt.post(c);
}
std::string config_error(const std::string& yaml) {
  try {
    config::parse_daemon_config(yaml, "bad.yaml", PEDALWAVE_CONFIG_DIR "/runtime");
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(Daemon, SimulatedPlantWalksAndStopsSafely) {
  const auto r = app::run_daemon(lockstep(6.0), {.plots_dir = "", .telemetry = false, .print = false});
  EXPECT_EQ(r.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(r.run.final_mode, runtime::Mode::kSafeStop);
  EXPECT_EQ(r.run.cycles, 6000u);
  EXPECT_EQ(r.run.overruns, 0u) << "lockstep clock: no overruns";
  EXPECT_NEAR(r.sim_time, 6.0, 0.02);
  // The same gait offline (simloop) walks at ~1.4 cm/s; through the runtime it must too.
  EXPECT_GT(r.forward_speed, 0.010);
  EXPECT_LT(r.forward_speed, 0.020);
}

TEST(Daemon, LockstepRunsAreReproducible) {
  const auto a = app::run_daemon(lockstep(3.0), {.plots_dir = "", .telemetry = false, .print = false});
  const auto b = app::run_daemon(lockstep(3.0), {.plots_dir = "", .telemetry = false, .print = false});
  EXPECT_EQ(a.forward_speed, b.forward_speed);  // bit-identical
}

TEST(Daemon, ConfigurationErrorsNameFileKeyAndExpectation) {
  std::string e = config_error("rate_hz: 1000\ndriver: {type: sim}\n");
  EXPECT_NE(e.find("driver.scene"), std::string::npos) << e;
  e = config_error("rate_hz: fast\ndriver: {type: sim, scene: ../scenes/stair.yaml}\n");
  EXPECT_NE(e.find("rate_hz = \"fast\": expected a number"), std::string::npos) << e;
  e = config_error("driver: {type: carrier-pigeon}\n");
  EXPECT_NE(e.find("one of sim, socketcan, serial"), std::string::npos) << e;
  // A bus that cannot carry 5 joints at 1 kHz is refused with the numbers.
  e = config_error("rate_hz: 1000\nrobot: {N: 6}\ndriver: {type: socketcan, ifname: vcan0, fd: false, bitrate: 1.0e6}\n");
  EXPECT_NE(e.find("bits"), std::string::npos) << e;
  EXPECT_NE(e.find("CAN FD"), std::string::npos) << e;
  // A host-side PD that is unstable at the loop rate is refused with the fix.
  e = config_error("rate_hz: 1000\ndriver: {type: sim, scene: ../scenes/flat_high_friction.yaml}\ncontroller: {pd_placement: host}\n");
  EXPECT_NE(e.find("controller"), std::string::npos) << e;
  EXPECT_NE(e.find("module"), std::string::npos) << e;
  e = config_error("rate_hz: 1000\ndriver: {type: sim, scene: ../scenes/flat_high_friction.yaml}\nrealtime: {priority: 150}\n");
  EXPECT_NE(e.find("realtime.priority = \"150\""), std::string::npos) << e;
  e = config_error("rate_hz: 1000\ndriver: {type: sim, scene: nowhere.yaml}\n");
  EXPECT_NE(e.find("nowhere.yaml"), std::string::npos) << e;
}

// The field run of the issue, in miniature: a latched observer warning and an operator "stop
// walking" (gait frozen, holding) in a run that ends at its cycle limit. The summary, the exit
// line, the event log and the JSON report all tell both, with value, threshold and 1-based joint.
TEST(Daemon, WarningsAndHoldsAreReportedNotNoFault) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("pedalwave_report_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  auto cfg = lockstep(3.0);
  // A snag on joint index 1 ("joint 2" in every text) for 0.4 s that the modules' torque limit
  // cannot overcome: persistent torque saturation, a warning (keep walking, publish it). Longer,
  // it would turn the joint past the plausible range (a stop).
  model::FaultSpec f;
  f.type = model::FaultType::kJointLoad;
  f.joint = 1;
  f.t_start = 0.5;
  f.value = 1.2;  // [N·m], > u_max
  f.duration = 0.4;
  cfg.driver.scene.faults.push_back(f);
  cfg.driver.scene.torque_limit_on = true;
  cfg.driver.scene.torque_limit.u_max = 0.8;
  cfg.log_file = (dir / "events.log").string();
  const std::string report = (dir / "report.json").string();
  const auto r = app::run_daemon(cfg, {.plots_dir = "",
                                       .telemetry = false,
                                       .print = false,
                                       .report_json = report,
                                       .operator_console = stop_walking_once_running});
  EXPECT_EQ(r.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(r.run.fault, runtime::FaultClass::kNone);
  SCOPED_TRACE(r.summary);
  // Summary: every event with value and threshold, joints 1-based, the reaction taken.
  EXPECT_NE(r.summary.find("warning saturation joint 2 (value "), std::string::npos);
  EXPECT_NE(r.summary.find("threshold "), std::string::npos);
  EXPECT_NE(r.summary.find("→ continue"), std::string::npos);
  EXPECT_NE(r.summary.find("operator: stop walking: gait frozen, holding → hold"), std::string::npos);
  // Exit line: no "no fault" when a warning and a hold happened; it names both.
  EXPECT_EQ(r.exit_line.find("no fault"), std::string::npos) << r.exit_line;
  EXPECT_NE(r.exit_line.find("no stopping fault"), std::string::npos) << r.exit_line;
  EXPECT_NE(r.exit_line.find("warning saturation joint 2"), std::string::npos) << r.exit_line;
  EXPECT_NE(r.exit_line.find("operator stop walking at "), std::string::npos) << r.exit_line;
  EXPECT_NE(r.exit_line.find("→ gait frozen, holding"), std::string::npos) << r.exit_line;
  // The event log line shows the 1-based joint too.
  const std::string log = read_all(cfg.log_file);
  EXPECT_NE(log.find("saturation joint 2 (value "), std::string::npos) << log;
  EXPECT_EQ(log.find("saturation joint 1 "), std::string::npos) << log;
  // JSON report: the schema's keys, the events with 1-based joints.
  const std::string json = read_all(report);
  for (const char* key : {"\"name\":", "\"config\":", "\"driver\":\"sim\"", "\"rate_hz\":",
                          "\"duration_s\":3", "\"exit\":{\"reason\":\"cycle_limit\"",
                          "\"final_mode\":\"SAFE_STOP\"", "\"fault\":\"none\"", "\"joint\":null",
                          "\"signal\":0", "\"events\":[", "\"events_dropped\":0", "\"loop\":{",
                          "\"max_skipped\":", "\"timing_us\":{", "\"wake\":{", "\"p999\":",
                          "\"bins\":[[", "\"driver_counters\":{\"frames_tx\":", "\"rx_dropped\":",
                          "\"settings\":{", "\"stale_timeout_s\":", "\"observer\":true",
                          "\"telemetry\":false", "\"kind\":\"warning\",\"class\":\"saturation"
                          "\",\"severity\":\"warning\",\"joint\":2",
                          "\"kind\":\"operator\"", "\"reaction\":\"hold\""})
    EXPECT_NE(json.find(key), std::string::npos) << key << "\n" << json.substr(0, 2000);
#ifdef PEDALWAVE_PYTHON3
  // A real JSON parser and a schema check (tests/tools/runtime/check_run_report.py).
  const std::string cmd = std::string(PEDALWAVE_PYTHON3) + " " CHECK_RUN_REPORT_PY " " + report +
                          " > " + (dir / "check.txt").string() + " 2>&1";
  EXPECT_EQ(std::system(cmd.c_str()), 0) << read_all(dir / "check.txt");
#endif
  fs::remove_all(dir);
}

TEST(Daemon, AnUnwritableReportPathIsRefusedBeforeTheRun) {
  try {
    app::run_daemon(lockstep(1.0), {.plots_dir = "",
                                    .telemetry = false,
                                    .print = false,
                                    .report_json = "/nonexistent-dir/report.json"});
    FAIL() << "expected a refusal";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("--report-json /nonexistent-dir/report.json"), std::string::npos)
        << e.what();
  }
}

// The file may name a CPU of the robot's machine (config/runtime/README.md, realtime.cpu); a run
// on a machine without it is refused before anything starts (BadInput: exit 2).
TEST(Daemon, ACpuThisMachineDoesNotHaveIsRefusedBeforeTheRun) {
  config::DaemonConfig c = lockstep(1.0);
  c.runtime.rt.cpu = 1023;
  try {
    app::run_daemon(c, {.plots_dir = "", .telemetry = false, .print = false});
    FAIL() << "expected a refusal";
  } catch (const app::BadInput& e) {
    EXPECT_NE(std::string(e.what()).find("realtime.cpu = 1023: expected -1 (no pinning) or a CPU of this machine"),
              std::string::npos) << e.what();
  }
}

TEST(Daemon, APlotsFolderThatCannotBeCreatedIsRefusedBeforeTheRun) {
  try {
    app::run_daemon(lockstep(1.0), {.plots_dir = "/proc/pedalwave-no/plots", .telemetry = false,
                                    .print = false});
    FAIL() << "expected a refusal";
  } catch (const app::BadInput& e) {
    EXPECT_NE(std::string(e.what()).find("--plots /proc/pedalwave-no/plots: cannot create the folder"),
              std::string::npos)
        << e.what();
  }
}

// The simulated plant's --plots: the plant's figures and the runtime's own (any driver), the CSV
// with one row per 20 cycles at 1 kHz (50 Hz) and the residual columns.
TEST(Daemon, PlotsWriteThePlantAndTheRuntimeFiguresAndTheCycleCsv) {
  namespace fs = std::filesystem;
  const fs::path dir = fs::temp_directory_path() / ("pw_daemon_plots_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  const auto r = app::run_daemon(lockstep(2.0), {.plots_dir = dir.string(), .telemetry = false,
                                                 .print = false});
  for (const char* f : {"cycles.csv", "runtime.json", "body.csv", "plant.json"})
    EXPECT_TRUE(fs::is_regular_file(dir / f)) << f;
  // The figures (tools/figures/runtime.py) where Debian's python3 has matplotlib (deps.sh
  // installs it); tests/tools/figures checks their content and the skip without matplotlib.
  if (std::system("/usr/bin/python3 -c 'import matplotlib, numpy' 2>/dev/null") == 0) {
    for (const char* f : {"snake_shapes.png", "paths.png", "speed.png", "runtime_signals.png", "observer.png"})
      EXPECT_GT(fs::is_regular_file(dir / f) ? fs::file_size(dir / f) : 0u, 10000u) << f;
  } else {
    std::printf("SKIPPED the figures' part: /usr/bin/python3 has no matplotlib\n");
  }
  std::ifstream csv(dir / "cycles.csv");
  std::string header, line;
  ASSERT_TRUE(std::getline(csv, header));
  EXPECT_NE(header.find(",residual_1,"), std::string::npos) << header;
  std::size_t rows = 0;
  while (std::getline(csv, line)) ++rows;
  EXPECT_EQ(rows, r.run.cycles / 20);
  fs::remove_all(dir);
}

// ---- exit status and the walking marker (DEPLOY.md "Service policy") ----------------------------

namespace {
bool walked(const app::DaemonResult& r) {
  for (const runtime::RunEvent& e : r.events)
    if (e.sample.to == runtime::Mode::kRunning) return true;
  return false;
}
std::filesystem::path fresh_state_dir(const std::string& name) {
  namespace fs = std::filesystem;
  const fs::path d = fs::temp_directory_path() / ("pedalwave_state_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(d);
  return d;
}
// What a run that crashed while walking leaves behind.
void leave_crash_marker(const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  std::ofstream(dir / "running") << "pid 4242, config robot.yaml, walking since 2026-01-01T00:00:00Z\n";
}
}  // namespace

TEST(DaemonExit, TheExitStatusSaysHowTheRunEnded) {
  using runtime::ExitReason;
  runtime::RunResult r;
  const std::pair<ExitReason, int> table[] = {
      {ExitReason::kCycleLimit, 0}, {ExitReason::kStopRequested, 0}, {ExitReason::kSignal, 0},
      {ExitReason::kFault, 4},      {ExitReason::kEmergencyStop, 5}, {ExitReason::kNone, 1}};
  for (const auto& [reason, code] : table) {
    r.reason = reason;
    EXPECT_EQ(app::exit_code(r), code) << runtime::to_string(reason);
  }
  EXPECT_EQ(app::kExitBadInput, 2);
}

// (a) A marker from a run that crashed while walking: an auto-starting configuration does not
// walk; the daemon says why, stays READY (torque off) to its end, and the orderly end clears it.
TEST(DaemonStateMarker, AfterACrashTheRobotStaysReadyAndSaysWhy) {
  const auto dir = fresh_state_dir("crash");
  leave_crash_marker(dir);
  auto cfg = lockstep(3.0);
  ASSERT_TRUE(cfg.runtime.auto_start) << "the test needs a configuration that starts on its own";
  const auto r = app::run_daemon(
      cfg, {.plots_dir = "", .telemetry = false, .print = false, .state_dir = dir.string()});
  EXPECT_TRUE(r.previous_run_crashed);
  EXPECT_NE(r.start_note.find("previous run did not end in order"), std::string::npos) << r.start_note;
  EXPECT_NE(r.start_note.find("pid 4242"), std::string::npos) << r.start_note;
  EXPECT_NE(r.start_note.find("auto_start is OFF"), std::string::npos) << r.start_note;
  EXPECT_NE(r.start_note.find("stays READY"), std::string::npos) << r.start_note;
  EXPECT_FALSE(walked(r)) << r.summary;
  EXPECT_FALSE(r.marked_running);
  EXPECT_EQ(r.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(r.run.cycles, 3000u);
  EXPECT_LT(std::abs(r.forward_speed), 1e-3) << "torque off: the robot must not move";
  EXPECT_FALSE(std::filesystem::exists(dir / "running")) << "an orderly end clears the marker";
  std::filesystem::remove_all(dir);
}

// After a crash, an operator's start command (DDS in the field; Runtime::post here) walks again.
TEST(DaemonStateMarker, AfterACrashAnOperatorStartWalks) {
  const auto dir = fresh_state_dir("start");
  leave_crash_marker(dir);
  auto start_when_ready = [](runtime::Runtime& rt) {
    while (rt.mode() != runtime::Mode::kReady && rt.mode() != runtime::Mode::kSafeStop)
      std::this_thread::yield();
    runtime::OperatorCommand c;
    c.kind = runtime::OperatorCommandKind::kStartWalking;
    c.id = 1;
    rt.post(c);
  };
  const auto r = app::run_daemon(lockstep(2.0), {.plots_dir = "",
                                                 .telemetry = false,
                                                 .print = false,
                                                 .operator_console = start_when_ready,
                                                 .state_dir = dir.string()});
  EXPECT_TRUE(r.previous_run_crashed);
  EXPECT_TRUE(walked(r)) << r.summary;
  EXPECT_TRUE(r.marked_running);
  EXPECT_EQ(r.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_FALSE(std::filesystem::exists(dir / "running"));
  std::filesystem::remove_all(dir);
}

// (b) A run that walks writes the marker (seen from another thread while it walks) and its
// normal end removes it: exit 0.
TEST(DaemonStateMarker, WalkingWritesTheMarkerAndANormalEndRemovesIt) {
  const auto dir = fresh_state_dir("normal");
  bool seen_while_walking = false;
  auto watch_then_stop = [&](runtime::Runtime& rt) {
    while (rt.mode() != runtime::Mode::kRunning && rt.mode() != runtime::Mode::kSafeStop)
      std::this_thread::yield();
    for (int i = 0; i < 5000 && !seen_while_walking; ++i) {
      seen_while_walking = std::filesystem::exists(dir / "running");
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
    rt.request_stop();
  };
  auto cfg = lockstep(0.0);  // until stopped
  cfg.runtime.max_cycles = 0;
  const auto r = app::run_daemon(cfg, {.plots_dir = "",
                                       .telemetry = false,
                                       .print = false,
                                       .operator_console = watch_then_stop,
                                       .state_dir = dir.string()});
  EXPECT_FALSE(r.previous_run_crashed);
  EXPECT_TRUE(r.start_note.empty());
  EXPECT_TRUE(seen_while_walking) << "the marker exists while the robot walks";
  EXPECT_TRUE(r.marked_running);
  EXPECT_EQ(r.run.reason, runtime::ExitReason::kStopRequested);
  EXPECT_EQ(app::exit_code(r.run), 0);
  EXPECT_FALSE(std::filesystem::exists(dir / "running"));
  std::filesystem::remove_all(dir);
}

// (c) A fault ends the run in a safe stop: the marker is removed (a fault is an orderly end: the
// service stays stopped, exit 4, and the next start begins afresh).
TEST(DaemonStateMarker, AFaultEndRemovesTheMarkerAndExits4) {
  const auto dir = fresh_state_dir("fault");
  auto cfg = lockstep(3.0);
  model::FaultSpec f;
  f.type = model::FaultType::kEncoderStuck;
  f.joint = 0;
  f.t_start = 0.5;
  cfg.driver.scene.faults.push_back(f);
  const auto r = app::run_daemon(
      cfg, {.plots_dir = "", .telemetry = false, .print = false, .state_dir = dir.string()});
  EXPECT_TRUE(walked(r));
  EXPECT_TRUE(r.marked_running);
  EXPECT_EQ(r.run.reason, runtime::ExitReason::kFault) << r.exit_line;
  EXPECT_EQ(r.run.fault, runtime::FaultClass::kEncoderStuck) << r.exit_line;
  EXPECT_EQ(app::exit_code(r.run), app::kExitFault);
  EXPECT_EQ(app::exit_code(r.run), 4);
  EXPECT_FALSE(std::filesystem::exists(dir / "running"));
  std::filesystem::remove_all(dir);
}

TEST(DaemonStateMarker, AStateFolderThatCannotBeWrittenIsBadInput) {
  try {
    app::run_daemon(lockstep(1.0), {.plots_dir = "",
                                    .telemetry = false,
                                    .print = false,
                                    .state_dir = "/proc/pedalwave"});
    FAIL() << "expected a refusal";
  } catch (const app::BadInput& e) {
    EXPECT_NE(std::string(e.what()).find("--state-dir /proc/pedalwave"), std::string::npos) << e.what();
  }
}

// CALIBRATING on the path a user runs: the simulated plant with a deflection sensor 0.02 rad off
// from the start (a mounting offset). The scene starts bent in the gait's shape: with torque off
// the robot first settles onto the ground (the window restarts while it moves), then the daemon
// zeros the sensor at rest and walks clean; the summary gives the zeros it found.
TEST(DaemonCalibration, ASensorOffsetFromTheStartIsZeroedAtRestAndTheWalkIsClean) {
  auto with_offset = [](bool calibrate) {
    auto cfg = lockstep(12.0);
    model::FaultSpec f;
    f.type = model::FaultType::kDeflectionBias;
    f.joint = 2;
    f.t_start = 0.0;
    f.value = 0.02;  // [rad]
    cfg.driver.scene.faults.push_back(f);
    if (calibrate) cfg.runtime.calibration.duration = 0.5;  // timeout: the default 5 s
    return app::run_daemon(cfg, {.plots_dir = "", .telemetry = false, .print = false});
  };
  // Uncalibrated, the offset is a spring torque nobody applied: the observer reports joint 3
  // (as motor friction, a warning: a bias present from the first cycle is not isolated as one).
  const auto plain = with_offset(false);
  EXPECT_NE(plain.exit_line.find("joint 3"), std::string::npos) << plain.exit_line;

  const auto cal = with_offset(true);
  SCOPED_TRACE(cal.summary);
  EXPECT_EQ(cal.run.reason, runtime::ExitReason::kCycleLimit) << cal.exit_line;
  EXPECT_EQ(cal.run.fault, runtime::FaultClass::kNone) << cal.exit_line;
  EXPECT_NE(cal.exit_line.find("no events"), std::string::npos) << "no warning either: " << cal.exit_line;
  ASSERT_TRUE(cal.run.calibrated);
  EXPECT_NEAR(cal.run.deflection_zero[2], 0.02, 3e-4) << "the offset, found at rest";
  for (int j : {0, 1, 3, 4}) EXPECT_LT(std::abs(cal.run.deflection_zero[static_cast<std::size_t>(j)]), 3e-4);
  EXPECT_NE(cal.summary.find("deflection zeros (CALIBRATING) [rad]: joint 1 "), std::string::npos);
  // It walks once READY (its speed is averaged from 2 s on, calibration's seconds included).
  EXPECT_GT(cal.forward_speed, 0.005);
  EXPECT_LT(cal.forward_speed, 0.020);
}
