// pedalwave_runtime: the runtime daemon. Loads a configuration (config/runtime/*.yaml), validates
// everything before starting, runs the fixed-rate loop until the duration, SIGINT/SIGTERM/SIGHUP/SIGQUIT, an
// operator e-stop or a fault, and ends every exit with the driver's safe command. The exit status
// says how the run ended (kExit* in daemon.hpp; the table is in the --help footer below).
#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>
#include <iostream>

#include "daemon.hpp"
#include "pedalwave/config/daemon.hpp"
#include "pedalwave/toolkit/cli.hpp"

namespace {
constexpr const char* kExitTable =
    "Exit status (how the run ended; the systemd unit never restarts after 2, 4, 5):\n"
    "  0  normal end: the duration reached, or an operator stop (SIGTERM/SIGINT/SIGHUP/SIGQUIT)\n"
    "  1  internal error (an exception outside the loop); under systemd: restarted, into READY\n"
    "  2  bad input: the configuration or the command line was refused\n"
    "  3  the simulated plant (driver: sim) went numerically wrong: its stability limit and a step\n"
    "     that works are printed\n"
    "  4  a fault ended the run (safe stop: torque off)\n"
    "  5  an operator emergency stop ended the run\n"
    "With --state-dir, a run that walked and did not end in order (crash, kill, power loss)\n"
    "leaves <dir>/running behind; the next run then stays READY until an operator start command.";
namespace cli = pedalwave::toolkit::cli;
static_assert(pedalwave::app::kExitBadInput == cli::kExitBadInput && pedalwave::app::kExitFault == cli::kExitFault &&
              pedalwave::app::kExitNumerical == cli::kExitNumerical &&
              pedalwave::app::kExitEmergencyStop == cli::kExitEmergencyStop &&
              pedalwave::app::kExitInternal == cli::kExitInternal);
constexpr const char* kTool = "pedalwave_runtime";
}  // namespace

