// pedalwave_loopbench: does DDS telemetry change the real-time loop's timing?
//
// Runs the real runtime loop — the daemon's wiring: simulated-plant driver (lockstep plant, which
// advances one period inside each write), gait controller, the observer (when its layer is built),
// the telemetry consumer thread — on the real-time clock at --rate, for --seconds, once per phase,
// all in one process run and under the same conditions:
//   off    telemetry off (the consumer drains the rings into no sink)
//   full   DdsTelemetry on lo, all four state topics at the loop rate (decimation 1)
//   demo   DdsTelemetry on lo at the demo's decimation (config/runtime/demo.yaml)
//   full-sec, demo-sec   the same with DDS Security (--security KEYSTORE: enclave
//          /pedalwave/pedalwave publishes, a second subscriber child /pedalwave/bench_monitor
//          reads; the keystore's governance, ENCRYPT by default), interleaved with the others
// for each robot size (--joints, N−1; default 5 and 24: the paper's N = 6 robot and an N = 25 one,
// an inline copy of the flat high-friction scene with more links). A pedalwave_monitor-like
// subscriber runs in a child process (this executable, --subscriber-child) on the same domain
// for the whole run and counts what it receives in each phase.
//
// Prints per phase: wake-up latency and compute time percentiles (p50/p99/p99.9/max), overruns,
// ring drops, and for the telemetry phases samples/s published and received and the loss at the
// subscriber, plus CPU time of the whole process and of the loop thread. --load-threads adds
// background CPU load (SCHED_OTHER spinning threads) for the whole run.
#include <fcntl.h>
#include <poll.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <CLI/CLI.hpp>

#include "pedalwave/toolkit/cli.hpp"

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "daemon.hpp"
#include "gait_stage.hpp"
#include "pedalwave/config/daemon.hpp"
#include "pedalwave/config/shipped.hpp"
#include "pedalwave/drivers/sim_driver.hpp"
#include "pedalwave/runtime/consumer.hpp"
#include "pedalwave/runtime/runtime.hpp"
#include "pedalwave/telemetry/dds_telemetry.hpp"
#include "pedalwave/telemetry/subscriber.hpp"
#include "pedalwave/toolkit/format.hpp"
#include "pedalwave/toolkit/table.hpp"
#include "pedalwave/interface/clock.hpp"

extern char** environ;

