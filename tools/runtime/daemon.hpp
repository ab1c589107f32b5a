// The runtime daemon, as a library so tests run it in-process: wires the configured driver
// (simulated plant, SocketCAN, serial servo bus), the gait controller, the observer and the DDS
// telemetry around runtime::Runtime, runs the loop on its own thread until the duration, a signal
// or a fault, and reports: every fault, warning, hold and operator command of the run (summary and
// exit line, joints 1-based), forward speed, loop timing percentiles; optional plots and a JSON
// report (run_report.hpp). On the simulated plant, a scene's `faults:` list is injected
// (drivers::FaultInjectingDriver around the SimDriver).
#pragma once

#include <functional>
#include <optional>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "pedalwave/config/daemon.hpp"
#include "pedalwave/model/integrators.hpp"
#include "pedalwave/observer/runtime_observer.hpp"
#include "pedalwave/runtime/run_events.hpp"
#include "pedalwave/runtime/runtime.hpp"

namespace pedalwave::app {

struct DaemonOptions {
  std::string plots_dir;     // write plots (and a CSV of the cycle samples) here; empty = none
  bool telemetry = true;     // false overrides the configuration's telemetry.enabled
  bool print = true;         // print the start report and the summary to stdout
  // Use this driver (not owned; already open, e.g. a SocketCanDriver on a socket pair or a
  // SerialDriver on a pty) instead of building the configured one; the configuration still says
  // which bus it is and is validated as usual. nullptr = build the configured driver.
  drivers::Driver* driver = nullptr;
  std::string report_json{};  // write the JSON report of the run here (run_report.hpp); empty = none
  // Runs on its own thread while the loop runs, given the runtime (an operator console; tests post
  // commands with Runtime::post). It must return once rt.mode() is SAFE_STOP; run_daemon joins it
  // after the loop. Runtime::post takes ONE producer: not together with DDS commands.
  std::function<void(runtime::Runtime&)> operator_console{};
  // Keep the walking marker (run_marker.hpp) in this folder (systemd's StateDirectory,
  // /var/lib/pedalwave); empty = off (development runs). A marker left by an earlier run means it
  // did not end in order: this run does not auto-start and stays READY until an operator starts it.
  std::string state_dir{};
  // --domain: the DDS domain, over the file's telemetry.domain_id and ROS_DOMAIN_ID.
  std::optional<std::uint32_t> domain{};
  // --observer-log: write the observer's inputs of the last observer_log_seconds of the run here
  // (CSV, observer/input_log.hpp), for --replay-observer; empty = none.
  std::string observer_log{};
  double observer_log_seconds = 60.0;
};

struct DaemonResult {
  runtime::RunResult run;
  double forward_speed = 0.0;  // average COM speed along +X after the first 2 s [m/s] (sim only)
  double sim_time = 0.0;       // simulated time covered [s] (sim only)
  std::string summary;         // the printed summary (ends with the exit line)
  std::string exit_line;       // "exit: cycle_limit, final mode SAFE_STOP, no stopping fault; …"
  runtime::EventLog event_log;        // every event of the run (bounded), for tests and tools
  std::vector<runtime::RunEvent> events;  // event_log.events()
  bool telemetry_active = false;
  bool previous_run_crashed = false;  // a marker of an earlier run was found (state_dir set)
  std::string start_note;             // what the daemon said about it at start (empty = nothing)
  bool marked_running = false;        // this run wrote the marker (it was seen RUNNING)
  // The simulated plant (driver: sim) went numerically wrong (NaN, singular mass matrix): the
  // fault that ended the run is the plant's, not the robot's. kOk otherwise and on a bus.
  model::StepStatus plant_status = model::StepStatus::kOk;
  double plant_t = 0.0;        // the plant's last good time [s] (plant_status not kOk)
  std::string plant_advice;    // its stability limit and a step that works (simloop::stability_advice)
  // The run ended on implausible measurements while the plant's fixed step is above its predicted
  // stability limit with a growth ≥ ×10 over the run (model::check: CheckLevel::kError): the
  // plant diverged before it overflowed (explicit Euler at h = 1e-3 s, ~2.3× its limit, stops on
  // "implausible joint 1" with every state still finite). Numerically wrong too, not a robot fault.
  bool plant_unstable = false;
  bool plant_failed() const { return plant_status != model::StepStatus::kOk || plant_unstable; }
};

// Exit status of pedalwave_runtime (README, "Exit status of pedalwave_runtime"; DEPLOY.md,
// "Service policy": the unit's RestartPreventExitStatus=2 4 5 never restarts after bad input, a
// fault or an e-stop; a crash — exit 1 or a signal — restarts, into READY because the walking
// marker is left behind).
inline constexpr int kExitNormal = 0;         // duration reached, SIGINT/SIGTERM or a stop request
inline constexpr int kExitInternal = 1;       // internal error (an exception outside the loop)
inline constexpr int kExitBadInput = 2;       // configuration or command line refused
inline constexpr int kExitNumerical = 3;      // the simulated plant (driver: sim) went numerically wrong
inline constexpr int kExitFault = 4;          // a fault ended the run (safe stop)
inline constexpr int kExitEmergencyStop = 5;  // an operator emergency stop ended the run
// How the loop ended → the status (toolkit::cli::exit_for_run_end, shared with pedalwave_soak).
int exit_code(const runtime::RunResult& r) noexcept;
// The same, but kExitNumerical when the simulated plant went numerically wrong (whatever fault
// the runtime then saw in its measurements).
int exit_code(const DaemonResult& r) noexcept;

// A refused option found before anything starts (--report-json, --state-dir): kExitBadInput.
struct BadInput : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Why the folder `dir` cannot take output files ("" = it can): created when missing, then a file
// is written into it and removed (a folder that exists but is read-only, /proc, is refused).
std::string folder_problem(const std::string& dir);
// Why the file `path` cannot be written or appended to ("" = it can): not a directory, its folder
// as folder_problem, and when it exists it is writable. Nothing is written to the file.
std::string file_problem(const std::string& path);

// What the configuration cannot be run with, by the rules of the tools ("" = nothing); the file
// alone decides it (--check-config too). On the simulated plant: a fixed integrator step longer
// than the control period (simloop::step_problem, pedalwave_sim's rule), e.g.
//   "scenes/x.yaml: integrator.h = 0.05: expected a step ≤ the control period 1/rate_hz = 0.001 s
//    (rate_hz in robot.yaml)"
std::string config_problem(const config::DaemonConfig& cfg);

// `pedalwave_runtime --replay-observer LOG`: the configuration's observer (with the FeedbackSpec
// the log names) run over an observer input log (--observer-log); prints what the live and the
// replayed observer concluded, where they differ, and for the first fault the cycles before it
// (each joint's status, sample age, the residual). Returns kExitNormal when the replayed observer
// found no fault, kExitFault when it found one; throws BadInput for a log it cannot read.
int replay_observer(const config::DaemonConfig& cfg, const std::string& log_path, std::ostream& out);

// `pedalwave_runtime --check`: what can be checked without moving the robot. Each item is one
// line "ok    <what>" or "FAIL  <what>: <why>".
struct CheckItem {
  bool ok = true;
  std::string what;  // e.g. "serial device /dev/ttyUSB0 opens"
  std::string why;   // the reason when !ok
};
// The configured device node exists and opens (serial), the CAN interface exists (socketcan), the
// CPU to pin the loop to exists (realtime.cpu ≥ 0), the DDS network interface exists (telemetry
// on and `telemetry` true), and the output folders and files of `opt` are writable (plots,
// report, state). Opens nothing that commands the robot.
std::vector<CheckItem> preflight(const config::DaemonConfig& cfg, const DaemonOptions& opt);

// Throws BadInput (before the run) for an unusable report path, plots folder, state folder or
// log_file, a realtime.cpu this machine does not have, and for a config_problem.
DaemonResult run_daemon(const config::DaemonConfig& cfg, const DaemonOptions& opt);

// The onboard observer as the daemon wires it: the configured robot (one stiffness per joint),
// the loop period and, on the simulated plant, the scene's nominal ground, known motor friction
// and torque limit; with `driver`, its declared feedback resolution and stale limit
// (Driver::feedback_spec(), after its configuration). nullptr when the configuration turns it off
// or the observer layer is not built.
std::unique_ptr<observer::RuntimeObserver> make_observer(const config::DaemonConfig& cfg,
                                                         const drivers::Driver* driver = nullptr);

}  // namespace pedalwave::app
