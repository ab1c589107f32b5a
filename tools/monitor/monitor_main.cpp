// pedalwave_monitor: discovers a pedalwave robot on a DDS domain and shows its telemetry live
// (a screen refreshed in place with ANSI codes when stdout is a terminal), optionally recording
// every topic to CSV (one file per topic: FILE.<topic>.csv) or to one MCAP file (FILE.mcap: every
// topic incl. the standard ones, ros2msg schemas, the CDR bytes as received; Foxglove and `ros2
// bag` open it), optionally serving the Foxglove WebSocket protocol for a live view in Foxglove
// (--foxglove PORT), optionally sending one operator command. Says when the robot goes silent and
// when it comes back. Ctrl-C exits cleanly.
//
//   pedalwave_monitor [--robot NAME] [--namespace /NS] [--domain 0] [--interface IF |
//                     --localhost-only] [--peer ADDR]... [--record run.csv|run.mcap]
//                     [--foxglove PORT [--foxglove-address 127.0.0.1]] [--duration S]
//                     [--once] [--silence-timeout 1.0] [--refresh 5] [--no-view]
//                     [--command start|stop|estop|gait --amplitude A --omega W --eta E
//                      [--ack-timeout 5]]
// Domain and discovery as a ROS 2 node: --domain, else ROS_DOMAIN_ID, else 0; --interface or
// --localhost-only, else CYCLONEDDS_URI / ROS_LOCALHOST_ONLY=1, else Cyclone's own choice.
// --command sends one command to the robot and exits on its final ack.
// Exit status: 0 normal end (--command: the robot executed it); 1 configuration/DDS error, or
// the MCAP recording failed (disk full, …: the file keeps its completed chunks);
// 2 bad input, or --once and nothing complete arrived; 3 --command rejected (by the robot's
// checks, its mailbox or its real-time loop); 4 --command without a final ack in time (no
// robot, or no answer).
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

#include "pedalwave/interface/clock.hpp"
#include "pedalwave/telemetry/foxglove_server.hpp"
#include "pedalwave/telemetry/mcap_recorder.hpp"
#include "pedalwave/telemetry/monitor_view.hpp"
#include "pedalwave/telemetry/recorder.hpp"
#include "pedalwave/telemetry/subscriber.hpp"

namespace {

using namespace pedalwave;
using Clock = std::chrono::steady_clock;

volatile sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

// CLOCK_MONOTONIC through the project's one clock helper (steady_clock is the same clock).
using pedalwave::monotonic_ns;

// Sends one command (once the robot is matched) and reports its ack through the monitor notices.
struct PendingCommand {
  runtime::OperatorCommand cmd;
  bool sent = false;
};

// The final ack of one command from one robot (acks of every robot share one topic).
struct AckWatcher final : telemetry::TelemetryListener {
  std::uint64_t id = 0;
  std::string robot;
  std::optional<telemetry::CommandAckMsg> final_ack;
  void on_command_ack(const telemetry::CommandAckMsg& m, const telemetry::MessageInfo&) override {
    if (m.id == id && m.robot == robot && m.final() && !final_ack) final_ack = m;
  }
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
  std::optional<std::uint32_t> domain;
  std::optional<std::string> interface;
  bool localhost_only = false;
  double ack_timeout_s = 5.0;
  std::string record;
  double duration_s = 0.0;
  bool once = false;
  double silence_s = 1.0;
  double refresh_hz = 5.0;
  bool no_view = false;
  std::string command;
  double amplitude = 0.0, omega = 0.0, eta = 0.0;
  app.add_option("--robot", cfg.robot, "the robot's name (its commands' target)")
      ->capture_default_str();
  app.add_option("--namespace", cfg.ros_namespace,
                 "the robot's ROS namespace (default: / + its name, e.g. /demo)");
  app.add_option("--domain", domain, "DDS domain id (default: ROS_DOMAIN_ID, else 0)")
      ->check(CLI::Range(0, 232));
  app.add_option("--interface", interface,
                 "network interface (default: CYCLONEDDS_URI, else Cyclone's choice)");
  app.add_flag("--localhost-only", localhost_only,
               "discovery by unicast on lo only (as ROS_LOCALHOST_ONLY=1)");
  app.add_option("--ack-timeout", ack_timeout_s,
                 "--command: seconds to wait for the robot and its final ack")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--peer", cfg.peers, "extra unicast discovery peer (repeatable)");
  // Recording and the Foxglove live view (MCAP: by the file's extension).
  std::string mcap_compression = "zstd";
  std::optional<int> foxglove_port;
  std::string foxglove_address = "127.0.0.1";
  app.add_option("--record", record,
                 "record every topic: FILE.mcap -> one MCAP file (every topic incl. the standard "
                 "ones, CDR as received); FILE.csv -> FILE.<topic>.csv, one file per topic");
  app.add_option("--mcap-compression", mcap_compression, "MCAP chunk compression")
      ->check(CLI::IsMember({"zstd", "lz4", "none"}))
      ->capture_default_str();
  app.add_option("--foxglove", foxglove_port,
                 "serve the Foxglove WebSocket protocol on this TCP port (Foxglove: open "
                 "connection ws://ADDRESS:PORT; 0: any free port)")
      ->check(CLI::Range(0, 65535));
  app.add_option("--foxglove-address", foxglove_address,
                 "IPv4 address the Foxglove server listens on (0.0.0.0: every interface)")
      ->capture_default_str();
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
  // DDS Security (README "Securing a robot"): these, else ROS_SECURITY_ENABLE=true with
  // ROS_SECURITY_KEYSTORE / ROS_SECURITY_ENCLAVE_OVERRIDE / ROS_SECURITY_STRATEGY.
  std::optional<std::string> sec_keystore, sec_enclave;
  app.add_option("--security-keystore", sec_keystore,
                 "SROS2 keystore folder: turns DDS Security on (tools/scripts/keystore.sh)");
  app.add_option("--security-enclave", sec_enclave,
                 "this identity's enclave in it, e.g. /pedalwave/alice");
  if (const auto rc = pedalwave::toolkit::cli::parse(app, argc, argv, "pedalwave_monitor")) return *rc;

