// pedalwave_runtime's command line end to end (issue 15): bad input exits 2 with one line naming
// the option or the file and what was expected; --check checks the devices, interfaces and
// folders without moving the robot; SIGHUP and SIGQUIT end the run in the same safe stop (and
// summary) as SIGTERM. The built executable is run as a child process.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "dds_domain_lease.hpp"

namespace {

namespace fs = std::filesystem;
const std::string kExe = PEDALWAVE_RUNTIME_EXE;
const std::string kConfigs = std::string(PEDALWAVE_CONFIG_DIR) + "/runtime/";

std::string slurp(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

class RuntimeCli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("pedalwave_runtime_cli_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(dir_);
  }
  // Starts the daemon with `args` (stdout/stderr into files); returns its pid.
  pid_t start(const std::string& args) {
    const std::string cmd = "exec '" + kExe + "' " + args + " >'" + (dir_ / "out").string() + "' 2>'" +
                            (dir_ / "err").string() + "'";
    const pid_t pid = ::fork();
    if (pid == 0) {
      ::execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
      ::_exit(127);
    }
    return pid;
  }
  // Waits for the child; returns its exit status (-signal when killed by one).
  static int wait_for(pid_t pid) {
    int status = 0;
    ::waitpid(pid, &status, 0);
    return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
  }
  int run(const std::string& args) { return wait_for(start(args)); }
  std::string out() const { return slurp(dir_ / "out"); }
  std::string err() const { return slurp(dir_ / "err"); }
  std::string write(const std::string& name, const std::string& text) const {
    const fs::path p = dir_ / name;
    std::ofstream(p) << text;
    return p.string();
  }
  // A scene: the shipped flat_high_friction.yaml with its `key:` lines replaced, e.g.
  // {{"integrator", "{method: rk4, h: 0.05}"}}.
  std::string flat_scene(const std::string& name,
                         const std::vector<std::pair<std::string, std::string>>& lines) const {
    std::string text = slurp(fs::path(PEDALWAVE_CONFIG_DIR) / "scenes" / "flat_high_friction.yaml");
    for (const auto& [key, value] : lines) {
      const std::size_t at = text.find("\n" + key + ":");
      EXPECT_NE(at, std::string::npos) << key;
      if (at == std::string::npos) continue;
      text.replace(at + 1, text.find('\n', at + 1) - at - 1, key + ": " + value);
    }
    return write(name, text);
  }
  // A daemon configuration on the simulated plant (lockstep clocks, no telemetry) with `extra`
  // lines appended.
  std::string sim_config(const std::string& name, const std::string& scene, const std::string& extra = "") const {
    return write(name, "name: " + name + "\nrate_hz: 1000\n"
                       "driver: {type: sim, scene: '" + scene + "', clock: lockstep}\n"
                       "controller: {k_c: 0, pd_placement: module}\n"
                       "realtime: {clock: lockstep, auto_start: true}\n"
                       "observer: {enabled: true}\ntelemetry: {enabled: false}\n" + extra);
  }
  fs::path dir_;
};

int lines(const std::string& s) { return static_cast<int>(std::count(s.begin(), s.end(), '\n')); }

}  // namespace

TEST_F(RuntimeCli, BadDurationsExit2WithOneLine) {
  const std::string c = "-c '" + kConfigs + "sim_lockstep.yaml' --no-telemetry --duration ";
  for (const char* d : {"-1", "nan", "inf", "1e308"}) {
    SCOPED_TRACE(d);
    EXPECT_EQ(run(c + d), 2);
    EXPECT_EQ(err().rfind(std::string("pedalwave_runtime: error: --duration "), 0), 0u) << err();
    EXPECT_NE(err().find(": expected a run time in [0, 1e+07] s (0 = until a signal)"), std::string::npos) << err();
    EXPECT_EQ(lines(err()), 1) << err();
  }
  for (const char* d : {"0.0004", "0.0007"}) {  // the file's rule: at least one period
    SCOPED_TRACE(d);
    EXPECT_EQ(run(c + d), 2);
    EXPECT_EQ(err(), "pedalwave_runtime: error: --duration " + std::string(d) +
                         ": expected 0 (until a signal) or at least one control period 1/rate_hz = 0.001 s\n");
  }
}

