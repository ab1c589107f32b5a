// The runtime walking over a real kernel CAN interface: the daemon with the SocketCAN driver
// (SocketCanDriver::open on vcan0: raw socket, filters, error frames, kernel timestamps) and the
// virtual robot on a second raw socket of vcan0, classic CAN at 100 Hz with the paper robot's 5
// joints, 6 s. can-utils' candump records the bus (`candump -L`, a decoder we did not write), and
// the recorded frames are checked by decoding candump's text independently of our codecs (the
// layouts and CRC of drivers/PROTOCOL.md, re-implemented here): ids, lengths, CRCs, SYNC counter
// advancing by one, SYNC count = loop cycles, one feedback frame per SYNC per joint echoing its
// counter, the commands of each cycle tagged with that cycle's SYNC counter, the gains, the gait in
// the decoded motor angles, and the torque-off frames of the safe stop at the end.
//
// Labelled "vcan": runs inside the test VM (tools/scripts/vm/test-vcan.sh BUILD_DIR). On a kernel
// without PF_CAN or without vcan0 it skips loudly, and fails when PEDALWAVE_REQUIRE_VCAN=1.
#include <gtest/gtest.h>
#include <net/if.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "dds_domain_lease.hpp"
#include "pedalwave/runtime/run_events.hpp"
#include "pedalwave/toolkit/cpu_load.hpp"
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
constexpr canid_t kMarkerStart = 0x7F0, kMarkerEnd = 0x7F1;

// CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, xorout 0xFF) over the 11-bit id as 2 bytes little-endian
// and data[0 … len−2] (PROTOCOL.md §2), written from the specification for this test.
std::uint8_t crc8_j1850(canid_t id, const std::vector<std::uint8_t>& d) {
  std::vector<std::uint8_t> bytes{static_cast<std::uint8_t>(id & 0xFF), static_cast<std::uint8_t>((id >> 8) & 0xFF)};
  bytes.insert(bytes.end(), d.begin(), d.end() - 1);
  std::uint8_t crc = 0xFF;
  for (std::uint8_t b : bytes) {
    crc ^= b;
    for (int k = 0; k < 8; ++k) crc = (crc & 0x80) ? static_cast<std::uint8_t>((crc << 1) ^ 0x1D) : static_cast<std::uint8_t>(crc << 1);
  }
  return static_cast<std::uint8_t>(crc ^ 0xFF);
}

std::int16_t s16(const std::vector<std::uint8_t>& d, std::size_t i) {
  return static_cast<std::int16_t>(d[i] | (d[i + 1] << 8));
}
std::uint16_t u16(const std::vector<std::uint8_t>& d, std::size_t i) {
  return static_cast<std::uint16_t>(d[i] | (d[i + 1] << 8));
}

int raw_socket() {
  const int s = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
  sockaddr_can a{};
  a.can_family = AF_CAN;
  a.can_ifindex = static_cast<int>(::if_nametoindex(kIf));
  if (s >= 0 && ::bind(s, reinterpret_cast<const sockaddr*>(&a), sizeof a) != 0) {
    ::close(s);
    return -1;
  }
  return s;
}

void send_marker(int s, canid_t id) {
  can_frame f{};
  f.can_id = id;
  f.len = 1;
  f.data[0] = 0x5A;
  ASSERT_EQ(::write(s, &f, CAN_MTU), static_cast<ssize_t>(CAN_MTU));
}

// Waits until candump has written a line with `id`; returns the lines.
std::vector<std::string> wait_marker(const Candump& d, canid_t id, int s, bool resend) {
  std::vector<std::string> lines;
  test::wait_until(
      [&] {
        if (resend) send_marker(s, id);
        lines = d.lines();
        for (const auto& l : lines)
          if (auto f = parse(l); f && f->id == id) return true;
        return false;
      },
      60.0);
  return lines;
}

}  // namespace

