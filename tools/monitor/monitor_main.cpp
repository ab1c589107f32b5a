// pedalwave_monitor: discovers a pedalwave robot on a DDS domain and shows its telemetry live
// (a screen refreshed in place with ANSI codes when stdout is a terminal), optionally recording
// every topic to CSV (one file per topic: FILE.<topic>.csv), optionally sending one operator
// command. Says when the robot goes silent and when it comes back. Ctrl-C exits cleanly.
//
//   pedalwave_monitor [--domain 0] [--interface lo] [--peer ADDR]... [--record run.csv]
//                     [--duration S] [--once] [--silence-timeout 1.0] [--refresh 5]
//                     [--no-view] [--command start|stop|estop|gait --amplitude A --omega W --eta E]
// Exit status: 0 normal end; 1 configuration/DDS error; 2 --once and nothing complete arrived.
#include <signal.h>
#include <unistd.h>

#include <CLI/CLI.hpp>

#include "pedalwave/toolkit/cli.hpp"
#include <spdlog/spdlog.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <memory>
#include <optional>

#include "pedalwave/telemetry/monitor_view.hpp"
#include "pedalwave/telemetry/recorder.hpp"
#include "pedalwave/telemetry/subscriber.hpp"

namespace {

using namespace pedalwave;
using Clock = std::chrono::steady_clock;

volatile sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

std::int64_t now_ns() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch())
      .count();
}

// Sends one command (once the robot is matched) and reports its ack through the monitor notices.
struct PendingCommand {
  runtime::OperatorCommand cmd;
  bool sent = false;
};