namespace {

using namespace pedalwave;
using Clock = std::chrono::steady_clock;

// ---- The subscriber child: counts every state topic; "reset" / "report" on stdin ---------------

struct Counts {
  std::uint64_t joint = 0, controller = 0, observer = 0, timing = 0, events = 0, descriptions = 0;
  std::uint64_t state() const { return joint + controller + observer + timing; }
};

struct CountingListener final : telemetry::TelemetryListener {
  Counts c;
  void on_joint_state(const telemetry::JointStateMsg&, const telemetry::MessageInfo&) override { ++c.joint; }
  void on_controller_state(const telemetry::ControllerStateMsg&, const telemetry::MessageInfo&) override { ++c.controller; }
  void on_observer_state(const telemetry::ObserverStateMsg&, const telemetry::MessageInfo&) override { ++c.observer; }
  void on_loop_timing(const telemetry::LoopTimingMsg&, const telemetry::MessageInfo&) override { ++c.timing; }
  void on_mode_event(const telemetry::ModeEventMsg&, const telemetry::MessageInfo&) override { ++c.events; }
  void on_fault_event(const telemetry::FaultEventMsg&, const telemetry::MessageInfo&) override { ++c.events; }
  void on_description(const telemetry::DescriptionMsg&, const telemetry::MessageInfo&) override { ++c.descriptions; }
};

// The enclaves of the secured phases (keystore.sh robot K pedalwave; monitor K
// /pedalwave/bench_monitor: the same keystore as pedalwave_telemetry_bench --security).
constexpr const char* kRobotEnclave = "/pedalwave/pedalwave";
constexpr const char* kMonitorEnclave = "/pedalwave/bench_monitor";

int subscriber_child(std::uint32_t domain, const std::string& keystore) {
  telemetry::SubscriberConfig sc;
  sc.domain_id = domain;
  if (!keystore.empty()) sc.security = {true, keystore, kMonitorEnclave};
  sc.interface = "lo";
  sc.state_history_depth = 1000;  // as a monitor would: up to 1 s at 1 kHz between polls
  sc.sender = "pedalwave_loopbench";
  telemetry::TelemetrySubscriber sub(sc);
  CountingListener l;
  sub.add_listener(l);
  std::printf("ready\n");
  std::fflush(stdout);
  std::string line;
  for (;;) {
    sub.poll(std::chrono::milliseconds(20));
    pollfd p{STDIN_FILENO, POLLIN, 0};
    if (::poll(&p, 1, 0) <= 0) continue;
    char buf[256];
    const ssize_t n = ::read(STDIN_FILENO, buf, sizeof buf);
    if (n <= 0) return 0;  // parent gone or done
    line.append(buf, static_cast<std::size_t>(n));
    for (std::size_t nl; (nl = line.find('\n')) != std::string::npos;) {
      const std::string cmd = line.substr(0, nl);
      line.erase(0, nl + 1);
      if (cmd == "reset") {
        while (sub.poll(std::chrono::milliseconds(0)) > 0) {}
        l.c = Counts{};
        std::printf("ok\n");
      } else if (cmd == "report") {
        while (sub.poll(std::chrono::milliseconds(0)) > 0) {}
        std::printf("counts %llu %llu %llu %llu %llu %llu\n", static_cast<unsigned long long>(l.c.joint),
                    static_cast<unsigned long long>(l.c.controller), static_cast<unsigned long long>(l.c.observer),
                    static_cast<unsigned long long>(l.c.timing), static_cast<unsigned long long>(l.c.events),
                    static_cast<unsigned long long>(l.c.descriptions));
      }
      std::fflush(stdout);
    }
  }
}

// Parent side of the child.
class SubscriberProcess {
 public:
  // keystore non-empty: the child joins with DDS Security (kMonitorEnclave).
  SubscriberProcess(std::uint32_t domain, const std::string& keystore) {
    int in[2], out[2];
    if (::pipe2(in, O_CLOEXEC) != 0 || ::pipe2(out, O_CLOEXEC) != 0) throw std::runtime_error("pipe2 failed");
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_adddup2(&fa, in[0], STDIN_FILENO);
    posix_spawn_file_actions_adddup2(&fa, out[1], STDOUT_FILENO);
    std::string exe = std::filesystem::read_symlink("/proc/self/exe").string();
    std::string flag = "--subscriber-child", dom = std::to_string(domain), ks = keystore;
    char* argv[] = {exe.data(), flag.data(), dom.data(), ks.empty() ? nullptr : ks.data(), nullptr};
    const int rc = posix_spawn(&pid_, exe.c_str(), &fa, nullptr, argv, environ);
    posix_spawn_file_actions_destroy(&fa);
    ::close(in[0]);
    ::close(out[1]);
    if (rc != 0) throw std::runtime_error("posix_spawn " + exe + " failed");
    to_ = ::fdopen(in[1], "w");
    from_ = ::fdopen(out[0], "r");
    if (read_line() != "ready") throw std::runtime_error("subscriber child did not start");
  }
  ~SubscriberProcess() {
    if (to_) std::fclose(to_);  // EOF on its stdin: the child exits
    if (pid_ > 0) ::waitpid(pid_, nullptr, 0);
    if (from_) std::fclose(from_);
  }
  SubscriberProcess(const SubscriberProcess&) = delete;
  SubscriberProcess& operator=(const SubscriberProcess&) = delete;

