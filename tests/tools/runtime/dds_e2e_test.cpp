// End to end with real Cyclone DDS on loopback: the runtime daemon (app::run_daemon) in
// simulated-plant mode, real-time loop clock at 1 kHz, publishing its telemetry, and subscribers
// receiving it — in this process (TelemetrySubscriber) and in other processes (pedalwave_monitor
// recording to CSV, over the loopback network). Checks:
//   - every topic arrives; content is consistent with the run (N−1 joints, the description is the
//     configuration's robot, α = β − deflection, SEA torque = K·deflection, modes
//     READY → RUNNING → SAFE_STOP with the safe stop last);
//   - rates follow the decimation: per topic, the published seqs are exactly the multiples of the
//     decimation, received with a stated best-effort loss (≤ 5 % of the expected samples, plus
//     what the runtime's own ring dropped);
//   - a late-joining subscriber (started mid-run) still gets the description and the mode events
//     that happened before it joined (transient-local), in-process and in another process;
//   - an emergency stop sent over DDS by another participant (the monitor, as an operator would
//     use it; and an in-process subscriber) stops the runtime with reason emergency stop, and the
//     safe stop reaches the driver (torque off at the simulated modules, the driver's last call).
// Robust on a loaded machine: no wall-clock bound is asserted; waits are long timeouts only.
// Each test process leases its own DDS domain id with the same lock files as tests/runtime/telemetry.
#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/file.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "daemon.hpp"
#include "dds_domain_lease.hpp"
#include "gait_stage.hpp"
#include "pedalwave/config/daemon.hpp"
#include "pedalwave/drivers/sim_driver.hpp"
#include "pedalwave/runtime/consumer.hpp"
#include "pedalwave/runtime/runtime.hpp"
#include "pedalwave/telemetry/dds_telemetry.hpp"
#include "pedalwave/telemetry/subscriber.hpp"

extern char** environ;

using namespace pedalwave;
using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

namespace {

// Generous upper bound for anything we wait for (discovery, a run on a machine at load 15).
constexpr auto kPatience = 120s;

// This process's own DDS domain (the same leases tests/runtime/telemetry takes).
std::uint32_t domain_id() { return test::dds_domain_id(); }

// The demo configuration (real-time loop clock, lockstep plant, telemetry on lo with the demo's
// decimation) on this process's domain, for `cycles` cycles.
config::DaemonConfig demo_config(std::uint64_t cycles) {
  auto c = config::load_daemon_config(PEDALWAVE_CONFIG_DIR "/runtime/demo.yaml");
  EXPECT_EQ(c.runtime.clock, runtime::ClockMode::kRealtime) << "demo.yaml should run on the real-time clock";
  c.duration = static_cast<double>(cycles) / c.runtime.rt.rate_hz;
  c.runtime.max_cycles = cycles;
  c.telemetry.enabled = true;
  c.telemetry.has_domain_id = true;
  c.telemetry.domain_id = domain_id();
  c.telemetry.has_interface = true;
  c.telemetry.interface = "lo";
  c.log_file = "/dev/null";  // the consumer's event log; the test reads the bus instead
  // The observer's verdicts are published but never acted on, so how long a run lasts and its
  // mode sequence do not depend on how loaded the machine is: on a loaded machine the demo's
  // SCHED_OTHER loop overruns, and (observed while writing this test) the observer then reports
  // encoder jumps/noise on the healthy plant, which by default would freeze or stop the robot.
  c.runtime.reactions.on_warning = runtime::Reaction::kContinue;
  c.runtime.reactions.on_degrade = runtime::Reaction::kContinue;
  c.runtime.reactions.on_stop = runtime::Reaction::kContinue;
  c.runtime.reactions.by_class.fill(runtime::Reaction::kBySeverity);
  return c;
}

telemetry::SubscriberConfig subscriber_config(const std::string& sender = "test_e2e") {
  telemetry::SubscriberConfig s;
  s.domain_id = domain_id();
  s.interface = "lo";
  s.state_history_depth = 2000;  // 2 s at 1 kHz between polls: a stalled test thread loses nothing
  s.sender = sender;
  s.robot = "demo";  // demo.yaml's name: its namespace /demo and the commands' target
  return s;
}

// Everything a subscriber received, in order.
struct Collector final : telemetry::TelemetryListener {
  std::vector<telemetry::JointStateMsg> joint;
  std::vector<telemetry::ControllerStateMsg> controller;
  std::vector<telemetry::ObserverStateMsg> observer;
  std::vector<telemetry::LoopTimingMsg> timing;
  std::vector<telemetry::ModeEventMsg> modes;
  std::vector<telemetry::FaultEventMsg> faults;
  std::vector<telemetry::DescriptionMsg> descriptions;
  std::vector<telemetry::CommandAckMsg> acks;
  void on_joint_state(const telemetry::JointStateMsg& m, const telemetry::MessageInfo&) override { joint.push_back(m); }
  void on_controller_state(const telemetry::ControllerStateMsg& m, const telemetry::MessageInfo&) override { controller.push_back(m); }
  void on_observer_state(const telemetry::ObserverStateMsg& m, const telemetry::MessageInfo&) override { observer.push_back(m); }
  void on_loop_timing(const telemetry::LoopTimingMsg& m, const telemetry::MessageInfo&) override { timing.push_back(m); }
  void on_mode_event(const telemetry::ModeEventMsg& m, const telemetry::MessageInfo&) override { modes.push_back(m); }
  void on_fault_event(const telemetry::FaultEventMsg& m, const telemetry::MessageInfo&) override { faults.push_back(m); }
  void on_description(const telemetry::DescriptionMsg& m, const telemetry::MessageInfo&) override { descriptions.push_back(m); }
  void on_command_ack(const telemetry::CommandAckMsg& m, const telemetry::MessageInfo&) override { acks.push_back(m); }