std::optional<runtime::OperatorCommandKind> parse_kind(const std::string& s) {
  using K = runtime::OperatorCommandKind;
  if (s == "start") return K::kStartWalking;
  if (s == "stop") return K::kStopWalking;
  if (s == "estop") return K::kEmergencyStop;
  if (s == "gait") return K::kSetGait;
  return std::nullopt;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"pedalwave_monitor: live view and recorder of a pedalwave robot's DDS telemetry"};
  telemetry::SubscriberConfig cfg;
  std::string record;
  double duration_s = 0.0;
  bool once = false;
  double silence_s = 1.0;
  double refresh_hz = 5.0;
  bool no_view = false;
  std::string command;
  double amplitude = 0.0, omega = 0.0, eta = 0.0;
  app.add_option("--domain", cfg.domain_id, "DDS domain id")->capture_default_str();
  app.add_option("--interface", cfg.interface, "network interface (lo: unicast to 127.0.0.1)")
      ->capture_default_str();
  app.add_option("--peer", cfg.peers, "extra unicast discovery peer (repeatable)");
  app.add_option("--record", record,
                 "record every topic to CSV: FILE.csv -> FILE.<topic>.csv, one file per topic");
  app.add_option("--duration", duration_s, "stop after this many seconds (0: until Ctrl-C)")
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--once", once,
               "print one complete snapshot (description + every state topic) and exit");
  app.add_option("--silence-timeout", silence_s, "seconds without a sample before 'silent'")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--refresh", refresh_hz, "screen refreshes per second")
      ->check(CLI::Range(0.2, 50.0))
      ->capture_default_str();
  app.add_flag("--no-view", no_view, "no live screen: print notices (found/silent/back/faults)");
  app.add_option("--command", command, "send one operator command: start|stop|estop|gait")
      ->check(CLI::IsMember({"start", "stop", "estop", "gait"}));
  app.add_option("--amplitude", amplitude, "gait amplitude A_p [rad] (--command gait)");
  app.add_option("--omega", omega, "gait frequency omega [rad/s] (--command gait)");
  app.add_option("--eta", eta, "nominal eta [rad] (--command gait)");
  if (const auto rc = pedalwave::toolkit::cli::parse(app, argc, argv, "pedalwave_monitor")) return *rc;

  spdlog::set_level(spdlog::level::warn);  // the screen is ours
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  const bool tty = ::isatty(STDOUT_FILENO) == 1;
  const bool live_view = !no_view && !once && tty;
  std::unique_ptr<telemetry::TelemetrySubscriber> sub;
  std::unique_ptr<telemetry::CsvRecorder> recorder;
  telemetry::MonitorState state(static_cast<std::int64_t>(silence_s * 1e9));
  try {
    sub = std::make_unique<telemetry::TelemetrySubscriber>(cfg);
    if (!record.empty()) recorder = std::make_unique<telemetry::CsvRecorder>(record);
  } catch (...) {
    // A refused --interface, --domain or --record value (std::invalid_argument): 2; else 1.
    return pedalwave::toolkit::cli::exit_for_current_exception("pedalwave_monitor");
  }
  sub->add_listener(state);
  if (recorder) sub->add_listener(*recorder);

  std::optional<PendingCommand> pending;
  if (!command.empty()) {
    PendingCommand p;
    p.cmd.kind = *parse_kind(command);
    p.cmd.id = static_cast<std::uint64_t>(now_ns());
    p.cmd.amplitude = amplitude;
    p.cmd.omega = omega;
    p.cmd.eta = eta;
    pending = p;
  }

  if (!live_view && !once) {
    std::fprintf(stderr, "pedalwave_monitor: listening on domain %u, interface \"%s\"%s\n",
                 cfg.domain_id, cfg.interface.c_str(),
                 record.empty() ? "" : (", recording to " + record).c_str());
  }
  if (live_view) std::fputs("\x1b[?25l\x1b[2J", stdout);  // hide cursor, clear

  const auto start = Clock::now();
  const auto refresh = std::chrono::duration<double>(1.0 / refresh_hz);
  auto next_draw = start;
  // --once without --duration waits up to 10 s for a complete picture.
  const double limit_s = duration_s > 0.0 ? duration_s : (once ? 10.0 : 0.0);
  int status = 0;
  while (g_stop == 0) {
    sub->poll(std::chrono::milliseconds(50));
    const std::int64_t t = now_ns();
    state.tick(t);
    if (pending && !pending->sent && state.liveness().heard() &&
        sub->wait_for_robot(std::chrono::milliseconds(0))) {
      pending->sent = sub->send_command(pending->cmd);
    }
    if (once && state.complete() && (!pending || pending->sent)) {
      // Give a sent command's ack a moment to arrive before the snapshot.
      for (const auto end = Clock::now() + std::chrono::seconds(1);
           pending && Clock::now() < end;) {
        sub->poll(std::chrono::milliseconds(50));
        state.tick(now_ns());
      }
      break;
    }
    if (live_view && Clock::now() >= next_draw) {
      const std::string screen = state.render(t, true);
      std::fputs("\x1b[H", stdout);
      std::fputs(screen.c_str(), stdout);
      std::fputs("\x1b[J", stdout);
      std::fflush(stdout);
      next_draw += std::chrono::duration_cast<Clock::duration>(refresh);
      if (next_draw < Clock::now()) next_draw = Clock::now();
    }
    if (!live_view && !once) {
      for (const auto& n : state.take_new_notices()) std::printf("%s\n", n.c_str());
      std::fflush(stdout);
    }
    if (limit_s > 0.0 &&
        std::chrono::duration<double>(Clock::now() - start).count() >= limit_s) {
      if (once) status = 2;
      break;
    }
  }

  if (live_view) std::fputs("\x1b[?25h\n", stdout);  // show cursor again
  if (once) {
    std::fputs(state.render(now_ns(), tty).c_str(), stdout);
    if (status == 2) std::fprintf(stderr, "pedalwave_monitor: no complete telemetry within %.1f s\n", limit_s);
  }
  if (recorder) {
    recorder->flush();
    std::fprintf(stderr, "pedalwave_monitor: recorded %llu joint_state rows to %s\n",
                 static_cast<unsigned long long>(recorder->rows("joint_state")),
                 recorder->file_for("joint_state").c_str());
  }
  std::fflush(stdout);
  return status;
}