  void reset() {
    send("reset");
    read_line();
  }
  Counts report() {
    send("report");
    Counts c;
    unsigned long long v[6] = {};
    const std::string l = read_line();
    if (std::sscanf(l.c_str(), "counts %llu %llu %llu %llu %llu %llu", &v[0], &v[1], &v[2], &v[3], &v[4], &v[5]) == 6)
      c = {v[0], v[1], v[2], v[3], v[4], v[5]};
    return c;
  }

 private:
  void send(const char* s) {
    std::fprintf(to_, "%s\n", s);
    std::fflush(to_);
  }
  std::string read_line() {
    char buf[256];
    if (std::fgets(buf, sizeof buf, from_) == nullptr) return {};
    std::string s(buf);
    if (!s.empty() && s.back() == '\n') s.pop_back();
    return s;
  }
  pid_t pid_ = -1;
  std::FILE* to_ = nullptr;
  std::FILE* from_ = nullptr;
};

// ---- Background load ----------------------------------------------------------------------------

class BackgroundLoad {
 public:
  explicit BackgroundLoad(int threads) {
    for (int t = 0; t < threads; ++t)
      threads_.emplace_back([this] {
        double y = 1.0;
        while (!stop_.load(std::memory_order_relaxed))
          for (int k = 0; k < 100000; ++k) y = std::sqrt(y + 1.0);
        sink_.store(y);
      });
  }
  ~BackgroundLoad() {
    stop_.store(true);
    for (auto& t : threads_) t.join();
  }