TEST_F(RuntimeCli, CommandLineErrorsExit2NotCli11Codes) {
  EXPECT_EQ(run("--no-such-option -c x.yaml"), 2);
  EXPECT_NE(err().find("pedalwave_runtime: error: "), std::string::npos) << err();
  EXPECT_NE(err().find("--no-such-option"), std::string::npos) << err();
  EXPECT_EQ(lines(err()), 1) << err();
  EXPECT_EQ(run("--duration"), 2);
  EXPECT_EQ(lines(err()), 1) << err();
  EXPECT_EQ(run("--help"), 0);
}

TEST_F(RuntimeCli, ConfigThatIsADeviceIsRefusedAtOnce) {
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(run("-c /dev/zero --check"), 2);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
  EXPECT_EQ(err(), "pedalwave_runtime: error: /dev/zero: is not a regular file (a device, a pipe or a socket): "
                   "expected a YAML file\n");
  EXPECT_EQ(run("-c '" + dir_.string() + "' --check"), 2);
  EXPECT_EQ(err(), "pedalwave_runtime: error: " + dir_.string() + ": is a directory: expected a YAML file\n");
}

TEST_F(RuntimeCli, CheckLooksAtDevicesInterfacesAndFolders) {
  const std::string serial = write("serial.yaml",
                                   "rate_hz: 250\ndriver: {type: serial, device: /dev/ttyUSB9, baud: 1000000}\n"
                                   "telemetry: {enabled: true, interface: eth99}\n");
  EXPECT_EQ(run("-c '" + serial + "' --check"), 2);
  EXPECT_NE(out().find("FAIL  serial device /dev/ttyUSB9 exists and opens: No such file or directory"),
            std::string::npos) << out();
  EXPECT_NE(out().find("FAIL  DDS network interface eth99 exists: no such network interface"), std::string::npos)
      << out();
  EXPECT_EQ(err(), "pedalwave_runtime: error: " + serial + ": --check failed (the FAIL lines above)\n");
  // A character device that opens (nothing is written to it).
  const std::string null_dev = write("null.yaml", "rate_hz: 250\ndriver: {type: serial, device: /dev/null, baud: 1000000}\n"
                                                  "telemetry: {enabled: true, interface: lo}\n");
  EXPECT_EQ(run("-c '" + null_dev + "' --check"), 0) << out() << err();
  EXPECT_NE(out().find("ok    serial device /dev/null exists and opens"), std::string::npos) << out();
  EXPECT_NE(out().find("ok    DDS network interface lo exists"), std::string::npos) << out();

  const std::string can = write("can.yaml", "rate_hz: 250\ndriver: {type: socketcan, ifname: can9, fd: true}\n"
                                            "telemetry: {enabled: false}\n");
  EXPECT_EQ(run("-c '" + can + "' --check"), 2);
  EXPECT_NE(out().find("FAIL  CAN interface can9 exists: no such network interface"), std::string::npos) << out();
  // --check-config: the file alone (a packaging machine without the bus).
  EXPECT_EQ(run("-c '" + can + "' --check-config"), 0) << err();
  EXPECT_EQ(out().find("FAIL"), std::string::npos) << out();

  const std::string sim = "-c '" + kConfigs + "sim_lockstep.yaml' --no-telemetry";
  EXPECT_EQ(run(sim + " --check --plots /proc/forbidden"), 2);
  EXPECT_NE(out().find("FAIL  --plots /proc/forbidden is a writable folder: cannot create the folder"),
            std::string::npos) << out();
  EXPECT_EQ(run(sim + " --check --plots '" + (dir_ / "plots").string() + "'"), 0) << out();
  EXPECT_TRUE(fs::is_directory(dir_ / "plots"));
}

