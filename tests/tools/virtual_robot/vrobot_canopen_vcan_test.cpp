// The CANopen walk over a real kernel CAN interface (vcan0): the daemon with the CANopen master
// (CanOpenDriver::open: raw socket, its id filters, kernel timestamps) in CSP, the virtual robot's
// CANopen drives on a second raw socket, and can-utils' candump as an independent peer recording
// the bus. The recorded frames are checked by decoding candump's text here, with CiA 301 / 402
// written from the specification, not with our codecs: the bring-up (NMT reset communication,
// every node's boot-up, SDO requests and answers, NMT start), one SYNC (080h, no data) per loop
// cycle, per SYNC every node's TPDO 1 (180h + node) and TPDO 2 (280h + node) and RPDO 1
// (200h + node) with the controlword enable operation, operational heartbeats (700h + node), the
// gait in the decoded positions, and the safe stop's disable operation.
//
// Labelled "vcan": runs inside the test VM (tools/scripts/vm/test-vcan.sh BUILD_DIR). On a kernel
// without PF_CAN or vcan0, or without candump, it skips loudly, and fails when
// PEDALWAVE_REQUIRE_VCAN=1.
#include <gtest/gtest.h>
#include <fcntl.h>
#include <net/if.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <numbers>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "pedalwave/drivers/canopen_driver.hpp"
#include "candump.hpp"
#include "walk_rig.hpp"

using namespace pedalwave;
using test::Candump;
using test::find_on_path;
using test::Frame;
using test::parse;
using test::vcan_required;

namespace {

constexpr const char* kIf = "vcan0";

std::uint16_t le16(const std::vector<std::uint8_t>& d, std::size_t i) {
  return static_cast<std::uint16_t>(d[i] | (d[i + 1] << 8));
}
std::int32_t le32(const std::vector<std::uint8_t>& d, std::size_t i) {
  return static_cast<std::int32_t>(std::uint32_t{d[i]} | (std::uint32_t{d[i + 1]} << 8) |
                                   (std::uint32_t{d[i + 2]} << 16) | (std::uint32_t{d[i + 3]} << 24));
}

}  // namespace