  bool saw_mode(runtime::Mode to) const {
    for (const auto& m : modes)
      if (m.to == static_cast<std::uint8_t>(to) && m.from != m.to) return true;
    return false;
  }
  // Mode transitions (from != to) as "ready>running" strings, in arrival order.
  std::vector<std::string> transitions() const {
    std::vector<std::string> t;
    for (const auto& m : modes)
      if (m.from != m.to) t.push_back(m.from_name + ">" + m.to_name);
    return t;
  }
};

// run_daemon on its own thread; the test thread polls subscribers meanwhile.
class DaemonThread {
 public:
  explicit DaemonThread(config::DaemonConfig cfg) : cfg_(std::move(cfg)) {
    // run_daemon installs these too; installing them first makes stop() safe at any moment.
    runtime::install_stop_signal_handlers();
    thread_ = std::thread([this] {
      try {
        result_ = app::run_daemon(cfg_, {.plots_dir = "", .telemetry = true, .print = false});
      } catch (...) {
        error_ = std::current_exception();
      }
      done_.store(true);
    });
  }
  // A test that fails early must not leave a long run going: SIGINT → the runtime's safe stop.
  ~DaemonThread() {
    if (thread_.joinable()) {
      if (!done_.load()) ::kill(::getpid(), SIGINT);
      thread_.join();
    }
    runtime::clear_stop_signal();
  }
  bool done() const { return done_.load(); }
  const app::DaemonResult& join() {
    thread_.join();
    if (error_) std::rethrow_exception(error_);
    return result_;
  }

 private:
  config::DaemonConfig cfg_;
  app::DaemonResult result_;
  std::exception_ptr error_;
  std::atomic<bool> done_{false};
  std::thread thread_;
};

// Polls `sub` until pred() or the patience runs out; returns pred().
template <class Pred>
bool poll_until(telemetry::TelemetrySubscriber& sub, Pred pred, std::chrono::nanoseconds patience = kPatience) {
  const auto end = Clock::now() + patience;
  while (!pred() && Clock::now() < end) sub.poll(20ms);
  return pred();
}

// After the publisher is gone: take whatever is still queued (nothing new for 300 ms).
// Until nothing came for 1 s (at most 10 s): a reliable sample lost on loopback is repaired after
// the writer's next heartbeat (100 ms), and on a loaded machine that took longer than the 300 ms
// this waited before (a fault event missing beside its flags in observer_state, once).
void drain(telemetry::TelemetrySubscriber& sub) {
  auto quiet_since = Clock::now();
  const auto end = Clock::now() + 10s;
  while (Clock::now() - quiet_since < 1s && Clock::now() < end)
    if (sub.poll(20ms) > 0) quiet_since = Clock::now();
}

// pedalwave_monitor as a child process (its own Cyclone domain instance: the loopback network),
// stdout and stderr to files; stopped with SIGINT (it then flushes its CSV files and exits 0).
class MonitorProcess {
 public:
  MonitorProcess(const std::vector<std::string>& extra, const std::string& out_path) {
#ifdef PEDALWAVE_MONITOR_EXE
    std::vector<std::string> argv{PEDALWAVE_MONITOR_EXE, "--domain", std::to_string(domain_id()),
                                  "--interface", "lo", "--robot", "demo", "--no-view"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, STDOUT_FILENO, out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    posix_spawn_file_actions_adddup2(&fa, STDOUT_FILENO, STDERR_FILENO);
    std::vector<char*> args;
    for (auto& a : argv) args.push_back(a.data());
    args.push_back(nullptr);
    const int rc = posix_spawn(&pid_, args[0], &fa, nullptr, args.data(), environ);
    posix_spawn_file_actions_destroy(&fa);
    if (rc != 0) throw std::runtime_error("posix_spawn " + argv[0] + " failed");
#else
    (void)extra, (void)out_path;
#endif
  }
  ~MonitorProcess() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
  }
  MonitorProcess(const MonitorProcess&) = delete;
  MonitorProcess& operator=(const MonitorProcess&) = delete;
  // SIGINT, then wait; returns the exit status (128 + signal if killed).
  int stop() {
    ::kill(pid_, SIGINT);
    int st = 0;
    ::waitpid(pid_, &st, 0);
    pid_ = -1;
    return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
  }