// Without --check too, an unwritable plots folder is refused before the run, not after it.
// realtime.cpu is the robot's: the file alone passes on any machine (--check-config on a packaging
// machine), --check says whether this machine has the CPU, and a run refuses to start without it
// (exit 2, before the driver opens), never pinning the loop nowhere.
TEST_F(RuntimeCli, ACpuThisMachineDoesNotHaveIsCheckedHereNotInTheFile) {
  const long n = ::sysconf(_SC_NPROCESSORS_ONLN);
  const std::string flat = (fs::path(PEDALWAVE_CONFIG_DIR) / "scenes" / "flat_high_friction.yaml").string();
  const std::string far = sim_config("far.yaml", flat, "duration: 1\n");
  std::string text = slurp(far);
  text.replace(text.find("realtime: {"), 11, "realtime: {cpu: 1023, ");
  std::ofstream(far) << text;
  EXPECT_EQ(run("-c '" + far + "' --check-config"), 0) << err();
  EXPECT_EQ(run("-c '" + far + "' --check"), 2) << out();
  EXPECT_NE(out().find("FAIL  CPU 1023 exists (this machine has " + std::to_string(n) + " online CPUs): "),
            std::string::npos) << out();
  EXPECT_EQ(run("-c '" + far + "'"), 2) << out();
  EXPECT_EQ(err(), "pedalwave_runtime: error: " + far + ": realtime.cpu = 1023: expected -1 (no pinning) or a CPU of "
                   "this machine, 0 … " + std::to_string(n - 1) + " (it has " + std::to_string(n) +
                   " online CPUs)\n");
  const std::string here = sim_config("here.yaml", flat, "duration: 0.01\n");
  text = slurp(here);
  text.replace(text.find("realtime: {"), 11, "realtime: {cpu: 0, ");
  std::ofstream(here) << text;
  EXPECT_EQ(run("-c '" + here + "' --check"), 0) << out() << err();
  EXPECT_NE(out().find("ok    CPU 0 exists (this machine has " + std::to_string(n) + " online CPUs)"),
            std::string::npos) << out();
}

TEST_F(RuntimeCli, UnwritablePlotsFolderFailsAtStart) {
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(run("-c '" + kConfigs + "sim_lockstep.yaml' --no-telemetry --duration 60 --plots /proc/forbidden"), 2);
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(10)) << "refused before the 60 s run";
  EXPECT_EQ(err().rfind("pedalwave_runtime: error: --plots /proc/forbidden: cannot create the folder", 0), 0u) << err();
  EXPECT_EQ(lines(err()), 1) << err();
}

// SIGHUP and SIGQUIT end the run like SIGTERM: safe stop, the summary's exit line, exit 0.
TEST_F(RuntimeCli, HangupAndQuitEndInTheSafeStop) {
  for (int sig : {SIGTERM, SIGHUP, SIGQUIT}) {
    SCOPED_TRACE(sig);
    const pid_t pid = start("-c '" + kConfigs + "sim_lockstep.yaml' --no-telemetry --duration 0");
    // Until the start report says it runs (at most 20 s on a loaded machine).
    for (int i = 0; i < 200 && out().find("pedalwave") == std::string::npos; ++i)
      std::this_thread::sleep_for(std::chrono::milliseconds(100));
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    ASSERT_EQ(::kill(pid, sig), 0);
    EXPECT_EQ(wait_for(pid), 0) << out() << err();
    EXPECT_NE(out().find("exit: signal, final mode SAFE_STOP, signal " + std::to_string(sig)), std::string::npos)
        << out();
    // The event log names the signal that came (not "SIGINT/SIGTERM" for a SIGHUP).
    const std::string name = sig == SIGTERM ? "SIGTERM" : sig == SIGHUP ? "SIGHUP" : "SIGQUIT";
    EXPECT_NE(err().find("mode RUNNING → SAFE_STOP: stop signal " + name + " → safe stop"), std::string::npos) << err();
    EXPECT_EQ(err().find("SIGINT/SIGTERM"), std::string::npos) << err();
  }
}