TEST(VrobotVcan, RuntimeWalksOverVcanAndCandumpSeesTheProtocol) {
  if (!drivers::can_sockets_available())
    VCAN_SKIP_OR_FAIL("this kernel has no PF_CAN (socket(AF_CAN) fails)");
  if (::if_nametoindex(kIf) == 0)
    VCAN_SKIP_OR_FAIL("no vcan0 (ip link add dev vcan0 type vcan && ip link set up vcan0)");
  const std::string exe = find_on_path("candump");
  if (exe.empty()) VCAN_SKIP_OR_FAIL("candump (can-utils) not on PATH");

  // The VM emulates the CPU (TCG: 10–30× slower than the host, ~100× when the host is at load
  // 12): 100 Hz (the controller's lowest rate), the virtual robot's plant at h ≤ 2.5e-4 s as in
  // the deployment tests below (its module-PD integration error within the observer's budget;
  // at the 4 ms this test used to run its plant at, that error was 0.13 N·m, 4× the residual's
  // threshold, and the observer, on here, named it a fault and froze the gait), a read deadline
  // of 0.9 period, a stale-data limit of 10 s and a module command lifetime of 1 s
  // (replies late by whole periods and loop overruns of tens of ms are normal here; the host
  // tests check freshness and the 50 ms lifetime). The loop thread is pinned to CPU 0: vcan
  // delivers a sent frame through the sending CPU's backlog queue, so a thread that migrates
  // between the VM's two CPUs can see its frames reordered on the bus (seen: a cycle's commands
  // after the next SYNC); a real controller's transmit queue keeps the order.
  const model::Scene scene = config::load_scene(test::kScenePath);
  test::WalkSetup s{.transport = test::Transport::kCanClassic, .rate_hz = 100, .duration = 6,
                    .stale_timeout = 10.0, .read_budget = 0.9, .command_timeout = 1.0, .cpu = 0,
                    .plant_max_step = 2.5e-4};
  const config::DaemonConfig cfg = test::daemon_config(s, scene);
  const test::WalkResult sim = test::walk_sim(s, scene);  // the same loop in lockstep, in-process
  ASSERT_EQ(cfg.driver.can.ifname, kIf);
  const int J = scene.robot.N - 1;

  // Each attempt: candump first, synchronized with a start marker, so it records the whole run;
  // the modules on one raw socket of vcan0, the runtime's driver on another (the real open()).
  // A run in which the emulated machine held the link ≥ 0.2 s is VOID and run again
  // (test::walk_unless_machine_stalled: CI saw the modules' thread get no SYNC for 1.68 s).
  const std::string file = std::string(::testing::TempDir()) + "vrobot_candump.log";
  std::vector<std::string> lines;
  int void_runs = 0;
  const test::WalkResult r = test::walk_unless_machine_stalled("vcan protocol walk", s.rate_hz,
                                                               void_runs, [&] {
    const int marker = raw_socket();
    EXPECT_GE(marker, 0);
    Candump dump(exe, file);
    EXPECT_TRUE(dump.running());
    wait_marker(dump, kMarkerStart, marker, true);
    vrobot::VirtualRobot robot(scene, vrobot::open_module_can_socket(kIf, false),
                               test::robot_options(s, scene, {}));
    std::unique_ptr<drivers::SocketCanDriver> drv = drivers::SocketCanDriver::open(cfg.driver.can);
    test::WalkResult w = test::run_walk(cfg, robot, *drv);
    send_marker(marker, kMarkerEnd);
    lines = wait_marker(dump, kMarkerEnd, marker, false);
    dump.stop();
    ::close(marker);
    return w;
  });
  EXPECT_LT(test::stall_of(r, s.rate_hz).worst(), test::kMachineStall)
      << "the machine held the link in every attempt (" << void_runs << " void runs)";
  std::printf("%s", r.report.c_str());
  std::printf("[vrobot-vcan] %llu cycles, overruns %llu, plant %.2f s, speed %.3f cm/s (simulated "
              "plant in-process: %.3f cm/s), host missing %llu, late %llu; candump lines %zu\n",
              static_cast<unsigned long long>(r.daemon.run.cycles),
              static_cast<unsigned long long>(r.daemon.run.overruns), r.plant_t, 100 * r.speed,
              100 * sim.speed,
              static_cast<unsigned long long>(r.counters.missing),
              static_cast<unsigned long long>(r.counters.late), lines.size());

  // ---- the run itself ----
  EXPECT_EQ(r.daemon.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(r.daemon.run.fault, runtime::FaultClass::kNone) << runtime::to_string(r.daemon.run.fault);
  EXPECT_EQ(r.daemon.run.cycles, 600u);
  EXPECT_GE(r.plant_t, 5.9) << "walked ≥ 5 s of plant time";
  // Walking forward like the simulated plant; loosely: the VM's real time is far noisier than
  // the host's (overruns, late replies), see the host tests for the ±10 % comparison.
  EXPECT_GT(r.speed, 0.25 * sim.speed) << "the COM moved forward like the simulated plant's";
  EXPECT_LT(r.speed, 2.0 * sim.speed);
  EXPECT_TRUE(r.all_modules_off);
  EXPECT_EQ(r.emu.lifetime_expired, 0u) << "commands reached the modules every cycle";
  EXPECT_EQ(r.counters.checksum + r.counters.malformed + r.counters.bus_errors + r.counters.tx_dropped, 0u);

  // ---- candump's record, decoded here ----
  std::vector<Frame> frames;
  bool in_run = false;
  int dropped_lines = 0, unparsable = 0;
  for (const std::string& l : lines) {
    if (l.find("DROPPED") != std::string::npos) {
      ++dropped_lines;
      continue;
    }
    auto f = parse(l);
    if (!f) {
      ++unparsable;
      continue;
    }
    if (f->id == kMarkerStart) {
      in_run = true;
      continue;
    }
    if (f->id == kMarkerEnd) break;
    if (in_run) frames.push_back(std::move(*f));
  }
  EXPECT_EQ(unparsable, 0);
  EXPECT_EQ(dropped_lines, 0) << "candump reported dropped frames";
  ASSERT_FALSE(frames.empty());

  struct Cycle {
    std::uint8_t c = 0;                          // SYNC counter
    std::array<int, 64> fb_echo{};               // feedback frames echoing c before the next SYNC
    std::array<int, 64> cmd{};                   // command frames tagged with c, per node
    int gains = 0;
  };
  std::vector<Cycle> cycles;
  int bad_len = 0, bad_crc = 0, bad_id = 0, fd_frames = 0, cmd_wrong_tag = 0;
  // Per node: the echoed counters in the order the frames appeared, and for each the number of
  // SYNCs seen before it (causality: the i-th answer comes after the i-th SYNC).
  std::array<std::vector<int>, 64> echoes;
  std::array<std::vector<std::size_t>, 64> syncs_before;
  int fb_total = 0, cmd_total = 0, off_cmds_running = 0, sync_steps_bad = 0, fb_torque_off = 0;
  int timing_total = 0, timing_wrong_echo = 0, timing_no_cmd = 0;
  std::map<int, int> torque_off_nodes_after_last_sync;
  std::array<double, 64> beta_min{}, beta_max{};
  beta_min.fill(1e9);
  beta_max.fill(-1e9);
  std::size_t last_sync_index = 0;
  for (std::size_t i = 0; i < frames.size(); ++i)
    if (frames[i].id == 0x080) last_sync_index = i;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const Frame& f = frames[i];
    EXPECT_EQ(f.iface, kIf);
    fd_frames += f.fd;
    const canid_t id = f.id;
    const std::size_t len = id == 0x080 ? 2u : 8u;
    if (f.data.size() != len) {
      ++bad_len;
      continue;
    }
    if (crc8_j1850(id, f.data) != f.data.back()) ++bad_crc;
    if (id == 0x080) {  // SYNC
      const std::uint8_t c = f.data[0];
      if (!cycles.empty() && c != static_cast<std::uint8_t>(cycles.back().c + 1)) ++sync_steps_bad;
      cycles.push_back(Cycle{.c = c});
      continue;
    }
    if (cycles.empty()) {  // nothing but SYNC can open the run
      ++bad_id;
      continue;
    }
    Cycle& cy = cycles.back();
    const int nib = f.data[6] & 0x0F;
    if (id > 0x180 && id <= 0x180u + J) {  // feedback
      const int node = static_cast<int>(id - 0x180);
      ++fb_total;
      if (nib == (cy.c & 0x0F)) ++cy.fb_echo[static_cast<std::size_t>(node)];
      echoes[static_cast<std::size_t>(node)].push_back(nib);
      syncs_before[static_cast<std::size_t>(node)].push_back(cycles.size());
      const double beta = 1e-4 * s16(f.data, 0);
      beta_min[static_cast<std::size_t>(node)] = std::min(beta_min[static_cast<std::size_t>(node)], beta);
      beta_max[static_cast<std::size_t>(node)] = std::max(beta_max[static_cast<std::size_t>(node)], beta);
      if (cycles.size() > 10 && i < last_sync_index && (f.data[6] >> 4) & 0x8) ++fb_torque_off;
    } else if (id > 0x200 && id <= 0x200u + J) {  // command
      const int node = static_cast<int>(id - 0x200);
      ++cmd_total;
      if (nib != (cy.c & 0x0F)) ++cmd_wrong_tag;
      ++cy.cmd[static_cast<std::size_t>(node)];
      const bool off = (f.data[6] >> 4) & 1;
      if (off && i < last_sync_index) ++off_cmds_running;
      if (off && i > last_sync_index) ++torque_off_nodes_after_last_sync[node];
      EXPECT_EQ(f.data[6] >> 5, 0) << "reserved bits";
    } else if (id > 0x380 && id <= 0x380u + J) {  // timing record (PROTOCOL.md §1.1)
      ++timing_total;
      if (nib != (cy.c & 0x0F)) ++timing_wrong_echo;
      if (i < last_sync_index && cycles.size() > 10 && (u16(f.data, 4) & 0x8000)) ++timing_no_cmd;
    } else if (id > 0x300 && id <= 0x300u + J) {  // gains
      ++cy.gains;
      if (i < last_sync_index) {
        EXPECT_NEAR(1e-2 * u16(f.data, 0), 30.0, 1e-9) << "kp = K_p";
        EXPECT_NEAR(1e-3 * u16(f.data, 2), 15.0, 1e-9) << "kd = K_D";
      }
      if (nib != (cy.c & 0x0F)) ++cmd_wrong_tag;
    } else {
      ++bad_id;
    }
  }
  EXPECT_EQ(bad_id, 0);
  EXPECT_EQ(bad_len, 0);
  EXPECT_EQ(bad_crc, 0);
  EXPECT_EQ(fd_frames, 0) << "classic CAN run";
  // SYNC: one per loop cycle, counter +1 mod 256 each time; the modules saw each one.
  EXPECT_EQ(cycles.size(), r.daemon.run.cycles);
  EXPECT_EQ(r.emu.syncs, r.daemon.run.cycles);
  EXPECT_EQ(sync_steps_bad, 0);
  // Feedback: every module answered every SYNC once, in order, echoing that SYNC's counter, and
  // never before the SYNC. (When the answer arrives — before the host's deadline or after the
  // next SYNC — depends on the VM's emulated CPU: counted, not asserted.)
  EXPECT_EQ(fb_total, J * static_cast<int>(cycles.size()));
  // Timing records: one per module and SYNC, echoing it; "no command" only before the first.
  EXPECT_EQ(timing_total, J * static_cast<int>(cycles.size()));
  std::printf("[vrobot-vcan] timing records after the next SYNC: %d of %d\n", timing_wrong_echo, timing_total);
  EXPECT_EQ(timing_no_cmd, 0) << "a module reported no command while walking";
  for (int n = 1; n <= J; ++n) {
    const auto& e = echoes[static_cast<std::size_t>(n)];
    ASSERT_EQ(e.size(), cycles.size()) << "node " << n;
    int wrong = 0, early = 0;
    for (std::size_t k = 0; k < e.size(); ++k) {
      wrong += e[k] != (cycles[k].c & 0x0F);
      early += syncs_before[static_cast<std::size_t>(n)][k] < k + 1;
    }
    EXPECT_EQ(wrong, 0) << "node " << n << ": answers out of step with the SYNCs";
    EXPECT_EQ(early, 0) << "node " << n << ": an answer before its SYNC";
  }
  int fb_on_time = 0;
  for (const Cycle& cy : cycles)
    for (int n = 1; n <= J; ++n) fb_on_time += cy.fb_echo[static_cast<std::size_t>(n)] == 1;
  std::printf("[vrobot-vcan] answers before the next SYNC: %d of %d\n", fb_on_time,
              J * static_cast<int>(cycles.size()));
  // Commands: every cycle, one per joint, tagged with that cycle's SYNC counter; one gains frame.
  EXPECT_EQ(cmd_wrong_tag, 0);
  int full_cycles = 0;
  for (std::size_t k = 0; k < cycles.size(); ++k) {
    bool all = cycles[k].gains == 1;
    for (int n = 1; n <= J; ++n)
      all = all && cycles[k].cmd[static_cast<std::size_t>(n)] == (k + 1 == cycles.size() ? 2 : 1);
    full_cycles += all;
  }
  EXPECT_EQ(full_cycles, static_cast<int>(cycles.size()))
      << "each cycle: J commands + 1 gains frame; the last cycle: its commands + the safe stop's";
  EXPECT_EQ(cmd_total, J * static_cast<int>(cycles.size()) + J);
  // The safe stop: a torque-off command to every module after the last SYNC, none before.
  EXPECT_EQ(off_cmds_running, 0);
  EXPECT_EQ(static_cast<int>(torque_off_nodes_after_last_sync.size()), J);
  for (const auto& [node, n] : torque_off_nodes_after_last_sync) EXPECT_EQ(n, 1) << "node " << node;
  EXPECT_EQ(fb_torque_off, 0) << "no module reported its output off while walking";
  // The gait, seen in the decoded motor angles: each joint swings by about 2 A_p = π/2.
  for (int n = 1; n <= J; ++n) {
    const double range = beta_max[static_cast<std::size_t>(n)] - beta_min[static_cast<std::size_t>(n)];
    EXPECT_GT(range, 1.2) << "joint " << n;
    EXPECT_LT(range, 2.0) << "joint " << n;
  }
}

