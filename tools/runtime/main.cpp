// pedalwave_runtime: the runtime daemon. Loads a configuration (config/runtime/*.yaml), validates
// everything before starting, runs the fixed-rate loop until the duration, SIGINT/SIGTERM, an
// operator e-stop or a fault, and ends every exit with the driver's safe command. The exit status
// says how the run ended (kExit* in daemon.hpp; the table is in the --help footer below).
#include <CLI/CLI.hpp>

#include <cstdio>
#include <iostream>

#include "daemon.hpp"
#include "pedalwave/config/daemon.hpp"

namespace {
constexpr const char* kExitTable =
    "Exit status (how the run ended; the systemd unit never restarts after 2, 4, 5):\n"
    "  0  normal end: the duration reached, or an operator stop (SIGTERM/SIGINT)\n"
    "  1  internal error (an exception outside the loop); under systemd: restarted, into READY\n"
    "  2  bad input: the configuration or the command line was refused\n"
    "  4  a fault ended the run (safe stop: torque off)\n"
    "  5  an operator emergency stop ended the run\n"
    "  (3 is reserved for the simulation tools: a run that went numerically wrong)\n"
    "With --state-dir, a run that walked and did not end in order (crash, kill, power loss)\n"
    "leaves <dir>/running behind; the next run then stays READY until an operator start command.";
}  // namespace

int main(int argc, char** argv) {
  namespace app = pedalwave::app;
  CLI::App cli{"pedalwave runtime daemon: read → observe → control → write at a fixed rate"};
  cli.footer(kExitTable);
  std::string config_path, plots_dir, report_json, state_dir;
  double duration = -1.0;
  bool check_only = false, no_telemetry = false;
  cli.add_option("-c,--config", config_path, "daemon configuration (YAML)")->required();
  cli.add_option("-d,--duration", duration, "override the run time [s] (0 = until a signal)");
  cli.add_option("--plots", plots_dir, "write plots of the run into this folder: runtime_signals.svg, observer.svg, cycles.csv (any driver); snake_shapes, paths, speed (simulated plant)");
  cli.add_option("--report-json", report_json,
                 "write a JSON report of the run (events, exit, loop timing, driver counters) here");
  cli.add_option("--state-dir", state_dir,
                 "keep the walking marker here (the unit: /var/lib/pedalwave); a marker left by "
                 "a run that did not end in order keeps this run in READY (no auto-start)");
  cli.add_flag("--check", check_only, "validate the configuration and exit");
  cli.add_flag("--no-telemetry", no_telemetry, "do not start DDS telemetry");
  try {
    cli.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int rc = cli.exit(e);
    return rc == 0 ? app::kExitNormal : app::kExitBadInput;
  }

  pedalwave::config::DaemonConfig cfg;
  try {
    cfg = pedalwave::config::load_daemon_config(config_path);
    if (duration >= 0) {
      cfg.duration = duration;
      cfg.runtime.max_cycles =
          duration > 0 ? static_cast<std::uint64_t>(duration * cfg.runtime.rt.rate_hz + 0.5) : 0;
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "configuration error: %s\n", e.what());
    return app::kExitBadInput;
  }
  if (check_only) {
    std::printf("%s: configuration valid (driver %s, %g Hz, %d joints, %s)\n", config_path.c_str(),
                pedalwave::config::to_string(cfg.driver.kind), cfg.runtime.rt.rate_hz,
                cfg.robot.N - 1,
                cfg.runtime.auto_start ? "starts walking on its own"
                                       : "waits in READY for an operator start command");
    return app::kExitNormal;
  }
  try {
    app::DaemonOptions opt;
    opt.plots_dir = plots_dir;
    opt.telemetry = !no_telemetry;
    opt.report_json = report_json;
    opt.state_dir = state_dir;
    const auto r = app::run_daemon(cfg, opt);
    return app::exit_code(r.run);
  } catch (const app::BadInput& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return app::kExitBadInput;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return app::kExitInternal;
  }
}