// Issue 15: a log_file in a folder that cannot be written is a FAIL line of --check and refused
// at the start of a run (exit 2, one line), not found by the logger after the driver is up.
TEST_F(RuntimeCli, LogFileThatCannotBeWrittenIsRefusedBeforeTheRun) {
  const std::string flat = std::string(PEDALWAVE_CONFIG_DIR) + "/scenes/flat_high_friction.yaml";
  const std::string bad = sim_config("bad_log.yaml", flat, "log_file: /proc/forbidden/events.log\n");
  EXPECT_EQ(run("-c '" + bad + "' --check"), 2) << out() << err();
  EXPECT_NE(out().find("FAIL  log_file /proc/forbidden/events.log can be written: cannot create the folder"),
            std::string::npos) << out();
  EXPECT_EQ(out().find("configuration valid"), std::string::npos) << out();
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_EQ(run("-c '" + bad + "' --duration 60"), 2) << out() << err();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(10)) << "refused before the 60 s run";
  EXPECT_EQ(err().rfind("pedalwave_runtime: error: " + bad +
                            ": log_file = \"/proc/forbidden/events.log\": cannot create the folder",
                        0),
            0u) << err();
  EXPECT_NE(err().find("expected a file that can be written"), std::string::npos) << err();
  EXPECT_EQ(lines(err()), 1) << err();
  EXPECT_EQ(out().find("pedalwave runtime '"), std::string::npos) << "nothing started\n" << out();
  // A writable one passes (its folder is created, as the logger would).
  const std::string log = (dir_ / "logs" / "events.log").string();
  const std::string good = sim_config("good_log.yaml", flat, "log_file: '" + log + "'\n");
  EXPECT_EQ(run("-c '" + good + "' --check"), 0) << out() << err();
  EXPECT_NE(out().find("ok    log_file " + log + " can be written"), std::string::npos) << out();
}

// Issue 15: the simulated plant's integrator step must fit the control period (pedalwave_sim's
// rule): rk4 with h = 0.05 at 1 kHz is refused as the configuration, naming the scene's key and
// the period, in every mode — not run into a blow-up that looks like a robot fault (exit 4).
TEST_F(RuntimeCli, SceneStepLongerThanTheControlPeriodIsRefused) {
  const std::string scene = flat_scene("coarse.yaml", {{"integrator", "{method: rk4, h: 0.05}"}});
  const std::string cfg = sim_config("coarse_cfg.yaml", scene);
  const std::string message = "pedalwave_runtime: error: " + scene +
                              ": integrator.h = 0.05: expected a step ≤ the control period 1/rate_hz = 0.001 s "
                              "(rate_hz 1000 in " + cfg + ")\n";
  for (const char* mode : {"--check-config", "--check", "--duration 2"}) {
    SCOPED_TRACE(mode);
    EXPECT_EQ(run("-c '" + cfg + "' " + mode), 2) << out() << err();
    EXPECT_EQ(err(), message);
  }
}

// Issue 15: when the simulated plant itself goes numerically wrong (its state overflows: NaN, a
// mass matrix that is no longer positive definite), the run ends as a simulation that went wrong
// — exit 3, the stability limit and a step that works, no speed — not as a robot fault (exit 4).
// RK4 at 1e-4 s against a ground damping of 1e5 N·s/m is ~150 times above its limit: the plant
// overflows within the first periods.
TEST_F(RuntimeCli, PlantThatGoesNumericallyWrongExits3WithTheStabilityAdvice) {
  const std::string scene =
      flat_scene("unstable.yaml", {{"ground", "{k: 350, d: 1.0e5, mu: 0.82, friction: regularized, v_s: 1.0e-3}"},
                                   {"integrator", "{method: rk4, h: 1.0e-4}"}});
  const std::string cfg = sim_config("unstable_cfg.yaml", scene);
  EXPECT_EQ(run("-c '" + cfg + "' --duration 5"), 3) << out() << err();
  EXPECT_NE(err().find("pedalwave_runtime: the simulated plant failed at t = "), std::string::npos) << err();
  EXPECT_NE(err().find("use h ≤"), std::string::npos) << err();
  EXPECT_NE(out().find("plant: "), std::string::npos) << out();
  EXPECT_NE(out().find("stability: "), std::string::npos) << out();
  EXPECT_EQ(out().find("forward speed"), std::string::npos) << out();
}