// The deployment path over the real SocketCAN (issue 12): the runtime daemon with its real
// SocketCAN driver on vcan0, the modules on another raw socket of vcan0, SCHED_FIFO for both, the
// observer ON and DDS telemetry ON (loopback inside the VM), the daemon's derived timeouts, 60 s:
// no event of any class and a speed within 10 % of the in-process plant at the same rate. Then the
// fault catalogue over the same bus: each fault detected and isolated on its joint.
// The VM emulates the CPU (TCG): classic CAN at 100 Hz, the virtual robot's plant at h = 2.5e-4 s
// (its module-PD integration error ≤ 0.01 N·m, a third of the residual threshold), the loop
// pinned to CPU 0 (see above: vcan reorders a migrating sender's frames).
// Enabled (issue 12) once two faults of the deployment path were found and fixed, both with a
// deterministic test in tests/tools/virtual_robot/vrobot_walk_test.cpp:
//  - the drivers' module-clock estimate slewed the sample times toward its converging offset at
//    up to 1000 ppm of each interval; an interval error ε·dt misplaces ≈ ε·k_d·β̇ of the module
//    law's torque (0.015 N·m per rad/s). In the VM the first SYNCs reach the modules 1.8 ms late,
//    the estimate then moves by 1.8 ms, and at 100 Hz (blocks of 1.28 s) it converged over the
//    walk's first seconds: the start-up actuator_torque at 2.6–2.7 s of every earlier VM walk
//    (0.046–0.05 N·m, joint 4 mostly). 20 ppm now
//    (BusModel.TheModulesClockEstimateConvergingAt100HzIsNoFault: 0.049 N·m at 2.6 s before).
//  - a command applied inside a gap of lost samples was placed a cycle back from the reported
//    one; at 100 Hz with the write time varying inside the cycle that kicked r by up to 0.05 N·m
//    (BusModel.LostRepliesWithAVaryingWriteTimeAt100Hz); the residual now skips such an interval.
// Before: the 60 s walk failed in every VM run. After: the walk alone passed 3 of 3 (speed −0.3 %,
// peak |r| 0.019 N·m), the seven tests 7 of 7 in one run — but in full `ctest -L vcan` runs a
// rare false encoder_jump in healthy time (|c| 5.7e-4 … 2.1e-3 rad against 5e-4; in the 60 s
// walk, a fault trial, and once the protocol walk) failed 4 of 13 runs, the clean-clone CI check
// among them (7.5e-4 rad at 20 s in the walk). Its cause is not confirmed (the observer's
// placement bound did not change it), so these were DISABLED: a finding, issue 12.
// Later: with the host loaded, walks stopped on gross actuator_torque values (3–22 N·m): a held
// modules' vCPU answered a backlog of ≥ 16 cycles at once and the 4-bit tags named commands 16
// cycles off — fixed (drivers/answer_log.hpp, BusWalkStalls.*). After that fix: four VM runs on
// an idle host, 7/7 and three times 18/18 (the walk −0.96 %, every fault on its joint), so they
// are ENABLED again (issue 12). Open: on a host loaded to load 3–8 (the emulated machine holding
// the link for seconds, mostly VOID runs) one broken-spring trial stopped on a false encoder_jump
// in healthy joint 5 (1.5e-3 rad at 2.64 s), cause not found (README "The vcan VM").
namespace {
test::WalkSetup vm_deployment(double duration, std::uint32_t domain) {
  test::WalkSetup s;
  s.transport = test::Transport::kCanClassic;
  s.rate_hz = 100;
  s.duration = duration;
  s.stale_timeout = 0;
  s.read_budget = 0;
  s.command_timeout = 0.5;
  s.observer = true;
  s.priority = 80;
  s.robot_priority = 70;
  s.telemetry = true;
  s.telemetry_domain = domain;
  s.clock_drift_ppm = 30;
  s.plant_max_step = 2.5e-4;
  s.cpu = 0;
  // PEDALWAVE_VM_PLOTS=DIR: the daemon's --plots of each walk (cycles.csv with the residuals) in
  // DIR/<domain>-<walk>, on the folder the VM shares with the host (debugging these tests).
  if (const char* dir = std::getenv("PEDALWAVE_VM_PLOTS"); dir != nullptr && *dir != '\0') {
    static int walks = 0;  // one folder per walk (the tests share a domain)
    s.plots_dir = std::string(dir) + "/" + std::to_string(domain) + "-" + std::to_string(++walks);
    std::filesystem::create_directories(s.plots_dir);
  }
  return s;
}

test::WalkResult walk_vcan(const test::WalkSetup& s, const model::Scene& scene) {
  const config::DaemonConfig cfg = test::daemon_config(s, scene);
  vrobot::VirtualRobotOptions vo = test::robot_options(s, scene, {});
  vrobot::VirtualRobot robot(scene, vrobot::open_module_can_socket(kIf, false), vo);
  std::unique_ptr<drivers::SocketCanDriver> drv = drivers::SocketCanDriver::open(cfg.driver.can);
  return test::run_walk(cfg, robot, *drv, s.telemetry, s.plots_dir);
}

// walk_vcan, run again when the emulated machine held the link (test::walk_unless_machine_stalled).
// Under a background CPU load inside the VM (issue 12's proof): one busy process per vCPU at
// normal priority, as the pty deployment tests run.
test::WalkResult walk_vcan_unless_stalled(const char* what, const test::WalkSetup& s,
                                          const model::Scene& scene) {
  int void_runs = 0;
  const long n = ::sysconf(_SC_NPROCESSORS_ONLN);
  const test::WalkResult r = test::walk_unless_machine_stalled(what, s.rate_hz, void_runs, [&] {
    toolkit::CpuLoad load;
    load.start(n > 0 ? static_cast<int>(n) : 1);
    test::WalkResult w = walk_vcan(s, scene);
    load.stop();
    return w;
  });
  EXPECT_LT(test::stall_of(r, s.rate_hz).worst(), test::kMachineStall)
      << "the machine held the link in every attempt (" << void_runs << " void runs)";
  return r;
}

std::string listed_events(const test::WalkResult& r) {
  std::string t;
  for (const runtime::RunEvent& e : r.daemon.events)
    if (e.listed) t += "  " + runtime::format_event_short(e, r.daemon.event_log) + "\n";
  return t;
}
}  // namespace

