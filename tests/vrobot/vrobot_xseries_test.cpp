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

#include <cmath>
#include <cstdio>
#include <string>

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
                "realtime: {clock: %s, read_budget: 0.8, stale_timeout: 0.2}\n"
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

}  // namespace

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
  test::WalkSetup s{.transport = test::Transport::kSerial, .rate_hz = rate, .duration = duration};
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