// Issue 15: explicit Euler at h = 1e-3 s (≈ 2.3× its stability limit, set by the module's damping)
// diverges, and the runtime's "implausible joint" check stops the run while every state is still
// finite: the plant never reports a failed step. The fault is the integrator's (model::check
// predicts the growth: CheckLevel::kError), so the run is numerically wrong — exit 3 with the
// advice, no speed — not a robot fault (exit 4, as before).
TEST_F(RuntimeCli, PlantBeyondItsStabilityLimitExits3EvenBeforeItOverflows) {
  const std::string scene = flat_scene("euler.yaml", {{"integrator", "{method: euler, h: 1.0e-3}"}});
  const std::string cfg = sim_config("euler_cfg.yaml", scene);
  EXPECT_EQ(run("-c '" + cfg + "' --duration 5"), 3) << out() << err();
  EXPECT_NE(err().find("diverging beyond its stability limit"), std::string::npos) << err();
  EXPECT_NE(err().find("use h ≤"), std::string::npos) << err();
  EXPECT_EQ(out().find("forward speed"), std::string::npos) << out();
  EXPECT_NE(out().find("fault implausible"), std::string::npos) << "the runtime's own verdict stays in the log\n"
                                                                 << out();
  // The same scene at a stable step is a normal run.
  const std::string fine = flat_scene("euler_fine.yaml", {{"integrator", "{method: euler, h: 1.0e-4}"}});
  EXPECT_EQ(run("-c '" + sim_config("euler_fine_cfg.yaml", fine) + "' --duration 1"), 0) << out() << err();
}

// Issue 15: an operator's emergency stop — pedalwave_monitor --command estop over DDS, as a person
// at another terminal sends it (README: the runtime's exit status table) — ends the daemon with
// its own exit status 5, distinct from a normal end (0) and a fault (4).
TEST_F(RuntimeCli, EmergencyStopFromTheMonitorExitsWithTheEStopStatus) {
#ifndef PEDALWAVE_MONITOR_EXE
  GTEST_SKIP() << "*** pedalwave_monitor not built (telemetry or tools off): cannot send the e-stop ***";
#else
  const std::uint32_t domain = pedalwave::test::dds_domain_id();
  const std::string flat = std::string(PEDALWAVE_CONFIG_DIR) + "/scenes/flat_high_friction.yaml";
  const std::string cfg = write(
      "estop.yaml", "name: estop\nrate_hz: 1000\n"
                    "driver: {type: sim, scene: '" + flat + "', clock: lockstep}\n"
                    "controller: {k_c: 0, pd_placement: module}\n"
                    "realtime: {clock: realtime, priority: 0, cpu: -1, lock_memory: false, auto_start: true}\n"
                    "observer: {enabled: true}\n"
                    "telemetry: {enabled: true, domain_id: 0, interface: lo, commands: true}\n");
  // A cap far beyond what the test needs: only the e-stop ends this run early. --domain beats the
  // file's domain_id (and ROS_DOMAIN_ID), and the start line says so.
  const pid_t pid = start("-c '" + cfg + "' --duration 60 --domain " + std::to_string(domain));
  for (int i = 0; i < 200 && out().find("pedalwave runtime '") == std::string::npos; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  ASSERT_NE(out().find("pedalwave runtime '"), std::string::npos) << out() << err();
  const fs::path mon_log = dir_ / "monitor.log";
  const std::string mon = std::string("'") + PEDALWAVE_MONITOR_EXE + "' --domain " + std::to_string(domain) +
                          " --interface lo --robot estop --no-view --command estop --ack-timeout 30 >'" + mon_log.string() +
                          "' 2>&1";
  const int mon_status = std::system(mon.c_str());
  const auto t0 = std::chrono::steady_clock::now();
  const int status = wait_for(pid);
  // The monitor exits on the final ack: 0 = the robot executed the e-stop.
  EXPECT_TRUE(WIFEXITED(mon_status) && WEXITSTATUS(mon_status) == 0)
      << "monitor status " << mon_status << ":\n" << slurp(mon_log);
  EXPECT_NE(slurp(mon_log).find("estop: command estop id"), std::string::npos) << slurp(mon_log);
  EXPECT_NE(slurp(mon_log).find("executed"), std::string::npos) << slurp(mon_log);
  EXPECT_EQ(status, 5) << "monitor status " << mon_status << ":\n" << slurp(mon_log) << "\n" << out() << err();
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(30)) << "the e-stop ended the run";
  EXPECT_NE(out().find("exit: emergency_stop, final mode SAFE_STOP"), std::string::npos) << out();
  EXPECT_NE(out().find("telemetry DDS domain " + std::to_string(domain) +
                       " (--domain), namespace /estop, discovery on lo (config (interface lo))"),
            std::string::npos) << out();
#endif
}


