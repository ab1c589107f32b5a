// The runtime walking a robot of stock DYNAMIXEL X-series servos (current control) plus springs
// and a deflection sensor per joint (drivers/PROTOCOL.md §3.6): the serial driver's X-series mode
// against the virtual robot's X-series bus over a pty, in real time.
//
// The onboard observer is OFF here, and that is a finding, not a choice: the servo's Present
// Position has 4096 counts per revolution (1.53e-3 rad), three times the observer's encoder
// consistency threshold (5e-4 rad), and with it on the check names encoder_noise within 0.3 s of
// the start and freezes the gait (PROTOCOL.md §3.6). The timing the driver hands out
// (FeedbackTiming::kModule from host-side times) is what the observer integrates over; its
// thresholds are the pedalwave modules' (1e-4 rad, 1e-3 rad/s).
// The controller places the PD on the host (a stock servo runs none) at 500 Hz with K_p = 20,
// K_D = 1.0, as config/runtime/xseries.yaml; the same controller against the in-process simulated
// plant (lockstep) gives the reference speed.
#include <gtest/gtest.h>
#include <poll.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <regex>
#include <string>
#include <vector>

#include "pedalwave/drivers/xseries_driver.hpp"
#include "walk_rig.hpp"

using namespace pedalwave;

namespace {

const model::Scene& scene() {
  static const model::Scene s = config::load_scene(test::kScenePath);
  return s;
}

config::DaemonConfig xseries_config(const std::string& driver, double rate, double duration,
                                    bool lockstep, bool observer) {
  char yaml[1024];
  std::snprintf(yaml, sizeof yaml,
                "name: vrobot-xseries\nrate_hz: %g\nduration: %g\nrobot: {N: %d}\ndriver: %s\n"
                "controller: {k_c: 0, pd_placement: host, K_p: 20, K_D: 1.0}\n"
                "realtime: {clock: %s, read_budget: 0.8}\n"
                "observer: {enabled: %s}\ntelemetry: {enabled: false}\n",
                rate, duration, scene().robot.N, driver.c_str(), lockstep ? "lockstep" : "realtime",
                observer ? "true" : "false");
  config::DaemonConfig c =
      config::parse_daemon_config(yaml, "vrobot-xseries.yaml", PEDALWAVE_CONFIG_DIR "/runtime");
  c.controller.gait.A_p = scene().gait.A_p;
  c.controller.gait.omega = scene().gait.omega;
  c.controller.admittance.Pi_n = {scene().gait.eta};
  return c;
}

// pedalwave_virtual_robot as a child process, its stdout+stderr on a pipe.
class Tool {
 public:
  explicit Tool(std::vector<std::string> args) {
    args.insert(args.begin(), PEDALWAVE_VROBOT_EXE);
    int p[2];
    if (::pipe2(p, O_CLOEXEC) != 0) return;
    std::vector<char*> argv;
    for (auto& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const pid_t parent = ::getpid();
    pid_ = ::fork();
    if (pid_ == 0) {
      if (::prctl(PR_SET_PDEATHSIG, SIGKILL) != 0 || ::getppid() != parent) ::_exit(126);
      ::dup2(p[1], STDOUT_FILENO);
      ::dup2(p[1], STDERR_FILENO);
      ::execv(argv[0], argv.data());
      ::_exit(127);
    }
    ::close(p[1]);
    out_ = p[0];
  }
  ~Tool() {
    if (pid_ > 0) {
      ::kill(pid_, SIGKILL);
      ::waitpid(pid_, nullptr, 0);
    }
    if (out_ >= 0) ::close(out_);
  }
  bool read_until(const std::string& needle, double timeout_s) {
    const std::int64_t end = test::mono_ns() + static_cast<std::int64_t>(timeout_s * 1e9);
    while (text.find(needle) == std::string::npos) {
      const std::int64_t left_ms = (end - test::mono_ns()) / 1'000'000;
      if (left_ms <= 0) return false;
      pollfd pf{out_, POLLIN, 0};
      if (::poll(&pf, 1, static_cast<int>(left_ms)) <= 0) continue;
      char buf[4096];
      const ssize_t n = ::read(out_, buf, sizeof buf);
      if (n <= 0) return text.find(needle) != std::string::npos;
      text.append(buf, static_cast<std::size_t>(n));
    }
    return true;
  }
  int wait() {
    read_until("\x01never\x01", 60.0);
    int st = 0;
    ::waitpid(pid_, &st, 0);
    pid_ = -1;
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  }
  void signal(int s) { ::kill(pid_, s); }
  std::string text;

 private:
  pid_t pid_ = -1;
  int out_ = -1;
};

}  // namespace

// The tool's bus option: `--pty --devices x_series` serves stock servos + sensors; the driver's
// real open() (configuration: identify, current control, Bus Watchdog) and the daemon run on it.
TEST(XSeriesCli, VirtualRobotServesTheXSeriesBusOnAPty) {
  Tool tool({"--scene", test::kScenePath, "--pty", "--devices", "x_series"});
  ASSERT_TRUE(tool.read_until("waiting for the host", 30.0)) << tool.text;
  EXPECT_NE(tool.text.find("x-series: servos XM430-W350 at IDs 1 … 5"), std::string::npos) << tool.text;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(tool.text, m, std::regex("pty: (/dev/pts/[0-9]+)"))) << tool.text;
  config::DaemonConfig cfg = xseries_config(
      "{type: serial, devices: x_series, device: /dev/null, baud: 4000000, return_delay: 2.0e-5}",
      500, 2, false, false);
  cfg.driver.serial.device = m[1];
  auto drv = drivers::SerialDriver::open(cfg.driver.serial);
  ASSERT_NE(drv->x_series(), nullptr);
  EXPECT_EQ(drv->x_series()->identity(4).sensor_model, drivers::dxl::x::kSensorModelNumber);
  const app::DaemonResult r = app::run_daemon(cfg, test::quiet(drv.get()));
  EXPECT_EQ(r.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(r.run.fault, runtime::FaultClass::kNone) << runtime::to_string(r.run.fault);
  EXPECT_EQ(r.run.cycles, 1000u);
  {
    const drivers::DriverCounters& c = drv->counters();
    std::printf("[vrobot] x-series cli: host rx %llu, missing %llu, late %llu, malformed %llu, "
                "tx_dropped %llu, longest silence %.1f ms\n",
                static_cast<unsigned long long>(c.frames_rx), static_cast<unsigned long long>(c.missing),
                static_cast<unsigned long long>(c.late), static_cast<unsigned long long>(c.malformed),
                static_cast<unsigned long long>(c.tx_dropped), c.rx_silence_max_ns * 1e-6);
  }
  drv.reset();
  tool.signal(SIGINT);
  EXPECT_EQ(tool.wait(), 0) << tool.text;
  EXPECT_NE(tool.text.find("SYNCs 1000,"), std::string::npos) << "a Bulk Read per cycle: " << tool.text;
  EXPECT_NE(tool.text.find("replies sent 10000,"), std::string::npos) << "servo + sensor per joint: " << tool.text;

  Tool bad({"--scene", test::kScenePath, "--can", "vcan0", "--devices", "x_series"});
  EXPECT_EQ(bad.wait(), 2);
  EXPECT_NE(bad.text.find("--devices x_series is a serial bus: give --pty"), std::string::npos) << bad.text;
}

TEST(XSeriesWalk, StockServosWalkWithTheHostPd) {
  const double rate = 500, duration = 8;
  const auto cycles = static_cast<std::uint64_t>(rate * duration);
  // Reference: the same host-PD controller on the in-process plant.
  const config::DaemonConfig sim_cfg = xseries_config(
      "{type: sim, scene: ../scenes/flat_high_friction.yaml, clock: lockstep}", rate, duration, true,
      false);
  const app::DaemonResult sim = app::run_daemon(sim_cfg, test::quiet());
  ASSERT_EQ(sim.run.fault, runtime::FaultClass::kNone) << runtime::to_string(sim.run.fault);

  const config::DaemonConfig cfg = xseries_config(
      "{type: serial, devices: x_series, device: /dev/null, baud: 4000000, return_delay: 2.0e-5}",
      rate, duration, false, false);
  ASSERT_EQ(cfg.driver.serial.devices, drivers::SerialDevices::kXSeries);
  // The servos answer on their own (real servos never wait for the host's CPU): the emulating
  // thread runs SCHED_FIFO, as the tool's does. Without it, at load 6.5 on this 2-core machine,
  // half the samples came late and the host PD — closed over the bus — walked at −155 % and
  // −16 % of the reference (the pedalwave modules' PD runs in the modules and does not care).
  test::WalkSetup s{.transport = test::Transport::kSerial, .rate_hz = rate, .duration = duration,
                    .robot_priority = 70};
  vrobot::VirtualRobotOptions vo = test::robot_options(s, scene(), {});
  vo.emulator.serial_devices = drivers::SerialDevices::kXSeries;
  vo.emulator.bus.baud = cfg.driver.serial.baud;
  vo.emulator.bus.return_delay_s = cfg.driver.serial.return_delay_s;
  vrobot::Pty pty = vrobot::open_pty();
  vrobot::VirtualRobot robot(scene(), pty.master, vo);
  drivers::SerialDriver drv(drivers::open_serial_port(pty.slave_path, cfg.driver.serial.baud),
                            cfg.driver.serial);
  robot.start();
  drv.configure_modules();  // identify, current control, return delay: what open() does
  for (int j = 0; j < drv.joints(); ++j) {
    EXPECT_EQ(drv.x_series()->identity(j).model, drivers::dxl::x::kModelXM430W350);
    EXPECT_EQ(drv.x_series()->identity(j).operating_mode, 3) << "shipped in position control";
  }
  const test::WalkResult r = test::run_walk(cfg, robot, drv);
  std::printf("[vrobot] %s\n", r.robot_thread.c_str());
  ::close(pty.slave_keep);
  const drivers::DriverCounters& c = r.counters;
  std::printf("[vrobot] x-series 500 Hz: speed %.4f cm/s (sim, same controller: %.4f cm/s, %+.2f %%), "
              "cycles %llu, overruns %llu, exit %s, fault %s (joint %d), missing %llu, late %llu\n%s",
              100 * r.speed, 100 * sim.forward_speed,
              100 * (r.speed - sim.forward_speed) / sim.forward_speed,
              static_cast<unsigned long long>(r.daemon.run.cycles),
              static_cast<unsigned long long>(r.daemon.run.overruns),
              runtime::to_string(r.daemon.run.reason), runtime::to_string(r.daemon.run.fault),
              r.daemon.run.fault_joint + 1, static_cast<unsigned long long>(c.missing),
              static_cast<unsigned long long>(c.late), r.report.c_str());
  EXPECT_EQ(r.daemon.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(r.daemon.run.fault, runtime::FaultClass::kNone) << runtime::to_string(r.daemon.run.fault);
  EXPECT_EQ(r.daemon.run.cycles, cycles);
  EXPECT_EQ(r.daemon.run.final_mode, runtime::Mode::kSafeStop);
  EXPECT_EQ(c.checksum + c.malformed + c.bus_errors, 0u);
  EXPECT_EQ(r.emu.rx_errors, 0u);
  EXPECT_LT(c.missing, 5 * cycles * 15 / 100) << "missing " << c.missing;
  EXPECT_TRUE(r.all_modules_off) << "safe stop: Torque Enable 0 reached every servo";
  EXPECT_EQ(r.emu.lifetime_expired, 0u) << "the servos' Bus Watchdog (0.5 s) never expired";
  EXPECT_TRUE(r.plant.all_off);
  EXPECT_FALSE(r.plant.failed);
  ASSERT_TRUE(std::isfinite(r.speed));
  EXPECT_GT(sim.forward_speed, 0.0);
  EXPECT_NEAR(r.speed, sim.forward_speed, 0.15 * sim.forward_speed);
}
