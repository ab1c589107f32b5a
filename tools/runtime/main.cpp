// pedalwave_runtime: the runtime daemon. Loads a configuration (config/runtime/*.yaml), validates
// everything before starting, runs the fixed-rate loop until the duration, SIGINT/SIGTERM or a
// fault, and ends every exit with the driver's safe command.
#include <CLI/CLI.hpp>

#include <cstdio>
#include <iostream>

#include "daemon.hpp"
#include "pedalwave/config/daemon.hpp"

int main(int argc, char** argv) {
  CLI::App app{"pedalwave runtime daemon: read → observe → control → write at a fixed rate"};
  std::string config_path, plots_dir, report_json;
  double duration = -1.0;
  bool check_only = false, no_telemetry = false;
  app.add_option("-c,--config", config_path, "daemon configuration (YAML)")->required();
  app.add_option("-d,--duration", duration, "override the run time [s] (0 = until a signal)");
  app.add_option("--plots", plots_dir, "write plots of the run into this folder (simulated plant)");
  app.add_option("--report-json", report_json,
                 "write a JSON report of the run (events, exit, loop timing, driver counters) here");
  app.add_flag("--check", check_only, "validate the configuration and exit");
  app.add_flag("--no-telemetry", no_telemetry, "do not start DDS telemetry");
  CLI11_PARSE(app, argc, argv);

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
    return 2;
  }
  if (check_only) {
    std::printf("%s: configuration valid (driver %s, %g Hz, %d joints)\n", config_path.c_str(),
                pedalwave::config::to_string(cfg.driver.kind), cfg.runtime.rt.rate_hz,
                cfg.robot.N - 1);
    return 0;
  }
  try {
    pedalwave::app::DaemonOptions opt;
    opt.plots_dir = plots_dir;
    opt.telemetry = !no_telemetry;
    opt.report_json = report_json;
    const auto r = pedalwave::app::run_daemon(cfg, opt);
    using pedalwave::runtime::ExitReason;
    return (r.run.reason == ExitReason::kFault) ? 3 : 0;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
}