 private:
  std::atomic<bool> stop_{false};
  std::atomic<double> sink_{0.0};
  std::vector<std::thread> threads_;
};

// Our part of each cycle without the simulated plant: read + observe + control, from the cycle
// samples (the lockstep plant advances inside the sim driver's write, which a hardware driver
// spends on the bus instead). Runs on the consumer thread in every phase, telemetry on or off.
class ComputeRecorder final : public runtime::TelemetrySink {
 public:
  void on_description(const runtime::RobotDescription&) override {}
  void on_cycle(const runtime::CycleSample& s) override {
    ours->record(static_cast<std::int64_t>(s.t_read_ns) + s.t_observe_ns + s.t_control_ns);
  }
  void on_event(const runtime::EventSample&) override {}
  std::unique_ptr<runtime::LatencyHistogram> ours = std::make_unique<runtime::LatencyHistogram>();
};

// ---- One phase ----------------------------------------------------------------------------------

struct Options {
  double seconds = 10.0;
  double rate = 1000.0;
  int priority = 80;
  int cpu = -1;
  bool lock_memory = true;
  std::vector<int> joints = {5, 24};
  std::vector<std::string> phases = {"off", "full", "demo"};
  int repeat = 1;
  int load_threads = 0;
  std::uint32_t domain = 99;
  std::string keystore;  // --security: the keystore of the *-sec phases
  bool subscriber = true;
  bool verbose = false;
};

struct PhaseResult {
  int joints = 0;
  std::string phase;
  int decimation = 0;  // state-topic decimation, 0 = telemetry off
  bool secure = false; // DDS Security on (the *-sec phases)
  runtime::RunResult run;
  std::unique_ptr<runtime::LoopMetrics> m;
  std::unique_ptr<runtime::LatencyHistogram> ours;  // read + observe + control per cycle [ns]
  telemetry::TelemetryStats sent{};
  Counts received{};
  bool subscriber_matched = false;
  double wall_s = 0.0;      // loop wall time [s]
  double process_cpu = 0.0; // process CPU time over the phase [s]
  double loop_cpu = 0.0;    // loop thread CPU time [s]
};

// The flat high-friction scene (config/scenes/flat_high_friction.yaml) with N links.
std::string scene_yaml(int links) {
  std::ostringstream s;
  s << "name: flat_high_friction_N" << links << "\n"
    << "description: loopbench, the flat high-friction scene with " << links << " links\n"
    << "robot: {N: " << links << ", joints: flexible}\n"
    << "ground: {k: 350, d: 15, mu: 0.82, friction: regularized, v_s: 1.0e-3}\n"
    << "initial: {pose: gait_start, x: 0.0, theta: 0}\n"
    << "gait: {A_p: pi/4, omega: pi, eta: -2*pi/5}\n"
    << "integrator: {method: implicit_velocity, h: 5.0e-4}\n";
  return s.str();
}

// The demo's daemon configuration (config/runtime/demo.yaml) with this run's rate, scene, RT
// settings, domain and decimation.
std::string daemon_yaml(const Options& o, const std::string& scene, int decimation) {
  std::ostringstream s;
  s << "name: loopbench\n"
    << "rate_hz: " << o.rate << "\n"
    << "driver: {type: sim, scene: " << scene << ", clock: lockstep, command_timeout: 0.05}\n"
    << "controller: {k_c: 0, pd_placement: module, K_p: 30, K_D: 15}\n"
    << "realtime: {clock: realtime, priority: " << o.priority << ", cpu: " << o.cpu
    << ", lock_memory: " << (o.lock_memory ? "true" : "false")
    << ", prefault_stack: 262144, stale_timeout: 0.02, auto_start: true}\n"
    << "observer: {enabled: true}\n"
    << "telemetry: {enabled: " << (decimation > 0 ? "true" : "false") << ", domain_id: " << o.domain
    << ", interface: lo, decimation_state: " << std::max(decimation, 1)
    << ", decimation_timing: " << std::max(decimation, 1) << ", commands: true}\n";
  return s.str();
}

double cpu_seconds(int who) {
  rusage u{};
  ::getrusage(who, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

PhaseResult run_phase(const Options& o, int joints, const std::string& phase, int decimation,
                      bool secure, const std::string& scene_path, SubscriberProcess* sub) {
  PhaseResult pr;
  pr.joints = joints;
  pr.phase = phase;
  pr.decimation = decimation;
  pr.secure = secure;
  config::DaemonConfig cfg = config::parse_daemon_config(
      daemon_yaml(o, scene_path, decimation), "loopbench.yaml",
      std::filesystem::path(scene_path).parent_path().string());
  cfg.runtime.max_cycles = static_cast<std::uint64_t>(std::llround(o.seconds * o.rate));
  // The observer runs and its verdicts are published, but never acted on: every phase runs its
  // full length whatever the observer concludes (a benchmark of timing, not of fault handling).
  cfg.runtime.reactions.on_warning = runtime::Reaction::kContinue;
  cfg.runtime.reactions.on_degrade = runtime::Reaction::kContinue;
  cfg.runtime.reactions.on_stop = runtime::Reaction::kContinue;
  cfg.runtime.reactions.by_class.fill(runtime::Reaction::kBySeverity);

  drivers::SimDriver sim(cfg.driver.scene, cfg.driver.sim);
  app::GaitStage stage(cfg.controller);
  const std::unique_ptr<runtime::Observer> observer = app::make_observer(cfg);  // as the daemon wires it
  auto rt = std::make_unique<runtime::Runtime>(cfg.runtime, sim, stage, observer.get());

  ComputeRecorder compute;
  std::vector<runtime::TelemetrySink*> sinks{&compute};
  std::unique_ptr<telemetry::DdsTelemetry> dds;
  if (decimation > 0) {
    telemetry::TelemetryConfig tc;
    tc.domain_id = cfg.telemetry.domain_id;
    tc.interface = cfg.telemetry.interface;
    tc.decimation = {decimation, decimation, decimation, decimation};
    if (secure) tc.security = {true, o.keystore, kRobotEnclave};
    runtime::Runtime* rtp = rt.get();
    dds = std::make_unique<telemetry::DdsTelemetry>(
        tc, [rtp](const runtime::OperatorCommand& c) { return rtp->post(c); });
    sinks.push_back(dds.get());
    if (sub) {
      // Start only once the subscriber is matched, so loss counts what it missed, not discovery.
      const auto end = Clock::now() + std::chrono::seconds(20);
      while (dds->joint_state_readers() == 0 && Clock::now() < end)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
      pr.subscriber_matched = dds->joint_state_readers() > 0;
      std::this_thread::sleep_for(std::chrono::milliseconds(200));  // the other side's match
    }
  }
  if (sub) sub->reset();

  runtime::ConsumerConfig cc;
  cc.log_events = false;
  cc.log_file = "/dev/null";
  runtime::TelemetryConsumer consumer(*rt, sinks, cc);
  consumer.start();
  const double cpu0 = cpu_seconds(RUSAGE_SELF);
  const auto t0 = Clock::now();
  std::thread loop([&] {
    pr.run = rt->run();
    pr.loop_cpu = pedalwave::thread_cpu_s();
  });
  loop.join();
  pr.wall_s = std::chrono::duration<double>(Clock::now() - t0).count();
  consumer.stop();
  pr.process_cpu = cpu_seconds(RUSAGE_SELF) - cpu0;
  pr.m = std::make_unique<runtime::LoopMetrics>(rt->metrics());
  pr.ours = std::move(compute.ours);
  if (dds) {
    pr.sent = dds->stats();
    std::this_thread::sleep_for(std::chrono::milliseconds(300));  // in flight → subscriber
  }
  if (sub) pr.received = sub->report();
  return pr;
}

// ---- Output -------------------------------------------------------------------------------------

double us(std::int64_t ns) { return static_cast<double>(ns) * 1e-3; }

std::string label(const PhaseResult& p) {
  if (p.decimation == 0) return "off";
  return p.phase + " (DDS" + (p.secure ? " secured" : "") + ", 1/" + std::to_string(p.decimation) + ")";
}

void print_tables(const Options& o, const std::vector<PhaseResult>& rs) {
  namespace tk = pedalwave::toolkit;
  auto t1 = [](std::int64_t ns) { return tk::fixed(us(ns), 1); };
  auto count = [](auto n) { return std::to_string(static_cast<unsigned long long>(n)); };
  tk::Table timing({"N−1", "telemetry", "cycles", "wake p50", "wake p99", "wake p99.9", "wake max", "compute p50",
                    "compute p99", "compute p99.9", "compute max", "cycle incl. plant p50", "p99", "p99.9", "max",
                    "overruns", "ring drops (cycle / event)"});
  for (const auto& p : rs) {
    const auto& m = *p.m;
    const auto& c = *p.ours;
    timing.add_row({std::to_string(p.joints), label(p), count(m.cycles), t1(m.wake.percentile(0.5)),
                    t1(m.wake.percentile(0.99)), t1(m.wake.percentile(0.999)), t1(m.wake.max()), t1(c.percentile(0.5)),
                    t1(c.percentile(0.99)), t1(c.percentile(0.999)), t1(c.max()), t1(m.cycle.percentile(0.5)),
                    t1(m.cycle.percentile(0.99)), t1(m.cycle.percentile(0.999)), t1(m.cycle.max()),
                    count(m.overruns), count(p.run.cycle_drops) + " / " + count(p.run.event_drops)});
  }
  std::printf("\n### Loop timing (µs), telemetry off vs on\n\n%s", timing.to_markdown().c_str());
  tk::Table telemetry({"N−1", "telemetry", "state samples published/s", "received/s", "loss", "process CPU [ms/s]",
                       "loop thread CPU [ms/s]", "rest (consumer, DDS) [ms/s]"});
  for (const auto& p : rs) {
    const double sent = static_cast<double>(p.sent.joint_state + p.sent.controller_state +
                                            p.sent.observer_state + p.sent.loop_timing);
    const double recv = static_cast<double>(p.received.state());
    const double proc = 1e3 * p.process_cpu / p.wall_s, loopc = 1e3 * p.loop_cpu / p.wall_s;
    const std::string cpu[3] = {tk::fixed(proc, 1), tk::fixed(loopc, 1), tk::fixed(proc - loopc, 1)};
    if (p.decimation == 0) {
      telemetry.add_row({std::to_string(p.joints), "off", "–", "–", "–", cpu[0], cpu[1], cpu[2]});
    } else if (!o.subscriber) {
      telemetry.add_row({std::to_string(p.joints), label(p), tk::fixed(sent / p.wall_s, 0), "(no subscriber)", "–",
                         cpu[0], cpu[1], cpu[2]});
    } else {
      telemetry.add_row({std::to_string(p.joints),
                         label(p) + (p.subscriber_matched ? "" : " (subscriber NOT matched before the start)"),
                         tk::fixed(sent / p.wall_s, 0), tk::fixed(recv / p.wall_s, 0),
                         tk::fixed(sent > 0 ? 100.0 * (1.0 - recv / sent) : 0.0, 3) + " %", cpu[0], cpu[1], cpu[2]});
    }
  }
  std::printf("\n### Telemetry at the subscriber (child process) and CPU cost\n\n%s", telemetry.to_markdown().c_str());
  std::printf("\nwake = actual wake-up − deadline. compute = read + observe + control of each cycle (our code,\n"
              "from the cycle samples). cycle incl. plant = wake-up → end of publish, including the sim\n"
              "driver's write, which advances the lockstep plant one period.\n"
              "Wall time of each phase: ");
  for (const auto& p : rs) std::printf("%.2f ", p.wall_s);
  std::printf("s\n");
}

}  // namespace

int main(int argc, char** argv) {
  if ((argc == 3 || argc == 4) && std::string(argv[1]) == "--subscriber-child") {
    try {
      return subscriber_child(static_cast<std::uint32_t>(std::stoul(argv[2])), argc == 4 ? argv[3] : "");
    } catch (const std::exception& e) {
      std::fprintf(stderr, "loopbench subscriber: %s\n", e.what());
      return 1;
    }
  }
  Options o;
  CLI::App app{"pedalwave_loopbench: the runtime loop's timing with DDS telemetry off and on"};
  app.add_option("-s,--seconds", o.seconds, "duration of each phase [s]")->check(CLI::Range(0.5, 3600.0));
  app.add_option("-r,--rate", o.rate, "loop rate [Hz]")->check(CLI::Range(1.0, 20000.0));
  app.add_option("-p,--priority", o.priority, "SCHED_FIFO priority of the loop thread, 0 = SCHED_OTHER")
      ->check(CLI::Range(0, 99));
  app.add_option("-c,--cpu", o.cpu, "pin the loop thread to this CPU, -1 = no pinning");
  app.add_flag("!--no-mlock", o.lock_memory, "do not mlockall");
  app.add_option("-j,--joints", o.joints, "robot sizes N−1 to run (each a flat scene with N links)")
      ->check(CLI::Range(1, 63))->delimiter(',');
  app.add_option("--phases", o.phases, "phases: off, full (DDS, every cycle), demo (DDS, demo decimation), "
                 "full-sec, demo-sec (the same with DDS Security, --security)")
      ->check(CLI::IsMember({"off", "full", "demo", "full-sec", "demo-sec"}))->delimiter(',');
  app.add_option("--repeat", o.repeat, "run the phase sequence this many times (interleaved)")->check(CLI::Range(1, 100));
  app.add_option("-b,--load-threads", o.load_threads, "background CPU load threads (SCHED_OTHER) for the whole run")
      ->check(CLI::Range(0, 256));
  app.add_option("--domain", o.domain, "DDS domain id (loopback)")->check(CLI::Range(0, 232));
  app.add_flag("!--no-subscriber", o.subscriber, "no subscriber child process");
  app.add_option("--security", o.keystore,
                 "keystore of the full-sec / demo-sec phases (enclaves /pedalwave/pedalwave as robot, "
                 "/pedalwave/bench_monitor as monitor: tools/scripts/keystore.sh)");
  app.add_flag("-v,--verbose", o.verbose, "print the per-stage table of every phase");
  if (const auto rc = pedalwave::toolkit::cli::parse(app, argc, argv, "pedalwave_loopbench")) return *rc;

  try {
    const int demo_decimation =
        config::load_daemon_config(config::shipped_dir() + "/runtime/demo.yaml").telemetry.decimation_state;
    const auto dir = std::filesystem::temp_directory_path() / ("pedalwave_loopbench_" + std::to_string(::getpid()));
    std::filesystem::create_directories(dir);

    std::printf("pedalwave_loopbench: %.1f s per phase at %.0f Hz, loop thread %s, cpu %d, mlockall %s, "
                "background load %d thread(s), %u online CPUs, load average before: ",
                o.seconds, o.rate, o.priority > 0 ? ("SCHED_FIFO " + std::to_string(o.priority)).c_str() : "SCHED_OTHER",
                o.cpu, o.lock_memory ? "requested" : "off", o.load_threads,
                static_cast<unsigned>(::sysconf(_SC_NPROCESSORS_ONLN)));
    {
      std::ifstream la("/proc/loadavg");
      std::string l;
      std::getline(la, l);
      std::printf("%s\n", l.c_str());
    }
    std::printf("driver: sim (lockstep plant), gait controller (module-side PD), observer on (verdicts published, not acted on); demo decimation 1/%d\n",
                demo_decimation);

    bool any_secure = false;
    for (const auto& phase : o.phases) any_secure = any_secure || phase.ends_with("-sec");
    if (any_secure && o.keystore.empty())
      throw std::invalid_argument("--phases full-sec/demo-sec need --security KEYSTORE (tools/scripts/keystore.sh)");
    // Two subscriber children when secured phases run: a secured participant and a plain one
    // never match, so each phase is read by the child of its kind.
    std::unique_ptr<SubscriberProcess> sub, sub_secure;
    if (o.subscriber) sub = std::make_unique<SubscriberProcess>(o.domain, "");
    if (o.subscriber && any_secure) sub_secure = std::make_unique<SubscriberProcess>(o.domain, o.keystore);
    std::unique_ptr<BackgroundLoad> load;
    if (o.load_threads > 0) load = std::make_unique<BackgroundLoad>(o.load_threads);
    runtime::install_stop_signal_handlers();

    std::vector<PhaseResult> results;
    bool warned = false;
    for (int rep = 0; rep < o.repeat; ++rep) {
      for (int joints : o.joints) {
        const std::string scene = (dir / ("flat_N" + std::to_string(joints + 1) + ".yaml")).string();
        std::ofstream(scene) << scene_yaml(joints + 1);
        for (const auto& phase : o.phases) {
          if (runtime::pending_stop_signal() != 0) break;
          const bool secure = phase.ends_with("-sec");
          const int dec = phase == "off" ? 0 : phase.starts_with("full") ? 1 : demo_decimation;
          PhaseResult pr = run_phase(o, joints, phase, dec, secure, scene, secure ? sub_secure.get() : sub.get());
          if (!warned) {
            std::printf("rt setup: %s\n", pr.run.rt.describe().c_str());
            for (const auto& w : pr.run.rt.warnings)
              std::printf("*** REAL-TIME SETUP PARTLY REFUSED: %s — numbers below are not real-time numbers\n", w.c_str());
            warned = true;
          }
          std::printf("  N-1 = %2d  %-16s done: %llu cycles, exit %s, %llu overruns\n", joints, label(pr).c_str(),
                      static_cast<unsigned long long>(pr.run.cycles), runtime::to_string(pr.run.reason),
                      static_cast<unsigned long long>(pr.run.overruns));
          if (o.verbose) std::printf("%s", runtime::format_table(*pr.m).c_str());
          std::fflush(stdout);
          results.push_back(std::move(pr));
        }
      }
    }
    print_tables(o, results);
    std::filesystem::remove_all(dir);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "pedalwave_loopbench: %s\n", e.what());
    return 2;
  }
  return 0;
}