  spdlog::set_level(spdlog::level::warn);  // the screen is ours
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);

  telemetry::DomainChoice choice;
  try {
    telemetry::DomainRequest req;
    if (domain) req.cli_domain = &*domain;
    if (interface) req.config_interface = &*interface;
    req.config_localhost_only = localhost_only;
    req.config_peers = cfg.peers;
    choice = telemetry::resolve_domain(req, [](const char* v) { return std::getenv(v); });
  } catch (...) {
    return pedalwave::toolkit::cli::exit_for_current_exception("pedalwave_monitor");
  }
  cfg.domain_id = choice.domain.domain_id;
  cfg.interface = choice.domain.interface;
  try {
    telemetry::SecurityRequest sreq;
    if (sec_keystore) sreq.cli_keystore = &*sec_keystore;
    if (sec_enclave) sreq.cli_enclave = &*sec_enclave;
    const auto sc = telemetry::resolve_security(sreq, [](const char* v) { return std::getenv(v); });
    if (!sc.warning.empty()) std::fprintf(stderr, "pedalwave_monitor: WARNING: %s\n", sc.warning.c_str());
    cfg.security = sc.security;
  } catch (...) {
    return pedalwave::toolkit::cli::exit_for_current_exception("pedalwave_monitor");
  }

  const bool tty = ::isatty(STDOUT_FILENO) == 1;
  const bool command_mode = !command.empty();
  const bool live_view = !no_view && !once && tty && !command_mode;
  std::unique_ptr<telemetry::TelemetrySubscriber> sub;
  std::unique_ptr<telemetry::CsvRecorder> recorder;
  std::unique_ptr<telemetry::McapRecorder> mcap;
  std::unique_ptr<telemetry::FoxgloveServer> foxglove;
  telemetry::MonitorState state(static_cast<std::int64_t>(silence_s * 1e9));
  const bool record_mcap = telemetry::is_mcap_path(record);
  if (record_mcap || foxglove_port) cfg.standard_topics = true;  // every topic, as ROS 2 sees it
  try {
    sub = std::make_unique<telemetry::TelemetrySubscriber>(cfg);
    if (record_mcap) {
      mcap = std::make_unique<telemetry::McapRecorder>(
          record, sub->topics(),
          telemetry::McapRecorderOptions{.compression = mcap::compression_from_string(mcap_compression)});
      sub->add_raw_listener(*mcap);
    } else if (!record.empty()) {
      recorder = std::make_unique<telemetry::CsvRecorder>(record);
    }
    if (foxglove_port) {
      foxglove = std::make_unique<telemetry::FoxgloveServer>(
          sub->topics(), telemetry::FoxgloveServerOptions{.address = foxglove_address,
                                                          .port = *foxglove_port,
                                                          .name = "pedalwave_monitor " + cfg.robot});
      sub->add_raw_listener(*foxglove);
      std::fprintf(stderr, "pedalwave_monitor: Foxglove WebSocket server on ws://%s:%d (%zu channels)\n",
                   foxglove_address.c_str(), foxglove->port(), sub->topics().size());
    }
  } catch (...) {
    // A refused --interface, --domain or --record value (std::invalid_argument): 2; else 1.
    return pedalwave::toolkit::cli::exit_for_current_exception("pedalwave_monitor");
  }
  sub->add_listener(state);
  if (recorder) sub->add_listener(*recorder);

