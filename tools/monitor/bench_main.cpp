// pedalwave_telemetry_bench: throughput, loss and publisher cost of the DDS telemetry at the loop
// rate, publisher and subscriber in two processes on loopback (as robot and monitor would be).
// For each N: a subscriber process (TelemetrySubscriber counting every topic) and a publisher
// process (DdsTelemetry::on_cycle at `rate` with clock_nanosleep to absolute deadlines, every
// state topic undecimated, SyntheticRobot samples). Reported per N:
//   sent       samples written per topic (joint/controller/observer/timing: the same count)
//   recv/s     samples received per second, all four topics together
//   loss       1 − received/sent over the four topics (best-effort QoS)
//   pub CPU    CPU time of the publishing thread per second of wall time
//              (CLOCK_THREAD_CPUTIME_ID; Cyclone serializes and sends in the writing thread),
//              and of the whole publisher process (getrusage, includes Cyclone's own threads)
//   on_cycle   per-call wall time of DdsTelemetry::on_cycle (4 writes): median, p99, max
//   latency    joint_state write (source timestamp) to the subscriber's take, median and p99
// --security KEYSTORE: both with DDS Security (enclaves /pedalwave/pedalwave, robot role, and
// /pedalwave/bench_monitor, monitor role: tools/scripts/keystore.sh), to compare with it off.
// The parent process never touches DDS (it only forks, so the children start clean).
//
//   pedalwave_telemetry_bench [--seconds 5] [--rate 1000] [--joints 6 24] [--domain 231]
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <CLI/CLI.hpp>

#include "pedalwave/toolkit/cli.hpp"
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include "pedalwave/telemetry/dds_telemetry.hpp"
#include "pedalwave/telemetry/subscriber.hpp"
#include "pedalwave/telemetry/synthetic.hpp"
#include "pedalwave/interface/clock.hpp"