// Issue 14: the observer's flight recorder on the command line. A run with an injected torque
// loss writes --observer-log; --replay-observer runs the configuration's observer over it: the
// same fault at the same cycle, the residuals bit for bit (exit 4: the replay found a fault), and
// the cycles before it at the faulty joint. A file that is not such a log, or a configuration with
// another robot, is refused naming the file.
TEST_F(RuntimeCli, ObserverLogReplaysTheRunsVerdictBitForBit) {
  const std::string scene =
      flat_scene("torque_loss.yaml", {{"duration", "20\nfaults: [{type: torque_gain, joint: 2, t_start: 3.0, value: 0.3}]"}});
  const std::string cfg = sim_config("torque_loss_cfg.yaml", scene);
  const std::string log = (dir_ / "inputs.csv").string();
  EXPECT_EQ(run("-c '" + cfg + "' --duration 7 --observer-log '" + log + "'"), 0) << out() << err();
  EXPECT_NE(out().find("fault actuator_torque joint 3"), std::string::npos) << out();
  EXPECT_NE(out().find("observer log: " + log + " (7000 of 7000 cycles"), std::string::npos) << out();
  EXPECT_EQ(run("-c '" + cfg + "' --replay-observer '" + log + "'"), 4) << out() << err();
  EXPECT_NE(out().find("live:   actuator_torque joint 3 at t = "), std::string::npos) << out();
  EXPECT_NE(out().find("replay: actuator_torque joint 3 at t = "), std::string::npos) << out();
  EXPECT_NE(out().find("max |replay - live| = 0 N·m; verdicts differ in 0 of 7000 cycles"), std::string::npos) << out();
  EXPECT_NE(out().find("the 40 cycles before it, joint 3"), std::string::npos) << out();
  // The same log, the observer's threshold is the configuration's: a healthy run's log replays clean.
  const std::string clean_log = (dir_ / "clean.csv").string();
  const std::string clean_cfg = sim_config("clean_cfg.yaml", flat_scene("clean.yaml", {}));
  EXPECT_EQ(run("-c '" + clean_cfg + "' --duration 4 --observer-log '" + clean_log + "'"), 0) << out() << err();
  EXPECT_EQ(run("-c '" + clean_cfg + "' --replay-observer '" + clean_log + "'"), 0) << out() << err();
  EXPECT_NE(out().find("live:   no fault\nreplay: no fault\n"), std::string::npos) << out();
  // Bad input: not a log; a robot with other joints; --observer-log without an observer.
  const std::string junk = write("junk.csv", "a,b\n1,2\n");
  EXPECT_EQ(run("-c '" + cfg + "' --replay-observer '" + junk + "'"), 2) << out() << err();
  EXPECT_NE(err().find(junk), std::string::npos) << err();
  const std::string big = write("big_cfg.yaml", "name: big\nrate_hz: 1000\n"
                                                "driver: {type: sim, scene: '" + flat_scene("big.yaml", {{"robot", "{N: 9, joints: flexible}"}}) +
                                                "', clock: lockstep}\nrealtime: {clock: lockstep}\n"
                                                "observer: {enabled: true}\ntelemetry: {enabled: false}\n");
  EXPECT_EQ(run("-c '" + big + "' --replay-observer '" + log + "'"), 2) << out() << err();
  EXPECT_NE(err().find("5 joints, but"), std::string::npos) << err();
  const std::string off = write("off_cfg.yaml", "name: off\nrate_hz: 1000\n"
                                                "driver: {type: sim, scene: '" + scene + "', clock: lockstep}\n"
                                                "realtime: {clock: lockstep}\nobserver: {enabled: false}\n"
                                                "telemetry: {enabled: false}\n");
  EXPECT_EQ(run("-c '" + off + "' --duration 1 --observer-log '" + log + "'"), 2) << out() << err();
  EXPECT_NE(err().find("observer: false"), std::string::npos) << err();
}
