// The runtime walking a robot of CANopen CiA 402 drives (driver.protocol: canopen): the daemon's
// loop with the onboard observer ON, the SocketCAN driver's CANopen master, and the virtual robot's
// CANopen personality (the scene's plant behind emulated drives) over a SOCK_SEQPACKET socket
// pair, in real time. CST: the controller's PD on the host (the drive applies the target torque);
// CSP: the drive's position loop is the module PD (gains 2010h / 2011h set by SDO). The same
// controller against the in-process simulated plant (lockstep) gives the reference speed. A node
// lost mid-walk (heartbeat) and a drive fault (EMCY) stop the runtime on that joint, named.
#include <gtest/gtest.h>
#include <sys/socket.h>

#include <cmath>
#include <cstdio>
#include <string>

#include "pedalwave/drivers/canopen_driver.hpp"
#include "walk_rig.hpp"

using namespace pedalwave;

namespace {

const model::Scene& scene() {
  static const model::Scene s = config::load_scene(test::kScenePath);
  return s;
}

constexpr double kRate = 250;  // 5 nodes: SYNC + RPDOs + 2 TPDOs each fit 1 Mbit/s at 250 Hz (CSP: 64 %)

config::DaemonConfig canopen_config(const std::string& driver, const std::string& controller, double duration,
                                    bool lockstep, const char* realtime_extra = "") {
  char yaml[1024];
  std::snprintf(yaml, sizeof yaml,
                "name: vrobot-canopen\nrate_hz: %g\nduration: %g\nrobot: {N: %d}\ndriver: %s\n"
                "controller: %s\n"
                "realtime: {clock: %s, stale_timeout: 0.2%s}\n"
                "observer: {enabled: true}\ntelemetry: {enabled: false}\n",
                kRate, duration, scene().robot.N, driver.c_str(), controller.c_str(),
                lockstep ? "lockstep" : "realtime", realtime_extra);
  config::DaemonConfig c = config::parse_daemon_config(yaml, "vrobot-canopen.yaml", PEDALWAVE_CONFIG_DIR "/runtime");
  c.controller.gait.A_p = scene().gait.A_p;
  c.controller.gait.omega = scene().gait.omega;
  c.controller.admittance.eta_n = {scene().gait.eta};
  return c;
}

struct CanOpenWalk {
  test::WalkResult r;
  std::string fault_text;
  int fault_joint = -1;
  std::uint64_t syncs_held = 0;  // reads that sent no SYNC: the previous window open
};

CanOpenWalk walk(const config::DaemonConfig& cfg, double duration, const drivers::FaultConfig& faults = {},
                 const drivers::canopen::CanOpenEmulatorConfig& cc = {}) {
  test::WalkSetup s{.transport = test::Transport::kCanClassic, .rate_hz = kRate, .duration = duration,
                    .robot_priority = 70};
  vrobot::VirtualRobotOptions vo = test::robot_options(s, scene(), faults);
  vo.bus = vrobot::Bus::kCanOpen;
  vo.canopen = cc;
  vo.emulator.bus.bitrate = cfg.driver.can.bitrate;
  int sv[2];
  if (::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv) != 0)
    throw std::system_error(errno, std::generic_category(), "socketpair");
  vrobot::VirtualRobot robot(scene(), sv[0], vo);
  robot.start();  // the drives answer the master's bring-up (NMT, SDO) before the loop starts
  drivers::CanOpenDriver drv(sv[1], cfg.driver.can);
  CanOpenWalk w;
  w.r = test::run_walk(cfg, robot, drv);
  w.fault_text = drv.fault_text();
  w.fault_joint = drv.fault_joint();
  w.syncs_held = drv.syncs_held();
  return w;
}

void print(const char* what, const CanOpenWalk& w, double sim_speed) {
  const test::WalkResult& r = w.r;
  std::printf("[vrobot] canopen %s %g Hz: speed %.4f cm/s (sim, same controller: %.4f cm/s, %+.2f %%), cycles %llu, "
              "exit %s, fault %s (joint %d), missing %llu, late %llu, driver fault '%s'\n%s",
              what, kRate, 100 * r.speed, 100 * sim_speed, 100 * (r.speed - sim_speed) / sim_speed,
              static_cast<unsigned long long>(r.daemon.run.cycles), runtime::to_string(r.daemon.run.reason),
              runtime::to_string(r.daemon.run.fault), r.daemon.run.fault_joint,
              static_cast<unsigned long long>(r.counters.missing), static_cast<unsigned long long>(r.counters.late),
              w.fault_text.c_str(), r.report.c_str());
}