namespace {

using namespace pedalwave;

volatile sig_atomic_t g_stop = 0;
void on_signal(int) { g_stop = 1; }

double process_cpu_s() {
  rusage ru{};
  getrusage(RUSAGE_SELF, &ru);
  return static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

double mono_s() { return 1e-9 * static_cast<double>(monotonic_ns()); }

void write_line(int fd, const std::string& s) {
  const std::string l = s + "\n";
  if (::write(fd, l.data(), l.size()) < 0) std::perror("write");
}

std::string read_line(int fd) {
  std::string s;
  char c = 0;
  while (::read(fd, &c, 1) == 1 && c != '\n') s += c;
  return s;
}

struct Counts : telemetry::TelemetryListener {
  unsigned long long joint = 0, ctrl = 0, obs = 0, timing = 0;
  std::vector<double> latency_us;   // joint_state: source timestamp -> take (both CLOCK_REALTIME)
  void on_joint_state(const telemetry::JointStateMsg&, const telemetry::MessageInfo& mi) override {
    ++joint;
    const std::int64_t now = clock_ns(CLOCK_REALTIME);
    latency_us.push_back(1e-3 * static_cast<double>(now - mi.source_time_ns));
  }
  void on_controller_state(const telemetry::ControllerStateMsg&,
                           const telemetry::MessageInfo&) override {
    ++ctrl;
  }
  void on_observer_state(const telemetry::ObserverStateMsg&,
                         const telemetry::MessageInfo&) override {
    ++obs;
  }
  void on_loop_timing(const telemetry::LoopTimingMsg&, const telemetry::MessageInfo&) override {
    ++timing;
  }
};

// --standard-topics: also sensor_msgs/JointState + /tf on every cycle (and /diagnostics at 1 Hz),
// with a subscriber to them; off: the four pedalwave state topics only (the table in README.md).
bool g_standard = false;
// --security: the keystore (empty: off).
std::string g_keystore;
telemetry::SecurityConfig security_for(const char* enclave) {
  if (g_keystore.empty()) return {};
  return {true, g_keystore, enclave};
}

[[noreturn]] void subscriber_child(std::uint32_t domain, int fd) {
  int rc = 0;
  {
    struct sigaction sa {};
    sa.sa_handler = on_signal;
    sigaction(SIGTERM, &sa, nullptr);
    telemetry::SubscriberConfig cfg;
    cfg.domain_id = domain;
    cfg.state_history_depth = 2000;
    cfg.standard_topics = g_standard;
    cfg.security = security_for("/pedalwave/bench_monitor");
    telemetry::TelemetrySubscriber sub(cfg);
    Counts c;
    c.latency_us.reserve(1'000'000);
    sub.add_listener(c);
    write_line(fd, "ready");
    while (g_stop == 0) sub.poll(std::chrono::milliseconds(20));
    sub.poll(std::chrono::milliseconds(0));
    std::sort(c.latency_us.begin(), c.latency_us.end());
    const auto pct = [&](double p) {
      return c.latency_us.empty()
                 ? 0.0
                 : c.latency_us[static_cast<std::size_t>(p * (c.latency_us.size() - 1))];
    };
    write_line(fd, std::to_string(c.joint) + " " + std::to_string(c.ctrl) + " " +
                       std::to_string(c.obs) + " " + std::to_string(c.timing) + " " +
                       std::to_string(pct(0.5)) + " " + std::to_string(pct(0.99)));
  }
  ::_exit(rc);
}

[[noreturn]] void publisher_child(std::uint32_t domain, int joints, double rate, double seconds,
                                  int fd) {
  {
    telemetry::TelemetryConfig cfg;
    cfg.domain_id = domain;
    cfg.standard_topics = g_standard;
    cfg.security = security_for("/pedalwave/pedalwave");
    telemetry::DdsTelemetry tel(cfg);
    const telemetry::SyntheticRobot robot(joints, rate);
    tel.on_description(robot.description());
    for (int i = 0; i < 1000 && tel.joint_state_readers() == 0; ++i) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    const auto cycles = static_cast<std::uint64_t>(seconds * rate);
    std::vector<runtime::CycleSample> samples(1000);  // precomputed: measure telemetry only
    for (std::size_t i = 0; i < samples.size(); ++i) samples[i] = robot.sample(i);
    std::vector<double> call_us;
    call_us.reserve(cycles);
    const auto period_ns = static_cast<long>(1e9 / rate);
    timespec next = to_timespec(monotonic_ns());
    const double wall0 = mono_s(), cpu0 = thread_cpu_s(), proc0 = process_cpu_s();
    for (std::uint64_t seq = 0; seq < cycles; ++seq) {
      runtime::CycleSample& s = samples[seq % samples.size()];
      s.seq = seq;
      const double t0 = mono_s();
      tel.on_cycle(s);
      call_us.push_back(1e6 * (mono_s() - t0));
      next.tv_nsec += period_ns;
      while (next.tv_nsec >= 1'000'000'000) {
        next.tv_nsec -= 1'000'000'000;
        ++next.tv_sec;
      }
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, nullptr);
    }
    const double wall = mono_s() - wall0, cpu = thread_cpu_s() - cpu0,
                 proc = process_cpu_s() - proc0;
    std::sort(call_us.begin(), call_us.end());
    const auto pct = [&](double p) {
      return call_us.empty() ? 0.0 : call_us[static_cast<std::size_t>(p * (call_us.size() - 1))];
    };
    const auto st = tel.stats();
    char buf[256];
    std::snprintf(buf, sizeof buf, "%llu %.6f %.6f %.6f %.3f %.3f %.3f %llu",
                  static_cast<unsigned long long>(st.joint_state), wall, cpu, proc, pct(0.5),
                  pct(0.99), call_us.empty() ? 0.0 : call_us.back(),
                  static_cast<unsigned long long>(st.write_errors));
    write_line(fd, buf);
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
  }
  ::_exit(0);
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"pedalwave_telemetry_bench: DDS telemetry samples/s, loss and publisher CPU"};
  double seconds = 5.0;
  double rate = 1000.0;
  std::vector<int> joint_counts = {6, 24};
  std::uint32_t domain = 231;
  app.add_option("--seconds", seconds, "publishing time per N [s]")->check(CLI::PositiveNumber)
      ->capture_default_str();
  app.add_option("--rate", rate, "cycle rate [Hz]")->check(CLI::Range(1.0, 20000.0))
      ->capture_default_str();
  app.add_option("--joints", joint_counts, "N-1 values to measure")
      ->check(CLI::Range(1, runtime::kMaxJoints));
  app.add_flag("--standard-topics", g_standard,
               "also publish (and subscribe to) the standard ROS 2 topics: joint_states, tf, "
               "diagnostics");
  app.add_option("--security", g_keystore,
                 "DDS Security with this keystore (enclaves /pedalwave/pedalwave as robot, "
                 "/pedalwave/bench_monitor as monitor; domain <= 230)");
  app.add_option("--domain", domain, "DDS domain id (keep clear of other users)")
      ->check(CLI::Range(0, 232))
      ->capture_default_str();
  if (const auto rc = pedalwave::toolkit::cli::parse(app, argc, argv, "pedalwave_telemetry_bench")) return *rc;
  spdlog::set_level(spdlog::level::warn);

