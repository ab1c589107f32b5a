// pedalwave_telemetry_synth: a stand-in robot publishing SyntheticRobot telemetry over DDS through
// DdsTelemetry (the same sink the runtime daemon uses), so the monitor and recorder can be shown
// before the runtime loop is wired in. It also shows how an executable constructs DdsTelemetry
// and registers the command handler: accepted commands are printed; an emergency stop switches
// the published mode to SAFE_STOP.
//
//   pedalwave_telemetry_synth [--domain 0] [--interface IF] [--robot pedalwave] [--joints 6] [--rate 1000]
//                             [--duration 0] [--fault-every 5] [--no-commands]
//                             [--decimate N] (all state topics)
#include <signal.h>
#include <time.h>

#include <CLI/CLI.hpp>

#include "pedalwave/toolkit/cli.hpp"
#include <spdlog/spdlog.h>

#include <atomic>
#include <cstdio>

#include "pedalwave/telemetry/dds_telemetry.hpp"
#include "pedalwave/telemetry/names.hpp"
#include "pedalwave/telemetry/synthetic.hpp"
#include "pedalwave/interface/clock.hpp"

namespace {

using namespace pedalwave;

volatile sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"pedalwave_telemetry_synth: publishes synthetic pedalwave telemetry over DDS"};
  telemetry::TelemetryConfig cfg;
  int joints = 6;
  double rate = 1000.0;
  double duration_s = 0.0;
  double fault_every_s = 5.0;
  bool no_commands = false;
  int decimate = 1;
  app.add_option("--domain", cfg.domain_id, "DDS domain id")->capture_default_str();
  cfg.interface = "";   // as a ROS 2 node: Cyclone's choice (CYCLONEDDS_URI, multicast)
  app.add_option("--interface", cfg.interface,
                 "network interface (default: Cyclone's choice; lo: localhost only)");
  app.add_option("--robot", cfg.robot_name, "robot name (namespace /NAME, commands' target)")
      ->capture_default_str();
  app.add_option("--peer", cfg.peers, "extra unicast discovery peer (repeatable)");
  app.add_option("--joints", joints, "N-1 joints")->check(CLI::Range(1, runtime::kMaxJoints))
      ->capture_default_str();
  app.add_option("--rate", rate, "cycle rate [Hz]")->check(CLI::Range(1.0, 10000.0))
      ->capture_default_str();
  app.add_option("--duration", duration_s, "seconds (0: until Ctrl-C)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--fault-every", fault_every_s, "a synthetic fault event every S seconds (0: none)")
      ->check(CLI::NonNegativeNumber)
      ->capture_default_str();
  app.add_flag("--no-commands", no_commands, "reject every command but emergency stop");
  app.add_option("--decimate", decimate, "publish every k-th cycle on every state topic")
      ->check(CLI::PositiveNumber);
  if (const auto rc = pedalwave::toolkit::cli::parse(app, argc, argv, "pedalwave_telemetry_synth")) return *rc;
  cfg.enable_commands = !no_commands;
  cfg.decimation = {decimate, decimate, decimate, decimate};

  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  // The handler runs on DdsTelemetry's command thread; a real daemon pushes into the runtime's
  // wait-free mailbox here and returns false when it is full.
  std::atomic<bool> estop{false};
  const auto on_command = [&estop](const runtime::OperatorCommand& c) {
    std::printf("command %s id %llu (A_p %.3f rad, omega %.3f rad/s, eta %.3f rad)\n",
                telemetry::command_kind_name(static_cast<std::uint8_t>(c.kind)).c_str(),
                static_cast<unsigned long long>(c.id), c.amplitude, c.omega, c.eta);
    std::fflush(stdout);
    if (c.kind == runtime::OperatorCommandKind::kEmergencyStop) estop = true;
    return true;
  };

  try {
    telemetry::DdsTelemetry tel(cfg, on_command);
    const telemetry::SyntheticRobot robot(joints, rate);
    tel.on_description(robot.description());
    tel.on_event(robot.mode_event(runtime::Mode::kReady, runtime::Mode::kRunning, 0));
    const auto period_ns = static_cast<std::int64_t>(1e9 / rate);
    const auto fault_cycles = static_cast<std::uint64_t>(fault_every_s * rate);
    const auto total = static_cast<std::uint64_t>(duration_s * rate);
    timespec next = to_timespec(monotonic_ns());
    bool stopped = false;
    std::uint64_t k = 0;
    for (std::uint64_t seq = 0; g_stop == 0 && (total == 0 || seq < total); ++seq) {
      runtime::CycleSample s = robot.sample(seq);
      if (estop && !stopped) {
        stopped = true;
        runtime::EventSample e = robot.mode_event(s.mode, runtime::Mode::kSafeStop, seq);
        std::snprintf(e.text.data(), e.text.size(), "operator emergency stop");
        tel.on_event(e);
      }
      if (stopped) s.mode = runtime::Mode::kSafeStop;
      tel.on_cycle(s);
      if (fault_cycles > 0 && seq > 0 && seq % fault_cycles == 0 && !stopped) {
        tel.on_event(robot.fault_event(k++, seq));
      }
      next.tv_nsec += period_ns;
      while (next.tv_nsec >= 1'000'000'000) {
        next.tv_nsec -= 1'000'000'000;
        ++next.tv_sec;
      }
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
    }
    const auto st = tel.stats();
    std::printf("published %llu joint_state, %llu fault events, %llu write errors\n",
                static_cast<unsigned long long>(st.joint_state),
                static_cast<unsigned long long>(st.fault_events),
                static_cast<unsigned long long>(st.write_errors));
  } catch (...) {
    // A refused option value (std::invalid_argument from the telemetry configuration): 2; else 1.
    return pedalwave::toolkit::cli::exit_for_current_exception("pedalwave_telemetry_synth");
  }
  return 0;
}