void expect_clean_walk(const CanOpenWalk& w, double duration, double sim_speed) {
  const test::WalkResult& r = w.r;
  const auto cycles = static_cast<std::uint64_t>(kRate * duration);
  EXPECT_EQ(r.daemon.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(r.daemon.run.fault, runtime::FaultClass::kNone)
      << runtime::to_string(r.daemon.run.fault) << " joint " << r.daemon.run.fault_joint;
  EXPECT_EQ(r.daemon.run.cycles, cycles);
  EXPECT_EQ(w.fault_joint, -1) << w.fault_text;
  EXPECT_EQ(r.counters.malformed + r.counters.bus_errors, 0u);
  EXPECT_EQ(r.emu.rx_errors, 0u);
  EXPECT_LT(r.counters.missing, 5 * cycles * 5 / 100) << "missing " << r.counters.missing;
  EXPECT_TRUE(r.all_modules_off) << "safe stop: disable operation reached every drive";
  EXPECT_EQ(r.emu.lifetime_expired, 0u);
  EXPECT_FALSE(r.plant.failed);
  ASSERT_TRUE(std::isfinite(r.speed));
  EXPECT_GT(sim_speed, 0.0);
  EXPECT_NEAR(r.speed, sim_speed, 0.15 * sim_speed);
}

const char* kSimDriver = "{type: sim, scene: ../scenes/flat_high_friction.yaml, clock: lockstep}";
// The walks: a consumer time a loaded machine's scheduling does not reach (the emulated drives'
// thread is held now and then); the lost-node walk: shorter than the runtime's stale_timeout
// (0.2 s), so the heartbeat consumer names the node before the runtime stops.
const char* kCstDriver = "{type: socketcan, ifname: vcan0, protocol: canopen, drive_mode: cst, heartbeat: 0.02, "
                         "heartbeat_timeout: 0.5}";
const char* kCspDriver = "{type: socketcan, ifname: vcan0, protocol: canopen, drive_mode: csp, heartbeat: 0.02, "
                         "heartbeat_timeout: 0.5}";
const char* kCstDriverFastHeartbeat = "{type: socketcan, ifname: vcan0, protocol: canopen, drive_mode: cst, "
                                      "heartbeat: 0.02, heartbeat_timeout: 0.06}";
const char* kHostPd = "{k_c: 0, pd_placement: host, K_p: 20, K_D: 0.5}";
const char* kModulePd = "{k_c: 0, pd_placement: module}";

}  // namespace

TEST(CanOpenWalk, CstWithTheHostPdAndTheObserverOn) {
  const double duration = 6;
  const app::DaemonResult sim = app::run_daemon(canopen_config(kSimDriver, kHostPd, duration, true), test::quiet());
  ASSERT_EQ(sim.run.fault, runtime::FaultClass::kNone) << runtime::to_string(sim.run.fault);
  const config::DaemonConfig cfg = canopen_config(kCstDriver, kHostPd, duration, false);
  ASSERT_EQ(cfg.driver.can.protocol, drivers::CanProtocol::kCanOpen);
  ASSERT_TRUE(cfg.observer);
  const CanOpenWalk w = walk(cfg, duration);
  print("CST", w, sim.forward_speed);
  expect_clean_walk(w, duration, sim.forward_speed);
}

TEST(CanOpenWalk, CspWithTheDrivesPositionLoopAndTheObserverOn) {
  const double duration = 6;
  const app::DaemonResult sim = app::run_daemon(canopen_config(kSimDriver, kModulePd, duration, true), test::quiet());
  ASSERT_EQ(sim.run.fault, runtime::FaultClass::kNone) << runtime::to_string(sim.run.fault);
  const config::DaemonConfig cfg = canopen_config(kCspDriver, kModulePd, duration, false);
  EXPECT_EQ(cfg.driver.can.canopen.csp_kp[0], 30.0) << "the controller's K_p goes to 2010h at bring-up";
  const CanOpenWalk w = walk(cfg, duration);
  print("CSP", w, sim.forward_speed);
  expect_clean_walk(w, duration, sim.forward_speed);
}