  std::printf("DDS telemetry, loopback, two processes, %g Hz for %g s per N, 4 state topics "
              "undecimated (best-effort), %s\n",
              rate, seconds,
              g_keystore.empty() ? "DDS Security off"
                                 : ("DDS Security ON (keystore " + g_keystore + ")").c_str());
  std::printf("%5s %8s %10s %8s %12s %14s %16s %28s %20s\n", "N-1", "sent", "recv/s", "loss",
              "write errs", "pub thread CPU", "pub process CPU", "on_cycle p50/p99/max [us]",
              "latency p50/p99 [us]");
  int failures = 0;
  for (int joints : joint_counts) {
    int sub_pipe[2], pub_pipe[2];
    if (::pipe(sub_pipe) != 0 || ::pipe(pub_pipe) != 0) return 1;
    std::fflush(stdout);
    const pid_t sub = ::fork();
    if (sub == 0) subscriber_child(domain, sub_pipe[1]);
    if (read_line(sub_pipe[0]) != "ready") {
      std::fprintf(stderr, "subscriber failed to start\n");
      return 1;
    }
    const pid_t pub = ::fork();
    if (pub == 0) publisher_child(domain, joints, rate, seconds, pub_pipe[1]);
    const std::string pr = read_line(pub_pipe[0]);
    ::waitpid(pub, nullptr, 0);
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    ::kill(sub, SIGTERM);
    const std::string sr = read_line(sub_pipe[0]);
    ::waitpid(sub, nullptr, 0);
    for (int fd : {sub_pipe[0], sub_pipe[1], pub_pipe[0], pub_pipe[1]}) ::close(fd);

    unsigned long long sent = 0, errors = 0, j = 0, c = 0, o = 0, t = 0;
    double wall = 0, cpu = 0, proc = 0, p50 = 0, p99 = 0, pmax = 0, l50 = 0, l99 = 0;
    if (std::sscanf(pr.c_str(), "%llu %lf %lf %lf %lf %lf %lf %llu", &sent, &wall, &cpu, &proc,
                    &p50, &p99, &pmax, &errors) != 8 ||
        std::sscanf(sr.c_str(), "%llu %llu %llu %llu %lf %lf", &j, &c, &o, &t, &l50, &l99) != 6 ||
        wall <= 0.0) {
      std::fprintf(stderr, "N-1 = %d: no result (publisher \"%s\", subscriber \"%s\")\n", joints,
                   pr.c_str(), sr.c_str());
      ++failures;
      continue;
    }
    const double recv = static_cast<double>(j + c + o + t);
    const double loss = 1.0 - recv / (4.0 * static_cast<double>(sent));
    char cpu_col[32], proc_col[32], calls[48], lat[40];
    std::snprintf(lat, sizeof lat, "%.0f / %.0f", l50, l99);
    std::snprintf(cpu_col, sizeof cpu_col, "%.1f ms/s", 1e3 * cpu / wall);
    std::snprintf(proc_col, sizeof proc_col, "%.1f ms/s", 1e3 * proc / wall);
    std::snprintf(calls, sizeof calls, "%.1f / %.1f / %.1f", p50, p99, pmax);
    std::printf("%5d %8llu %10.0f %7.3f%% %12llu %14s %16s %28s %20s\n", joints, sent,
                recv / wall, 100.0 * loss, errors, cpu_col, proc_col, calls, lat);
    std::printf("      per topic received: joint_state %llu, controller_state %llu, "
                "observer_state %llu, loop_timing %llu\n",
                j, c, o, t);
  }
  return failures == 0 ? 0 : 1;
}