 private:
  pid_t pid_ = -1;
};

bool have_monitor() {
#ifdef PEDALWAVE_MONITOR_EXE
  return true;
#else
  return false;
#endif
}

// A CSV file written by CsvRecorder: header → column index, rows as cells (quotes removed).
struct Csv {
  std::map<std::string, std::size_t> col;
  std::vector<std::vector<std::string>> rows;
  const std::string& at(std::size_t r, const std::string& name) const { return rows.at(r).at(col.at(name)); }
};
std::vector<std::string> split_csv(const std::string& line) {
  std::vector<std::string> cells(1);
  bool quoted = false;
  for (std::size_t i = 0; i < line.size(); ++i) {
    const char c = line[i];
    if (quoted) {
      if (c == '"' && i + 1 < line.size() && line[i + 1] == '"') cells.back() += '"', ++i;
      else if (c == '"') quoted = false;
      else cells.back() += c;
    } else if (c == '"') {
      quoted = true;
    } else if (c == ',') {
      cells.emplace_back();
    } else {
      cells.back() += c;
    }
  }
  return cells;
}
Csv read_csv(const std::string& path) {
  Csv csv;
  std::ifstream in(path);
  std::string line;
  if (!std::getline(in, line)) return csv;
  const auto head = split_csv(line);
  for (std::size_t i = 0; i < head.size(); ++i) csv.col[head[i]] = i;
  while (std::getline(in, line))
    if (!line.empty()) csv.rows.push_back(split_csv(line));
  return csv;
}

std::string temp_dir(const std::string& tag) {
  const auto d = std::filesystem::temp_directory_path() /
                 ("pedalwave_e2e_" + tag + "_" + std::to_string(::getpid()));
  std::filesystem::create_directories(d);
  return d.string();
}

// Number of multiples of k in [first, last].
std::uint64_t multiples_in(std::uint64_t first, std::uint64_t last, std::uint64_t k) {
  if (last < first) return 0;
  const std::uint64_t lo = (first + k - 1) / k, hi = last / k;
  return hi >= lo ? hi - lo + 1 : 0;
}

// The state topics of one subscriber: seqs strictly increasing multiples of k, and a count that
// misses at most 5 % of the samples published in [0, cycles) (plus the runtime ring's own drops,
// which never reached the publisher). Best-effort over DDS promises no more.
template <class Msg>
void expect_decimated_stream(const std::vector<Msg>& v, const char* topic, std::uint64_t k,
                             std::uint64_t cycles, std::uint64_t ring_drops) {
  ASSERT_FALSE(v.empty()) << topic << ": nothing received";
  for (std::size_t i = 0; i < v.size(); ++i) {
    EXPECT_EQ(v[i].seq % k, 0u) << topic << " seq " << v[i].seq << " is not a multiple of the decimation " << k;
    if (i > 0) {
      EXPECT_GT(v[i].seq, v[i - 1].seq) << topic << ": seq not increasing at " << i;
    }
    EXPECT_LT(v[i].seq, cycles) << topic;
  }
  const std::uint64_t expected = multiples_in(0, cycles - 1, k);
  const double allowed_missing = 0.05 * static_cast<double>(expected) + static_cast<double>(ring_drops / k + 1);
  EXPECT_GE(static_cast<double>(v.size()), static_cast<double>(expected) - allowed_missing)
      << topic << ": received " << v.size() << " of " << expected << " published (decimation " << k
      << ", ring drops " << ring_drops << ")";
  EXPECT_LE(v.size(), expected) << topic;
}

void expect_description_matches(const telemetry::DescriptionMsg& d, const config::DaemonConfig& c) {
  const model::Params& p = c.robot;
  EXPECT_EQ(d.links, p.N);
  EXPECT_DOUBLE_EQ(d.link_length, 2.0 * p.l);
  EXPECT_DOUBLE_EQ(d.link_mass, p.m_l);
  EXPECT_DOUBLE_EQ(d.rotor_mass, p.m_r);
  EXPECT_DOUBLE_EQ(d.rotor_inertia, p.I_r);
  EXPECT_DOUBLE_EQ(d.gear_ratio, p.n);
  ASSERT_EQ(d.spring_stiffness.size(), static_cast<std::size_t>(p.N - 1));
  for (int j = 0; j < p.N - 1; ++j) EXPECT_DOUBLE_EQ(d.spring_stiffness[static_cast<std::size_t>(j)], p.stiffness(j)) << j;
  EXPECT_DOUBLE_EQ(d.rate_hz, c.runtime.rt.rate_hz);
  EXPECT_DOUBLE_EQ(d.joint_state_rate_hz, c.runtime.rt.rate_hz / c.telemetry.decimation_state);
  EXPECT_DOUBLE_EQ(d.loop_timing_rate_hz, c.runtime.rt.rate_hz / c.telemetry.decimation_timing);
  EXPECT_EQ(d.name, c.name);
  EXPECT_EQ(d.driver, "sim");
}

std::size_t count_rows_with(const Csv& csv, const std::string& col, const std::string& value) {
  if (!csv.col.count(col)) return 0;
  std::size_t n = 0;
  for (std::size_t r = 0; r < csv.rows.size(); ++r)
    if (csv.at(r, col) == value) ++n;
  return n;
}

}  // namespace