TEST(VrobotVcan, DeploymentWalks60sObserverAndTelemetryOnUnderCpuLoad) {
  if (!drivers::can_sockets_available())
    VCAN_SKIP_OR_FAIL("this kernel has no PF_CAN (socket(AF_CAN) fails)");
  if (::if_nametoindex(kIf) == 0) VCAN_SKIP_OR_FAIL("no vcan0");
  test::DomainLease lease;
  const model::Scene scene = config::load_scene(test::kScenePath);
  const test::WalkSetup s = vm_deployment(60, lease.id());
  test::WalkSetup ref = s;
  ref.telemetry = false;
  const test::WalkResult sim = test::walk_sim(ref, scene);
  const test::WalkResult r = walk_vcan_unless_stalled("60 s walk", s, scene);
  std::printf("[vrobot-vcan] deployment: %s\n  speed %.4f cm/s (in-process %.4f cm/s, %+.2f %%), "
              "%llu cycles, overruns %llu, host missing %llu, late %llu; %s; rt: %s\n%s%s",
              r.daemon.exit_line.c_str(), 100 * r.speed, 100 * sim.speed,
              100 * (r.speed - sim.speed) / sim.speed,
              static_cast<unsigned long long>(r.daemon.run.cycles),
              static_cast<unsigned long long>(r.daemon.run.overruns),
              static_cast<unsigned long long>(r.counters.missing),
              static_cast<unsigned long long>(r.counters.late), r.robot_thread.c_str(),
              r.daemon.run.rt.describe().c_str(), r.report.c_str(), listed_events(r).c_str());
  EXPECT_EQ(r.daemon.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(r.daemon.run.fault, runtime::FaultClass::kNone) << runtime::to_string(r.daemon.run.fault);
  int listed = 0;
  for (const runtime::RunEvent& e : r.daemon.events) listed += e.listed;
  EXPECT_EQ(listed, 0) << "no fault, warning or hold:\n" << listed_events(r);
  EXPECT_TRUE(r.daemon.telemetry_active);
  EXPECT_EQ(r.daemon.run.cycles, 6000u);
  EXPECT_TRUE(r.all_modules_off);
  ASSERT_TRUE(std::isfinite(r.speed));
  EXPECT_NEAR(r.speed, sim.speed, 0.10 * sim.speed);
}

struct VcanFault {
  model::FaultType type;
  int joint;
  double value;
  runtime::FaultClass expect;
  const char* name;
};
void PrintTo(const VcanFault& f, std::ostream* os) { *os << f.name << " on joint " << f.joint + 1; }

class VrobotVcanFaults : public ::testing::TestWithParam<VcanFault> {};

TEST_P(VrobotVcanFaults, DetectedAndIsolatedOverVcan) {
  if (!drivers::can_sockets_available())
    VCAN_SKIP_OR_FAIL("this kernel has no PF_CAN (socket(AF_CAN) fails)");
  if (::if_nametoindex(kIf) == 0) VCAN_SKIP_OR_FAIL("no vcan0");
  const VcanFault f = GetParam();
  test::DomainLease lease;
  model::Scene scene = config::load_scene(test::kScenePath);
  scene.faults.push_back({.type = f.type, .joint = f.joint, .t_start = 4.0, .value = f.value});
  const test::WalkResult r = walk_vcan_unless_stalled(f.name, vm_deployment(12, lease.id()), scene);
  std::printf("[vrobot-vcan] %s on joint %d: %s\n%s", f.name, f.joint + 1,
              r.daemon.exit_line.c_str(), listed_events(r).c_str());
  const runtime::RunEvent* first = nullptr;
  for (const runtime::RunEvent& e : r.daemon.events)
    if (e.listed && e.sample.fault != runtime::FaultClass::kNone) {
      first = &e;
      break;
    }
  ASSERT_NE(first, nullptr) << f.name << ": not detected\n" << r.daemon.summary;
  EXPECT_EQ(first->sample.fault, f.expect) << runtime::to_string(first->sample.fault);
  EXPECT_EQ(first->sample.joint, f.joint);
  EXPECT_GE(r.daemon.event_log.seconds(first->sample), 4.0) << "no verdict before the onset";
  EXPECT_LE(r.daemon.event_log.seconds(first->sample), 8.0);
}

INSTANTIATE_TEST_SUITE_P(
    Vcan, VrobotVcanFaults,
    ::testing::Values(
        VcanFault{model::FaultType::kTorqueGain, 2, 0.0, runtime::FaultClass::kActuatorTorque, "torque_loss"},
        VcanFault{model::FaultType::kSpringScale, 1, 0.2, runtime::FaultClass::kSpringBroken, "broken_spring"},
        VcanFault{model::FaultType::kEncoderStuck, 3, 0.0, runtime::FaultClass::kEncoderStuck, "encoder_stuck"},
        VcanFault{model::FaultType::kEncoderOffset, 0, 0.02, runtime::FaultClass::kEncoderJump, "encoder_jump"},
        VcanFault{model::FaultType::kDeflectionBias, 2, 0.05, runtime::FaultClass::kDeflectionBias, "deflection_bias"},
        VcanFault{model::FaultType::kModuleSilent, 4, 0.0, runtime::FaultClass::kModuleSilent, "silent_module"}),
    [](const auto& param_info) { return std::string(param_info.param.name); });