int main(int argc, char** argv) {
  namespace app = pedalwave::app;
  CLI::App cli{"pedalwave runtime daemon: read → observe → control → write at a fixed rate"};
  cli.footer(kExitTable);
  std::string config_path, plots_dir, report_json, state_dir;
  std::optional<double> duration;
  bool check_only = false, check_config = false, no_telemetry = false;
  cli.add_option("-c,--config", config_path, "daemon configuration (YAML)")->required();
  cli.add_option("-d,--duration", duration, "override the run time [s] (0 = until a signal)");
  cli.add_option("--plots", plots_dir, "write the run's data into this folder (cycles.csv, runtime.json; body.csv, plant.json for the simulated plant) and its figures (tools/figures/runtime.py, matplotlib): runtime_signals.png, observer.png (any driver); snake_shapes, paths, speed .png (simulated plant)");
  cli.add_option("--report-json", report_json,
                 "write a JSON report of the run (events, exit, loop timing, driver counters) here");
  cli.add_option("--state-dir", state_dir,
                 "keep the walking marker here (the unit: /var/lib/pedalwave); a marker left by "
                 "a run that did not end in order keeps this run in READY (no auto-start)");
  cli.add_flag("--check", check_only,
               "validate the configuration and check what can be checked without moving the robot "
               "(device node opens, CAN and DDS interfaces exist, output folders writable), then exit");
  cli.add_flag("--check-config", check_config,
               "validate the configuration file only (no devices, interfaces or folders: a build or "
               "packaging machine without the robot), then exit");
  cli.add_flag("--no-telemetry", no_telemetry, "do not start DDS telemetry");
  std::optional<std::uint32_t> domain;
  cli.add_option("--domain", domain,
                 "DDS domain id (0 … 232), over the file's telemetry.domain_id and ROS_DOMAIN_ID")
      ->check(CLI::Range(0, 232));
  std::string observer_log, replay_log;
  double observer_log_seconds = 60.0;
  cli.add_option("--observer-log", observer_log,
                 "write the observer's inputs of the run's last --observer-log-seconds to this CSV "
                 "(every cycle: each joint's feedback, status and sample time, the command, the live "
                 "residual and verdict) for --replay-observer");
  cli.add_option("--observer-log-seconds", observer_log_seconds,
                 "how much of the run --observer-log keeps [s] (default 60, at most 300)");
  cli.add_option("--replay-observer", replay_log,
                 "run the configuration's observer over an --observer-log file instead of the robot: "
                 "what the live and the replayed observer concluded, and the cycles before the first "
                 "fault; exit 4 when the replay finds a fault")
      ->excludes("--plots");
  if (const auto rc = cli::parse(cli, argc, argv, kTool)) return *rc;

  pedalwave::config::DaemonConfig cfg;
  try {
    cfg = pedalwave::config::load_daemon_config(config_path);
  } catch (const std::exception& e) {
    return cli::bad_input(kTool, e.what());
  }
  // What the file cannot be run with (a sim scene's step longer than the control period): refused
  // in every mode, --check-config too.
  if (const std::string why = app::config_problem(cfg); !why.empty()) return cli::bad_input(kTool, why);
  if (duration) {  // nan, inf, negative, 1e308 and less than one period are refused
    if (const std::string why = pedalwave::config::duration_problem(*duration, cfg.runtime.rt.rate_hz);
        !why.empty()) {
      std::ostringstream os;
      os << "--duration " << *duration << ": expected " << why;
      return cli::bad_input(kTool, os.str());
    }
    cfg.duration = *duration;
    cfg.runtime.max_cycles =
        *duration > 0 ? static_cast<std::uint64_t>(std::llround(*duration * cfg.runtime.rt.rate_hz)) : 0;
  }
  if (!replay_log.empty()) {
    try {
      return app::replay_observer(cfg, replay_log, std::cout);
    } catch (const app::BadInput& e) {
      return cli::bad_input(kTool, e.what());
    }
  }
  app::DaemonOptions opt;
  opt.observer_log = observer_log;
  opt.observer_log_seconds = observer_log_seconds;
  opt.plots_dir = plots_dir;
  opt.telemetry = !no_telemetry;
  opt.domain = domain;
  opt.report_json = report_json;
  opt.state_dir = state_dir;
  if (check_only || check_config) {
    bool all_ok = true;
    for (const app::CheckItem& c : check_only ? app::preflight(cfg, opt) : std::vector<app::CheckItem>{}) {
      all_ok &= c.ok;
      std::printf("%s  %s%s%s\n", c.ok ? "ok  " : "FAIL", c.what.c_str(), c.ok ? "" : ": ", c.why.c_str());
    }
    if (!all_ok) return cli::bad_input(kTool, config_path + ": --check failed (the FAIL lines above)");
    std::printf("%s: configuration valid (driver %s, %g Hz, %d joints, %s)\n", config_path.c_str(),
                pedalwave::config::to_string(cfg.driver.kind), cfg.runtime.rt.rate_hz,
                cfg.robot.N - 1,
                cfg.runtime.auto_start ? "starts walking on its own"
                                       : "waits in READY for an operator start command");
    return app::kExitNormal;
  }
  try {
    const auto r = app::run_daemon(cfg, opt);
    if (r.plant_failed())  // numerically wrong, not a robot fault
      std::fprintf(stderr, "%s: the simulated plant failed at t = %g s: %s; %s\n", kTool, r.plant_t,
                   r.plant_unstable ? "diverging beyond its stability limit"
                                    : std::string(pedalwave::model::to_string(r.plant_status)).c_str(),
                   r.plant_advice.c_str());
    return app::exit_code(r);
  } catch (const app::BadInput& e) {
    return cli::bad_input(kTool, e.what());
  } catch (...) {
    // A value the driver or the runtime refuses (std::invalid_argument, config::ConfigError): 2;
    // anything else: 1.
    return cli::exit_for_current_exception(kTool);
  }
}