// The demo robot publishing for 4 s at 1 kHz (4000 cycles); an in-process subscriber from the start,
// a monitor process from the start, and late joiners (one in-process, one monitor process) started
// once the robot has been RUNNING for a while.
TEST(DdsEndToEnd, RuntimePublishesEveryTopicConsistentlyAndLateJoinersCatchUp) {
  constexpr std::uint64_t kCycles = 4000;
  const config::DaemonConfig cfg = demo_config(kCycles);
  const int J = cfg.robot.N - 1;
  const auto dec_state = static_cast<std::uint64_t>(cfg.telemetry.decimation_state);
  const auto dec_timing = static_cast<std::uint64_t>(cfg.telemetry.decimation_timing);
  ASSERT_GT(dec_state, 1u) << "the demo decimates the state topics; this test checks that";

  const std::string dir = temp_dir("publish");
  telemetry::TelemetrySubscriber sub(subscriber_config());
  Collector all;
  sub.add_listener(all);
  std::unique_ptr<MonitorProcess> early_mon, late_mon;
  if (have_monitor()) early_mon = std::make_unique<MonitorProcess>(
                          std::vector<std::string>{"--record", dir + "/early.csv"}, dir + "/early.log");

  DaemonThread daemon(cfg);

  // Mid-run: the robot has been RUNNING and published state for a while (≥ 1000 cycles).
  ASSERT_TRUE(poll_until(sub, [&] {
    return daemon.done() || (all.saw_mode(runtime::Mode::kRunning) && !all.joint.empty() &&
                             all.joint.back().seq >= 1000);
  })) << "no state from the robot within the patience";
  if (daemon.done()) {
    std::string why;
    for (const auto& m : all.modes) why += "\n  mode " + m.from_name + " > " + m.to_name + ": " + m.text;
    for (const auto& f : all.faults)
      why += "\n  fault " + f.class_name + " joint " + std::to_string(f.joint) + " value " +
             std::to_string(f.value) + " threshold " + std::to_string(f.threshold) + ": " + f.text;
    FAIL() << "the run ended before the late joiners could join (received " << all.joint.size()
           << " joint states)" << why;
  }
  telemetry::TelemetrySubscriber late(subscriber_config("late"));
  Collector late_seen;
  late.add_listener(late_seen);
  if (have_monitor()) late_mon = std::make_unique<MonitorProcess>(
                         std::vector<std::string>{"--record", dir + "/late.csv"}, dir + "/late.log");
  const std::uint64_t joined_at = all.joint.back().seq;

  while (!daemon.done()) {
    sub.poll(10ms);
    late.poll(10ms);
  }
  const app::DaemonResult& r = daemon.join();
  drain(sub);
  drain(late);

  // ---- The run itself ----
  EXPECT_TRUE(r.telemetry_active);
  EXPECT_EQ(r.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(r.run.final_mode, runtime::Mode::kSafeStop);
  EXPECT_EQ(r.run.cycles, kCycles);

  // ---- Every topic arrived (fault_event only if the observer reported something) ----
  ASSERT_FALSE(all.descriptions.empty()) << "robot_description";
  ASSERT_FALSE(all.modes.empty()) << "mode_event";
  ASSERT_FALSE(all.joint.empty()) << "joint_state";
  ASSERT_FALSE(all.controller.empty()) << "controller_state";
  ASSERT_FALSE(all.observer.empty()) << "observer_state";
  ASSERT_FALSE(all.timing.empty()) << "loop_timing";
  EXPECT_EQ(r.run.fault, runtime::FaultClass::kNone) << "verdicts do not stop this run";

  // ---- Description = the configuration's robot ----
  expect_description_matches(all.descriptions.back(), cfg);

  // ---- Modes: ... READY → RUNNING → SAFE_STOP, the safe stop last ----
  const auto tr = all.transitions();
  ASSERT_GE(tr.size(), 3u);
  EXPECT_EQ(tr[tr.size() - 3], "configured>ready");
  EXPECT_EQ(tr[tr.size() - 2], "ready>running");
  EXPECT_EQ(tr[tr.size() - 1], "running>safe_stop");
  EXPECT_EQ(all.modes.back().to, static_cast<std::uint8_t>(runtime::Mode::kSafeStop)) << "safe stop is the last event";
  EXPECT_NE(all.modes.back().text.find("cycle limit"), std::string::npos) << all.modes.back().text;
  for (std::size_t i = 1; i < all.modes.size(); ++i) EXPECT_GE(all.modes[i].seq, all.modes[i - 1].seq);

  // ---- Content: N−1 joints; α = β − deflection; τ_SEA = K·deflection; finite everything ----
  const auto& K = all.descriptions.back().spring_stiffness;
  for (const auto& m : all.joint) {
    ASSERT_EQ(m.beta.size(), static_cast<std::size_t>(J));
    ASSERT_EQ(m.beta_dot.size(), static_cast<std::size_t>(J));
    ASSERT_EQ(m.alpha.size(), static_cast<std::size_t>(J));
    ASSERT_EQ(m.deflection.size(), static_cast<std::size_t>(J));
    ASSERT_EQ(m.tau_sea.size(), static_cast<std::size_t>(J));
    for (std::size_t j = 0; j < static_cast<std::size_t>(J); ++j) {
      ASSERT_TRUE(std::isfinite(m.beta[j]) && std::isfinite(m.beta_dot[j]) && std::isfinite(m.deflection[j]));
      EXPECT_NEAR(m.alpha[j], m.beta[j] - m.deflection[j], 1e-12) << "seq " << m.seq << " joint " << j;
      EXPECT_NEAR(m.tau_sea[j], K[j] * m.deflection[j], 1e-9 * (1.0 + std::abs(K[j] * m.deflection[j])))
          << "seq " << m.seq << " joint " << j;
    }
  }
  // The plant moves: the gait drives the joints (not a stream of zeros).
  double max_abs_beta = 0.0, max_abs_defl = 0.0;
  for (const auto& m : all.joint)
    for (std::size_t j = 0; j < static_cast<std::size_t>(J); ++j) {
      max_abs_beta = std::max(max_abs_beta, std::abs(m.beta[j]));
      max_abs_defl = std::max(max_abs_defl, std::abs(m.deflection[j]));
    }
  EXPECT_GT(max_abs_beta, 0.1) << "the gait (A_p = π/4) should swing the joints";
  EXPECT_GT(max_abs_defl, 0.0) << "flexible joints under load deflect";
  // Controller state: mode running while walking, commands sized and finite, the safe stop zero.
  std::size_t running = 0;
  for (const auto& m : all.controller) {
    ASSERT_EQ(m.alpha_d.size(), static_cast<std::size_t>(J));
    ASSERT_EQ(m.eta.size(), static_cast<std::size_t>(J));
    ASSERT_EQ(m.u.size(), static_cast<std::size_t>(J));
    for (double x : m.u) ASSERT_TRUE(std::isfinite(x));
    if (m.mode == static_cast<std::uint8_t>(runtime::Mode::kRunning)) {
      ++running;
      EXPECT_EQ(m.mode_name, "running");
    }
  }
  EXPECT_GE(running, all.controller.size() - 2) << "all but the first/last state samples are RUNNING";
  // Time: controller time advances with seq at the loop period (t = seq·T from the first cycle).
  for (std::size_t i = 1; i < all.joint.size(); ++i) {
    const double dt = all.joint[i].t - all.joint[i - 1].t;
    const double dseq = static_cast<double>(all.joint[i].seq - all.joint[i - 1].seq);
    EXPECT_GT(dt, 0.0);
    EXPECT_GE(all.joint[i].stamp_ns, all.joint[i - 1].stamp_ns);
    EXPECT_GE(dt, dseq / cfg.runtime.rt.rate_hz - 1e-9) << "t advances at least one period per cycle";
  }
  for (const auto& m : all.observer) {
    ASSERT_EQ(m.residual.size(), static_cast<std::size_t>(J));
    ASSERT_EQ(m.tau_ext.size(), static_cast<std::size_t>(J));
    for (std::size_t j = 0; j < static_cast<std::size_t>(J); ++j)
      ASSERT_TRUE(std::isfinite(m.residual[j]) && std::isfinite(m.tau_ext[j])) << "seq " << m.seq;
  }
  // Fault events and observer state tell the same story: a fault class reported at seq s is set
  // in the fault flags of an observer_state sample from s on (latched), and flags set in a sample
  // belong to classes that were reported as events (event ring drops aside).
  std::uint32_t reported = 0;
  for (const auto& f : all.faults) {
    ASSERT_LT(f.fault_class, 32u);
    EXPECT_NE(f.class_name, "none");
    EXPECT_GE(f.joint, -1);
    EXPECT_LT(f.joint, J);
    reported |= 1u << f.fault_class;
    bool seen_in_state = false;
    for (const auto& m : all.observer)
      if (m.seq >= f.seq && (m.fault_flags & (1u << f.fault_class))) seen_in_state = true;
    const bool state_after = !all.observer.empty() && all.observer.back().seq >= f.seq + dec_state;
    if (state_after) {
      EXPECT_TRUE(seen_in_state) << f.class_name << " at seq " << f.seq << " never in observer_state";
    }
  }
  if (r.run.event_drops == 0) {
    for (const auto& m : all.observer) {
      EXPECT_EQ(m.fault_flags & ~reported, 0u) << "seq " << m.seq << ": flags without a fault event";
    }
  }
  // Loop timing: cumulative counters never decrease and end at most at the run's totals.
  for (std::size_t i = 1; i < all.timing.size(); ++i) {
    EXPECT_GE(all.timing[i].overruns, all.timing[i - 1].overruns);
    EXPECT_GE(all.timing[i].ring_drops, all.timing[i - 1].ring_drops);
  }
  EXPECT_LE(all.timing.back().overruns, r.run.overruns);
  EXPECT_LE(all.timing.back().ring_drops, r.run.cycle_drops);
  for (const auto& m : all.timing) EXPECT_GE(m.t_read_ns + m.t_control_ns + m.t_write_ns, 0);

  // ---- Rates: exactly the decimated seqs, within the stated best-effort loss ----
  std::printf("run: %llu cycles, %llu overruns, ring drops %llu; in-process received: joint %zu, "
              "controller %zu, observer %zu, timing %zu, modes %zu, fault events %zu, descriptions %zu; "
              "late joiner from seq %llu\n",
              static_cast<unsigned long long>(r.run.cycles), static_cast<unsigned long long>(r.run.overruns),
              static_cast<unsigned long long>(r.run.cycle_drops), all.joint.size(), all.controller.size(),
              all.observer.size(), all.timing.size(), all.modes.size(), all.faults.size(),
              all.descriptions.size(), static_cast<unsigned long long>(late_seen.joint.empty() ? 0 : late_seen.joint.front().seq));
  expect_decimated_stream(all.joint, "joint_state", dec_state, r.run.cycles, r.run.cycle_drops);
  expect_decimated_stream(all.controller, "controller_state", dec_state, r.run.cycles, r.run.cycle_drops);
  expect_decimated_stream(all.observer, "observer_state", dec_state, r.run.cycles, r.run.cycle_drops);
  expect_decimated_stream(all.timing, "loop_timing", dec_timing, r.run.cycles, r.run.cycle_drops);

  // ---- The late in-process joiner: description and the earlier mode events (transient-local) ----
  ASSERT_FALSE(late_seen.descriptions.empty()) << "late joiner: no description";
  expect_description_matches(late_seen.descriptions.front(), cfg);
  const auto late_tr = late_seen.transitions();
  ASSERT_GE(late_tr.size(), 3u);
  EXPECT_EQ(late_tr[late_tr.size() - 2], "ready>running") << "happened before the late joiner existed";
  EXPECT_EQ(late_tr.back(), "running>safe_stop");
  ASSERT_FALSE(late_seen.joint.empty());
  EXPECT_GT(late_seen.joint.front().seq, 0u) << "state is volatile: a late joiner starts mid-run";
  EXPECT_GT(late_seen.joint.front().seq, joined_at) << "no state from before it joined (volatile)";

  // ---- The monitor processes (the loopback network path) ----
  if (!have_monitor()) {
    GTEST_SKIP() << "*** pedalwave_monitor not built (tools off): the cross-process half of this "
                    "test did not run ***";
  }
  EXPECT_EQ(early_mon->stop(), 0);
  EXPECT_EQ(late_mon->stop(), 0);
  // Early monitor: every topic, decimated seqs, ≤ 5 % loss over the seq span it was matched for.
  for (const char* topic : {"joint_state", "controller_state", "observer_state", "loop_timing"}) {
    const Csv c = read_csv(dir + "/early." + topic + ".csv");
    ASSERT_FALSE(c.rows.empty()) << "monitor process: no " << topic << " (log: " << dir << "/early.log)";
    const std::uint64_t k = std::string(topic) == "loop_timing" ? dec_timing : dec_state;
    std::uint64_t first = std::stoull(c.at(0, "seq")), last = first;
    for (std::size_t i = 0; i < c.rows.size(); ++i) {
      const std::uint64_t s = std::stoull(c.at(i, "seq"));
      EXPECT_EQ(s % k, 0u) << topic;
      last = s;
    }
    const std::uint64_t expected = multiples_in(first, last, k);
    std::printf("monitor process, %s: %zu rows of %llu published in seq [%llu, %llu]\n", topic, c.rows.size(),
                static_cast<unsigned long long>(expected), static_cast<unsigned long long>(first),
                static_cast<unsigned long long>(last));
    EXPECT_GE(static_cast<double>(c.rows.size()), 0.95 * static_cast<double>(expected) - static_cast<double>(r.run.cycle_drops / k))
        << topic << " over the network: " << c.rows.size() << " of " << expected;
    EXPECT_LE(c.rows.size(), expected) << topic;
  }
  {
    const Csv js = read_csv(dir + "/early.joint_state.csv");
    ASSERT_TRUE(js.col.count("alpha_" + std::to_string(J))) << "N−1 joint columns, 1-based";
    EXPECT_FALSE(js.col.count("alpha_" + std::to_string(J + 1))) << "no more than N−1 joint columns";
    EXPECT_FALSE(js.col.count("alpha_0")) << "joint columns are 1-based";
  }
  // Late monitor process: description and the mode events from before it started.
  const Csv desc = read_csv(dir + "/late.robot_description.csv");
  ASSERT_EQ(desc.rows.size(), 1u) << "late monitor: description (log: " << dir << "/late.log)";
  EXPECT_EQ(std::stoi(desc.at(0, "links")), cfg.robot.N);
  EXPECT_DOUBLE_EQ(std::stod(desc.at(0, "link_length")), 2.0 * cfg.robot.l);
  const Csv modes = read_csv(dir + "/late.mode_event.csv");
  EXPECT_EQ(count_rows_with(modes, "to_name", "running"), 1u) << "READY → RUNNING was before it joined";
  EXPECT_EQ(count_rows_with(modes, "to_name", "safe_stop"), 1u);
  ASSERT_FALSE(modes.rows.empty());
  EXPECT_EQ(modes.at(modes.rows.size() - 1, "to_name"), "safe_stop");
  const Csv late_js = read_csv(dir + "/late.joint_state.csv");
  ASSERT_FALSE(late_js.rows.empty());
  EXPECT_GT(std::stoull(late_js.at(0, "seq")), 0u);
  std::filesystem::remove_all(dir);
}

// An operator's emergency stop from another process: pedalwave_monitor --command estop, as a
// person at another terminal would send it. The runtime stops with reason emergency stop.
TEST(DdsEndToEnd, EmergencyStopFromTheMonitorStopsTheRuntime) {
  if (!have_monitor()) GTEST_SKIP() << "*** pedalwave_monitor not built (tools off): cannot send the command from it ***";
  // A cap far beyond what the test needs (≥ 120 s): only the e-stop ends this run early.
  config::DaemonConfig cfg = demo_config(120'000);
  const std::string dir = temp_dir("estop");
  telemetry::TelemetrySubscriber sub(subscriber_config());
  Collector seen;
  sub.add_listener(seen);
  DaemonThread daemon(cfg);
  ASSERT_TRUE(poll_until(sub, [&] { return daemon.done() || (seen.saw_mode(runtime::Mode::kRunning) && seen.joint.size() >= 20); }));
  ASSERT_FALSE(daemon.done());
  const std::uint64_t seq_before = seen.joint.back().seq;
  MonitorProcess mon({"--command", "estop", "--record", dir + "/op.csv"}, dir + "/op.log");
  ASSERT_TRUE(poll_until(sub, [&] { return daemon.done(); })) << "the e-stop did not stop the runtime";
  const app::DaemonResult& r = daemon.join();
  drain(sub);
  EXPECT_EQ(mon.stop(), 0);

  EXPECT_EQ(r.run.reason, runtime::ExitReason::kEmergencyStop);
  EXPECT_EQ(r.run.final_mode, runtime::Mode::kSafeStop);
  EXPECT_GT(r.run.cycles, seq_before);
  EXPECT_LT(r.run.cycles, 120'000u);
  ASSERT_FALSE(seen.modes.empty());
  EXPECT_EQ(seen.modes.back().to_name, "safe_stop");
  EXPECT_EQ(seen.modes.back().from_name, "running");
  EXPECT_NE(seen.modes.back().text.find("emergency stop"), std::string::npos) << seen.modes.back().text;
  // The monitor saw its command queued, then executed (its recording of command_ack), and
  // exited 0 on its own (mon.stop() above only reaps it).
  const Csv ack = read_csv(dir + "/op.command_ack.csv");
  ASSERT_EQ(ack.rows.size(), 2u) << "log: " << dir << "/op.log";
  EXPECT_EQ(ack.at(0, "kind_name"), "emergency_stop");
  EXPECT_EQ(ack.at(0, "status"), "queued");
  EXPECT_EQ(ack.at(1, "status"), "executed") << ack.at(1, "reason");
  EXPECT_EQ(ack.at(1, "robot"), "demo");
  std::filesystem::remove_all(dir);
}

// The same wiring as the daemon (sim driver, gait controller, DDS sink, consumer) with a driver in
// between that records the calls: an e-stop from a second DDS participant reaches the driver as
// its LAST call, and the simulated modules are then torque-off.
namespace {
class SpyDriver final : public drivers::Driver {
 public:
  explicit SpyDriver(drivers::Driver& inner) : inner_(inner) {}
  int joints() const override { return inner_.joints(); }
  drivers::IoStatus read(std::int64_t now, std::int64_t deadline, drivers::Feedback& out) override {
    ++reads;
    if (safe_stops > 0) ++calls_after_safe_stop;
    return inner_.read(now, deadline, out);
  }
  drivers::IoStatus write(const drivers::Command& cmd) override {
    ++writes;
    if (safe_stops > 0) ++calls_after_safe_stop;
    return inner_.write(cmd);
  }
  void safe_stop() override {
    ++safe_stops;
    inner_.safe_stop();
  }
  const drivers::DriverCounters& counters() const override { return inner_.counters(); }
  std::atomic<std::uint64_t> reads{0}, writes{0}, safe_stops{0}, calls_after_safe_stop{0};

 private:
  drivers::Driver& inner_;
};
}  // namespace

TEST(DdsEndToEnd, EmergencyStopOverDdsReachesTheDriverLast) {
  const config::DaemonConfig cfg = demo_config(120'000);
  drivers::SimDriver sim(cfg.driver.scene, cfg.driver.sim);
  SpyDriver spy(sim);
  app::GaitStage stage(cfg.controller);
  auto rt = std::make_unique<runtime::Runtime>(cfg.runtime, spy, stage, nullptr);
  telemetry::TelemetryConfig tc;
  tc.domain_id = cfg.telemetry.domain_id;
  tc.interface = cfg.telemetry.interface;
  tc.robot_name = cfg.name;
  tc.decimation = {cfg.telemetry.decimation_state, cfg.telemetry.decimation_state,
                   cfg.telemetry.decimation_state, cfg.telemetry.decimation_timing};
  tc.enable_commands = false;  // an e-stop is honoured even with commands disabled
  runtime::Runtime* rtp = rt.get();
  telemetry::DdsTelemetry dds(tc, [rtp](const runtime::OperatorCommand& c) { return rtp->post(c); });
  runtime::TelemetryConsumer consumer(*rt, {&dds}, {.poll_period = 0.002, .log_file = "/dev/null"});
  consumer.start();
  runtime::RunResult result;
  std::atomic<bool> done{false};
  std::thread loop([&] {
    result = rt->run();
    done.store(true);
  });

  // A second participant (what the monitor is): waits for the robot to be RUNNING, then sends.
  telemetry::TelemetrySubscriber op(subscriber_config("operator"));
  Collector seen;
  op.add_listener(seen);
  const bool running = poll_until(op, [&] { return done.load() || seen.saw_mode(runtime::Mode::kRunning); });
  const bool matched = op.wait_for_robot(kPatience);
  runtime::OperatorCommand estop;
  estop.kind = runtime::OperatorCommandKind::kEmergencyStop;
  estop.id = 4242;
  estop.amplitude = std::nan("");  // garbage in the gait fields must not matter for an e-stop
  bool sent = false;
  if (running && matched && !done.load()) sent = op.send_command(estop);
  if (!sent) rt->request_stop();  // never leave the loop running on a failed precondition
  poll_until(op, [&] { return done.load(); });
  loop.join();
  consumer.stop(&result);
  drain(op);

  ASSERT_TRUE(running) << "robot never reported RUNNING";
  ASSERT_TRUE(matched) << "robot's command reader never matched";
  ASSERT_TRUE(sent);
  EXPECT_EQ(result.reason, runtime::ExitReason::kEmergencyStop);
  EXPECT_EQ(result.final_mode, runtime::Mode::kSafeStop);
  // The acks: queued although commands are disabled, then executed by the loop.
  ASSERT_EQ(seen.acks.size(), 2u);
  EXPECT_EQ(seen.acks[0].id, 4242u);
  EXPECT_EQ(seen.acks[0].status, telemetry::AckStatus::kQueued) << seen.acks[0].reason;
  EXPECT_EQ(seen.acks[1].id, 4242u);
  EXPECT_EQ(seen.acks[1].status, telemetry::AckStatus::kExecuted) << seen.acks[1].reason;
  // The safe stop reached the driver, once, as its last call.
  EXPECT_EQ(spy.safe_stops.load(), 1u);
  EXPECT_EQ(spy.calls_after_safe_stop.load(), 0u);
  EXPECT_GT(spy.writes.load(), 0u);
  // ...and the simulated modules are torque-off: every joint reports it.
  drivers::Feedback fb{};
  sim.read(runtime::monotonic_ns(), runtime::monotonic_ns(), fb);
  ASSERT_EQ(fb.joints, cfg.robot.N - 1);
  for (int j = 0; j < fb.joints; ++j)
    EXPECT_NE(fb.status[static_cast<std::size_t>(j)] & drivers::kStatusTorqueOff, 0) << "joint " << j;
  // The bus saw the stop too: RUNNING → SAFE_STOP, last, with the reason.
  ASSERT_FALSE(seen.modes.empty());
  EXPECT_EQ(seen.modes.back().to_name, "safe_stop");
  EXPECT_NE(seen.modes.back().text.find("emergency stop"), std::string::npos);
}