  std::optional<PendingCommand> pending;
  AckWatcher acks;
  acks.robot = cfg.robot;
  sub->add_listener(acks);
  if (!command.empty()) {
    PendingCommand p;
    p.cmd.kind = *parse_kind(command);
    p.cmd.id = static_cast<std::uint64_t>(monotonic_ns());
    p.cmd.amplitude = amplitude;
    p.cmd.omega = omega;
    p.cmd.eta = eta;
    pending = p;
    acks.id = p.cmd.id;
  }

  if (pending && !sub->command_refusal(pending->cmd.kind).empty()) {
    std::fprintf(stderr, "pedalwave_monitor: --command %s not sent: %s\n", command.c_str(),
                 sub->command_refusal(pending->cmd.kind).c_str());
    return 5;
  }
  if (!live_view && !once) {
    std::fprintf(stderr,
                 "pedalwave_monitor: robot \"%s\" (namespace %s), domain %u (%s), discovery %s "
                 "(%s), %s%s\n",
                 cfg.robot.c_str(), cfg.effective_namespace().c_str(), cfg.domain_id,
                 choice.domain_source.c_str(),
                 cfg.interface.empty() ? "Cyclone's choice of interface"
                                       : ("on " + cfg.interface).c_str(),
                 choice.discovery_source.c_str(),
                 telemetry::describe_security(cfg.security).c_str(),
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
    const std::int64_t t = monotonic_ns();
    state.tick(t);
    if (pending && !pending->sent && sub->wait_for_robot(std::chrono::milliseconds(0))) {
      pending->sent = sub->send_command(pending->cmd);
    }
    if (command_mode) {
      // Exit on this command's final ack from this robot (acks of other robots and commands
      // travel on the same topic).
      for (const auto& n : state.take_new_notices()) std::printf("%s\n", n.c_str());
      std::fflush(stdout);
      if (pending->sent && acks.final_ack) {
        const auto& a = *acks.final_ack;
        std::printf("%s: command %s id %llu %s: %s\n", a.robot.c_str(), command.c_str(),
                    static_cast<unsigned long long>(a.id), telemetry::to_string(a.status),
                    a.reason.c_str());
        status = a.status == telemetry::AckStatus::kExecuted ? 0 : 3;
        break;
      }
      if (std::chrono::duration<double>(Clock::now() - start).count() >= ack_timeout_s) {
        std::fprintf(stderr,
                     "pedalwave_monitor: %s within %.1f s (robot \"%s\": is --robot right? a "
                     "robot ignores commands addressed to another name)\n",
                     pending->sent ? "no final ack" : "no robot answering commands", ack_timeout_s,
                     cfg.robot.c_str());
        status = 4;
        break;
      }
      continue;
    }
    if (once && state.complete() && (!pending || pending->sent)) {
      // Give a sent command's ack a moment to arrive before the snapshot.
      for (const auto end = Clock::now() + std::chrono::seconds(1);
           pending && Clock::now() < end;) {
        sub->poll(std::chrono::milliseconds(50));
        state.tick(monotonic_ns());
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
    std::fputs(state.render(monotonic_ns(), tty).c_str(), stdout);
    if (status == 2) std::fprintf(stderr, "pedalwave_monitor: no complete telemetry within %.1f s\n", limit_s);
  }
  if (mcap) {
    int rc = 0;
    try {
      mcap->close();
    } catch (const std::exception& e) {
      std::fprintf(stderr, "pedalwave_monitor: %s\n", e.what());
      rc = 1;
    }
    if (!mcap->error().empty()) {
      std::fprintf(stderr, "pedalwave_monitor: recording stopped early: %s\n", mcap->error().c_str());
      rc = 1;
    }
    std::fprintf(stderr, "pedalwave_monitor: recorded %llu messages on %zu topics to %s (%u chunks, %llu bytes)\n",
                 static_cast<unsigned long long>(mcap->messages()), sub->topics().size(),
                 mcap->path().c_str(), mcap->stats().chunk_count,
                 static_cast<unsigned long long>(mcap->stats().bytes_written));
    if (status == 0) status = rc;
  }
  if (foxglove) {
    std::fprintf(stderr, "pedalwave_monitor: Foxglove server sent %llu messages, dropped %llu for slow clients\n",
                 static_cast<unsigned long long>(foxglove->messages_sent()),
                 static_cast<unsigned long long>(foxglove->messages_dropped()));
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