// CSP, the PD in the drives: in the VM the loop's first cycles came 30–40 ms apart even at
// SCHED_FIFO 80 with mlockall (the read overran its deadline); in CST the PD runs on the host and
// a 40 ms hold of its torque is beyond the sampled PD's stability limit 2J/K_D = 13 ms, so the
// motor ran away (−64 … −130 rad/s) and the observer stopped the robot on an implausible rate,
// rightly. CST is walked over a socket pair (vrobot_canopen_test); this test is about the bus.
TEST(CanOpenVcan, CspWalkWithCandumpCheckingSyncPdosAndTheBringUp) {
  if (!drivers::can_sockets_available())
    VCAN_SKIP_OR_FAIL("this kernel has no PF_CAN (socket(AF_CAN) fails)");
  if (::if_nametoindex(kIf) == 0)
    VCAN_SKIP_OR_FAIL("PF_CAN works but there is no vcan0 (ip link add dev vcan0 type vcan && ip link set up vcan0)");
  const std::string exe = find_on_path("candump");
  if (exe.empty()) VCAN_SKIP_OR_FAIL("candump (Debian package can-utils) is not on PATH");

  const model::Scene scene = config::load_scene(test::kScenePath);
  const int J = scene.robot.N - 1;
  // The VM is slow: 100 Hz, generous timeouts (as the own protocol's vcan walk), observer on.
  const double rate = 100, duration = 6;
  // The CANopen walk's configuration, and the same controller on the in-process plant (lockstep).
  auto configure = [&](const char* driver, const char* realtime) {
    char yaml[1024];
    std::snprintf(yaml, sizeof yaml,
                  "name: vcan-canopen\nrate_hz: %g\nduration: %g\nrobot: {N: %d}\ndriver: %s\n"
                  "controller: {k_c: 0, pd_placement: module, K_p: 30, K_D: 15}\nrealtime: %s\n"
                  "observer: {enabled: true}\ntelemetry: {enabled: false}\n",
                  rate, duration, scene.robot.N, driver, realtime);
    config::DaemonConfig c = config::parse_daemon_config(yaml, "vcan-canopen.yaml", PEDALWAVE_CONFIG_DIR "/runtime");
    c.controller.gait.A_p = scene.gait.A_p;
    c.controller.gait.omega = scene.gait.omega;
    c.controller.admittance.eta_n = {scene.gait.eta};
    return c;
  };
  const config::DaemonConfig cfg =
      configure("{type: socketcan, ifname: vcan0, protocol: canopen, drive_mode: csp, heartbeat: 0.1, "
                "heartbeat_timeout: 2.0}",
                "{clock: realtime, cpu: 0, priority: 80, lock_memory: true, stale_timeout: 10, read_budget: 0.8}");
  const app::DaemonResult sim = app::run_daemon(
      configure("{type: sim, scene: ../scenes/flat_high_friction.yaml, clock: lockstep}", "{clock: lockstep}"),
      test::quiet());
  ASSERT_EQ(sim.run.fault, runtime::FaultClass::kNone) << runtime::to_string(sim.run.fault);

  // SCHED_FIFO for the loop (80) and the drives' thread (70), as the other deployment walks in the
  // VM: at normal priority the VM's first cycles overran to 27 ms, beyond the host PD's sampled
  // stability limit 2J/K_D = 13 ms in CST (the PD on the host); see above.
  test::WalkSetup s{.transport = test::Transport::kCanClassic, .rate_hz = rate, .duration = duration,
                    .command_timeout = 1.0, .plant_max_step = 2.5e-4};
  s.robot_priority = 70;
  // PEDALWAVE_VM_PLOTS=DIR: the daemon's --plots (cycles.csv) in DIR/canopen, on the folder the VM
  // shares with the host (debugging this test).
  std::string plots;
  if (const char* dir = std::getenv("PEDALWAVE_VM_PLOTS"); dir != nullptr && *dir != '\0') {
    plots = std::string(dir) + "/canopen";
    std::filesystem::create_directories(plots);
  }
  // Each attempt: candump first, so it records the whole run. A run in which the emulated machine
  // held the link ≥ 0.2 s is VOID and run again (test::walk_unless_machine_stalled), as the own
  // protocol's VM walks. A loop that overran is not void (issue 14: once the samples of a SYNC
  // queued behind the loop's own RPDOs went out without a time, 6 of 6 such runs were clean; before,
  // 3 of 5–6 named a false actuator_torque, deflection_bias or motor_friction).
  const std::string file = std::string(::testing::TempDir()) + "canopen_candump.log";
  std::vector<std::string> lines;
  std::string driver_fault;
  int driver_fault_joint = -1, void_runs = 0;
  static int attempts = 0;  // across --gtest_repeat too: each attempt's folder is kept
  std::string sync_note;
  auto attempt = [&] { return test::walk_unless_machine_stalled("canopen vcan walk", rate, void_runs, [&] {
    Candump dump(exe, file);
    EXPECT_TRUE(dump.running());
    std::this_thread::sleep_for(std::chrono::milliseconds(300));  // candump bound to vcan0
    vrobot::VirtualRobotOptions vo = test::robot_options(s, scene, {});
    vo.bus = vrobot::Bus::kCanOpen;
    if (!plots.empty()) vo.emulator.trace_syncs = 4000;
    vrobot::VirtualRobot robot(scene, vrobot::open_canopen_module_socket(kIf), vo);
    robot.start();
    std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the drives' power-on boot-ups
    std::unique_ptr<drivers::CanOpenDriver> drv = drivers::CanOpenDriver::open(cfg.driver.can);
    // One folder per attempt: a void run's data stay beside the verdict's.
    const std::string attempt_plots = plots.empty() ? plots : plots + "/attempt-" + std::to_string(++attempts);
    test::WalkResult w = test::run_walk(cfg, robot, *drv, false, attempt_plots);
    if (!attempt_plots.empty()) {  // the drives' view of each SYNC (ModuleBank::SyncTrace)
      std::ofstream tr(attempt_plots + "/drive_syncs.csv");
      tr << "sync,stamp_ns,handled_ns,behind_ns\n";
      for (const auto& x : robot.bank().sync_trace())
        tr << x.sync << ',' << x.stamp_ns << ',' << x.handled_ns << ',' << x.behind_ns << '\n';
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(500));  // candump writes the tail
    dump.stop();
    lines = dump.lines();
    driver_fault = drv->fault_text();
    driver_fault_joint = drv->fault_joint();
    char echo[400];
    std::snprintf(echo, sizeof echo,
                  "SYNC echo %s: longest send %.2f ms, %llu SYNCs sent > 1 ms late, %llu echoes lost; %llu SYNCs held "
                  "(the previous window open); clock offset: %llu tries re-read, kept bracket %lld ns; %llu echoes "
                  "stamped at read (no time); %llu SYNCs placed after the frames ahead (up to %.3f ms)",
                  drv->sync_echo() ? "on" : "OFF", 1e-6 * static_cast<double>(drv->sync_delay_max_ns()),
                  static_cast<unsigned long long>(drv->syncs_delayed()),
                  static_cast<unsigned long long>(drv->sync_echoes_lost()),
                  static_cast<unsigned long long>(drv->syncs_held()),
                  static_cast<unsigned long long>(drv->clock_offset().retried()),
                  static_cast<long long>(drv->clock_offset().width_ns()),
                  static_cast<unsigned long long>(drv->echoes_stamped_at_read()),
                  static_cast<unsigned long long>(drv->syncs_after_frames()),
                  1e-6 * static_cast<double>(drv->after_frames_max_ns()));
    sync_note = echo;
    return w;
  }); };
  // A loop that overruns (a loaded machine: 150–500 of 600 cycles late with one busy loop beside
  // the VM) is a run like any other: the runtime's verdicts below must hold in it too.
  const test::WalkResult r = attempt();
  EXPECT_LT(test::stall_of(r, rate).worst(), test::kMachineStall)
      << "the machine held the link in every attempt (" << void_runs << " void runs)";
  std::printf("%s[canopen-vcan] %llu cycles, overruns %llu, speed %.3f cm/s (in-process %.3f cm/s), missing %llu, "
              "late %llu (used %llu), driver fault '%s'; %s\n",
              r.report.c_str(), static_cast<unsigned long long>(r.daemon.run.cycles),
              static_cast<unsigned long long>(r.daemon.run.overruns), 100 * r.speed, 100 * sim.forward_speed,
              static_cast<unsigned long long>(r.counters.missing), static_cast<unsigned long long>(r.counters.late),
              static_cast<unsigned long long>(r.counters.late_used), driver_fault.c_str(), sync_note.c_str());
  EXPECT_EQ(r.daemon.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(r.daemon.run.fault, runtime::FaultClass::kNone) << runtime::to_string(r.daemon.run.fault);
  // The deployment path is clean: no fault, warning or hold (issue 14: before the synchronous
  // window and the late answers' use, 845 of 3000 samples were dropped as late and the observer
  // named a false actuator_torque).
  int listed = 0;
  for (const runtime::RunEvent& e : r.daemon.events) listed += e.listed;
  EXPECT_EQ(listed, 0) << "no fault, warning or hold: " << r.daemon.exit_line;
  EXPECT_EQ(driver_fault_joint, -1) << driver_fault;
  EXPECT_TRUE(r.all_modules_off);
  ASSERT_TRUE(std::isfinite(r.speed));
  EXPECT_NEAR(r.speed, sim.forward_speed, 0.15 * sim.forward_speed);

  // ---- The bus as candump saw it ----
  std::vector<Frame> frames;
  for (const std::string& l : lines)
    if (auto f = parse(l)) frames.push_back(*f);
  ASSERT_FALSE(frames.empty());
  // Bring-up: NMT reset communication to all (000h: 82 00), a boot-up (700h + node: 00) from every
  // node, SDO requests (600h + node) each answered (580h + node), NMT start (000h: 01 00) after.
  std::size_t reset_at = frames.size(), start_at = frames.size();
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const Frame& f = frames[i];
    if (f.id == 0x000 && f.data == std::vector<std::uint8_t>{0x82, 0x00} && reset_at == frames.size()) reset_at = i;
    if (f.id == 0x000 && f.data == std::vector<std::uint8_t>{0x01, 0x00}) start_at = i;
  }
  ASSERT_LT(reset_at, frames.size()) << "NMT reset communication";
  ASSERT_LT(start_at, frames.size()) << "NMT start";
  ASSERT_LT(reset_at, start_at);
  std::map<unsigned, int> boot, sdo_req, sdo_resp;
  for (std::size_t i = reset_at; i < start_at; ++i) {
    const Frame& f = frames[i];
    if (f.id > 0x700 && f.id <= 0x77F && f.data == std::vector<std::uint8_t>{0x00}) ++boot[f.id - 0x700];
    if (f.id > 0x600 && f.id <= 0x67F && f.data.size() == 8) ++sdo_req[f.id - 0x600];
    if (f.id > 0x580 && f.id <= 0x5FF && f.data.size() == 8) {
      ++sdo_resp[f.id - 0x580];
      EXPECT_NE(f.data[0], 0x80) << "an SDO abort from node " << f.id - 0x580;
    }
  }
  for (unsigned n = 1; n <= static_cast<unsigned>(J); ++n) {
    // One boot-up answers the reset; a drive's power-on boot-up can land after the reset too when
    // the VM schedules the drives' thread late, so at most two.
    EXPECT_GE(boot[n], 1) << "boot-up of node " << n;
    EXPECT_LE(boot[n], 2) << "boot-up of node " << n;
    EXPECT_GT(sdo_req[n], 20) << "node " << n << " configured by SDO";
    EXPECT_EQ(sdo_resp[n], sdo_req[n]) << "every SDO request of node " << n << " answered (no abort)";
  }
  // The cycle: SYNCs without data; between two SYNCs each node's TPDOs (8 bytes) and RPDO 1
  // (8 bytes: controlword, target position, torque offset).
  int syncs = 0, complete = 0, enabled_rpdos = 0, operational_hb = 0;
  std::map<unsigned, std::pair<double, double>> range;  // node → min, max position [rad]
  std::vector<int> t1(J + 1), t2(J + 1), rp(J + 1);
  auto close_cycle = [&] {
    if (syncs == 0) return;
    bool all = true;
    for (int n = 1; n <= J; ++n) all = all && t1[n] == 1 && t2[n] == 1;
    complete += all ? 1 : 0;
    std::fill(t1.begin(), t1.end(), 0);
    std::fill(t2.begin(), t2.end(), 0);
  };
  const Frame* last_rpdo = nullptr;
  for (std::size_t i = start_at; i < frames.size(); ++i) {
    const Frame& f = frames[i];
    if (f.id == 0x080) {
      EXPECT_TRUE(f.data.empty()) << "SYNC without counter";
      close_cycle();
      ++syncs;
    } else if (f.id > 0x180 && f.id <= 0x180 + static_cast<unsigned>(J)) {
      ASSERT_EQ(f.data.size(), 8u);
      ++t1[f.id - 0x180];
      const double beta = le32(f.data, 2) * 2 * std::numbers::pi / (1 << 20);  // 608Fh: 2^20 / rev
      auto& [lo, hi] = range.try_emplace(f.id - 0x180, beta, beta).first->second;
      lo = std::min(lo, beta);
      hi = std::max(hi, beta);
    } else if (f.id > 0x280 && f.id <= 0x280 + static_cast<unsigned>(J)) {
      ASSERT_EQ(f.data.size(), 8u);
      ++t2[f.id - 0x280];
    } else if (f.id > 0x200 && f.id <= 0x200 + static_cast<unsigned>(J)) {
      ASSERT_EQ(f.data.size(), 8u);  // CSP RPDO 1: controlword, target position, torque offset
      if (le16(f.data, 0) == 0x000F) ++enabled_rpdos;
      last_rpdo = &f;
    } else if (f.id > 0x700 && f.id <= 0x77F && f.data == std::vector<std::uint8_t>{0x05}) {
      ++operational_hb;
    }
  }
  close_cycle();
  std::printf("[canopen-vcan] candump: %zu frames, %d SYNCs, %d complete cycles, %d enabled RPDOs, "
              "%d operational heartbeats\n", frames.size(), syncs, complete, enabled_rpdos, operational_hb);
  EXPECT_GE(syncs, static_cast<int>(r.daemon.run.cycles)) << "one SYNC per loop cycle (+ the safe stop's)";
  EXPECT_LE(syncs, static_cast<int>(r.daemon.run.cycles) + 1);
  // The drives' punctuality (every node's TPDOs between two SYNCs) is the emulated drives', not
  // the runtime's: asserted when the machine ran the drives' thread without holding it ≥ 20 ms; a
  // loaded machine holds it many times (the runtime's verdicts above hold either way).
  if (r.emu.self_stalls == 0) {
    EXPECT_GT(complete, syncs * 9 / 10) << "every node's TPDO 1 and 2 once per SYNC";
  } else {
    EXPECT_GT(complete, 0) << "every node's TPDO 1 and 2 once per SYNC, at least sometimes";
    std::printf("######## NOT CHECKED: every node's TPDOs once per SYNC (%d of %d SYNCs complete): the machine "
                "held the emulated drives' thread >= 20 ms %llu times; the runtime's checks above were made ########\n",
                complete, syncs, static_cast<unsigned long long>(r.emu.self_stalls));
  }
  EXPECT_GT(enabled_rpdos, J * syncs / 2) << "enable operation while walking";
  EXPECT_GE(operational_hb, J * 40) << "100 ms heartbeats over 6 s, state operational";
  ASSERT_NE(last_rpdo, nullptr);
  EXPECT_EQ(le16(last_rpdo->data, 0), 0x0007) << "the safe stop: disable operation";
  for (int n = 1; n <= J; ++n)
    EXPECT_GT(range[static_cast<unsigned>(n)].second - range[static_cast<unsigned>(n)].first, 0.1)
        << "node " << n << " follows the gait";
}