// The bus of the vcan VM, on the host: drives that answer after the master's read deadline (every
// SYNC, from 1 s in) and a drives' thread held now and then beyond the synchronous window (their
// answers to those SYNCs never sent). The late answers are used as their SYNC's samples one cycle
// later, the lost ones leave gaps the observer bridges: the walk stays clean — no false alarm —
// and keeps its speed.
TEST(CanOpenWalk, CspWithLateAndLostAnswersNoFalseAlarm) {
  const double duration = 6;
  const app::DaemonResult sim = app::run_daemon(canopen_config(kSimDriver, kModulePd, duration, true), test::quiet());
  ASSERT_EQ(sim.run.fault, runtime::FaultClass::kNone) << runtime::to_string(sim.run.fault);
  // The read waits 1.44 ms of the 4 ms period (the bus needs 1.4); the drives answer 1.5 ms after the
  // SYNC, their last TPDO ≈ 2.8 ms after it, inside their window (0.95 · 4 ms: room for a slow
  // sanitizer build's drives' thread), and their thread is held 10 ms every 100 SYNCs.
  const std::string driver = std::string(kCspDriver).replace(std::string(kCspDriver).size() - 1, 1, ", sync_window: 0.95}");
  const config::DaemonConfig cfg = canopen_config(driver, kModulePd, duration, false, ", read_budget: 0.36");
  ASSERT_EQ(cfg.driver.can.canopen.sync_window, 0.95);
  drivers::FaultConfig f;
  f.reply_latency_ns = 1'500'000;
  f.onset_sync = 250;
  f.thread_stall_ns = 10'000'000;
  f.stall_first_sync = 300;
  f.stall_every_syncs = 100;
  const CanOpenWalk w = walk(cfg, duration, f);
  print("CSP, late answers and a held drives' thread", w, sim.forward_speed);
  std::printf("[vrobot] SYNCs held %llu; late answers used %llu of %llu late\n",
              static_cast<unsigned long long>(w.syncs_held), static_cast<unsigned long long>(w.r.counters.late_used),
              static_cast<unsigned long long>(w.r.counters.late));
  const auto cycles = static_cast<std::uint64_t>(kRate * duration);
  EXPECT_EQ(w.r.daemon.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(w.r.daemon.run.fault, runtime::FaultClass::kNone)
      << runtime::to_string(w.r.daemon.run.fault) << " joint " << w.r.daemon.run.fault_joint;
  int listed = 0;
  for (const runtime::RunEvent& e : w.r.daemon.events) listed += e.listed;
  EXPECT_EQ(listed, 0) << "no fault, warning or hold: " << w.r.daemon.exit_line;
  EXPECT_EQ(w.fault_joint, -1) << w.fault_text;
  // From 1 s on every answer is late (5 drives); most are used.
  EXPECT_GT(w.r.counters.late_used, (cycles - 250) * 5 / 2);
  EXPECT_TRUE(w.r.all_modules_off);
  ASSERT_TRUE(std::isfinite(w.r.speed));
  EXPECT_NEAR(w.r.speed, sim.forward_speed, 0.15 * sim.forward_speed);
}

TEST(CanOpenWalk, ANodeLostMidWalkStopsTheRuntimeOnItsJointNamedByTheHeartbeatConsumer) {
  const double duration = 5;
  const config::DaemonConfig cfg = canopen_config(kCstDriverFastHeartbeat, kHostPd, duration, false);
  drivers::FaultConfig f;
  f.module[2].silent = true;
  f.onset_sync = 500;  // 2 s in
  const CanOpenWalk w = walk(cfg, duration, f);
  print("CST, node 3 lost", w, NAN);
  EXPECT_EQ(w.r.daemon.run.reason, runtime::ExitReason::kFault);
  // The runtime's stale-data check or the observer's module_silent: either names the joint.
  EXPECT_TRUE(w.r.daemon.run.fault == runtime::FaultClass::kStaleData ||
              w.r.daemon.run.fault == runtime::FaultClass::kModuleSilent)
      << runtime::to_string(w.r.daemon.run.fault);
  EXPECT_EQ(w.r.daemon.run.fault_joint, 2);
  EXPECT_EQ(w.fault_joint, 2);
  EXPECT_EQ(w.fault_text.rfind("CANopen node 3 (joint 3): heartbeat lost: none for ", 0), 0u) << w.fault_text;
  // (A silent emulated node stops sending, not receiving: the safe stop reaches it too.)
  EXPECT_TRUE(w.r.all_modules_off) << "safe stop: disable operation reached every drive";
  EXPECT_LT(w.r.daemon.run.cycles, static_cast<std::uint64_t>(kRate * duration));
}

TEST(CanOpenWalk, AnEmcyMidWalkStopsTheRuntimeOnItsJointNamed) {
  const double duration = 5;
  const config::DaemonConfig cfg = canopen_config(kCstDriver, kHostPd, duration, false);
  drivers::canopen::CanOpenEmulatorConfig cc;
  cc.emcy_joint = 1;
  cc.emcy_at_sync = 500;
  cc.emcy_code = 0x4210;
  const CanOpenWalk w = walk(cfg, duration, {}, cc);
  print("CST, EMCY on node 2", w, NAN);
  EXPECT_EQ(w.r.daemon.run.reason, runtime::ExitReason::kFault);
  EXPECT_EQ(w.r.daemon.run.fault, runtime::FaultClass::kStaleData);
  EXPECT_EQ(w.r.daemon.run.fault_joint, 1);
  EXPECT_EQ(w.fault_text, "CANopen node 2 (joint 2): EMCY 4210h, error register 09h: excess temperature (device)");
  EXPECT_TRUE(w.r.all_modules_off) << "the other drives got disable operation";
}

