// pedalwave_virtual_robot — a scene's plant model answering as the robot's modules would, on a CAN
// interface or on the far end of a pseudo-terminal, in real time, until Ctrl-C (or --duration).
//
//   pedalwave_virtual_robot --scene config/scenes/flat_high_friction.yaml --can vcan0 [--fd]
//   pedalwave_virtual_robot --scene config/scenes/flat_high_friction.yaml --can vcan0 --protocol canopen
//   pedalwave_virtual_robot --scene config/scenes/flat_high_friction.yaml --pty [--link PATH]
//       [--latency ms] [--loss p] [--bit-error p] [--silent J]... [--counter-fault J:repeat]...
//       [--fault-onset SYNC] [--command-timeout ms] [--seed n] [--h s] [--max-gap s]
//       [--duration s] [--status s] [--no-faults] [--ignore-host-faults]
//       [--devices pedalwave|x_series [--torque-constant N·m/A] [--sensor-id-offset n]]
//
// The scene's `faults:` are injected inside the modules (vrobot::SimulationPlant: physical faults
// on the plant, sensor faults on what the modules report, module_silent as a module that stops
// answering; t = plant time) and listed at start and in the exit report; --no-faults ignores them.
// A host-side fault (stale, out_of_order, repeated_frame) is refused (exit 2) unless
// --ignore-host-faults.
//
// --pty prints "pty: /dev/pts/N" (and makes the --link symlink): give that path to the runtime's
// serial driver (driver.device). Plant time starts at the first SYNC. Prints what it did (frames,
// faults injected, plant time, COM distance) at exit. Exit codes: 0 done; 2 bad input (scene,
// option); 1 the transport could not be opened (e.g. no PF_CAN on this kernel).
#include <CLI/CLI.hpp>

#include "pedalwave/toolkit/cli.hpp"
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <string>
#include <thread>
#include <vector>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/drivers/canopen_emulator.hpp"
#include "pedalwave/model/integrators.hpp"
#include "pedalwave/vrobot/virtual_robot.hpp"

namespace {

std::atomic<int> g_signal{0};
extern "C" void on_signal(int s) { g_signal.store(s); }

int bad_input(const std::string& what) {
  std::cerr << "pedalwave_virtual_robot: error: " << what << '\n';
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  namespace vr = pedalwave::vrobot;
  namespace pd = pedalwave::drivers;

  CLI::App app{"pedalwave_virtual_robot: run a scene's plant model and answer as the robot's SEA "
               "modules would (drivers/PROTOCOL.md), on a CAN interface or a pseudo-terminal"};
  std::string scene_path, can_if, link;
  bool fd = false, pty = false, no_faults = false, ignore_host_faults = false;
  double latency_ms = 0.0, loss = 0.0, bit_error = 0.0, timeout_ms = 500.0, duration = 0.0,
         status_every = 0.0, max_gap = 1.0;
  // The bus the modules sit on (wire times) and their clocks.
  double bitrate = 1e6, data_bitrate = 5e6, return_delay_us = 20.0, drift_ppm = 30.0;
  int baud = 4'000'000, priority = 70, cpu = -1;
  bool no_wire = false;
  std::vector<int> silent;
  std::vector<std::string> counter_faults;
  std::uint64_t onset = 1;
  std::uint32_t seed = 1;
  double h = 0.0;
  // The serial bus's devices: pedalwave modules, or stock X-series servos + deflection sensors.
  std::string devices = "pedalwave";
  std::string protocol = "pedalwave";
  double torque_constant = 1.78;
  int sensor_id_offset = 100;
  app.add_option("--scene", scene_path, "scene file (YAML), e.g. config/scenes/flat_high_friction.yaml")
      ->required();
  auto* o_can = app.add_option("--can", can_if, "CAN interface the modules are on (e.g. vcan0, can0)");
  auto* o_pty = app.add_flag("--pty", pty, "serve a DYNAMIXEL 2.0 bus on a new pseudo-terminal; "
                             "prints its slave path");
  o_can->excludes(o_pty);
  app.add_flag("--fd", fd, "CAN FD frame set (command groups, FD replies); needs MTU 72");
  app.add_option("--link", link, "with --pty: also make this symlink to the slave path");
  app.add_option("--latency", latency_ms, "reply latency after SYNC / Sync Read [ms]")
      ->check(CLI::NonNegativeNumber)->capture_default_str();
  app.add_option("--loss", loss, "probability that a reply is not sent [0, 1]")
      ->check(CLI::Range(0.0, 1.0))->capture_default_str();
  app.add_option("--bit-error", bit_error, "probability that one bit of a reply is flipped [0, 1]")
      ->check(CLI::Range(0.0, 1.0))->capture_default_str();
  app.add_option("--silent", silent, "joint (1…N-1) whose module stops answering (repeatable)");
  app.add_option("--counter-fault", counter_faults,
                 "J:repeat or J:backwards — module J's echoed SYNC counter repeats / goes backwards");
  app.add_option("--fault-onset", onset, "faults act from this SYNC number on (1 = the first)")
      ->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--command-timeout", timeout_ms, "command lifetime before a module turns its "
                 "output off [ms]")->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--seed", seed, "random seed of the injected loss / bit errors")->capture_default_str();
  app.add_option("--max-gap", max_gap, "a SYNC gap longer than this is not integrated (the plant "
                 "waits while no host talks) [s]")->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--h", h, "integrator step override [s] (default: the scene's; a slow machine, "
                 "e.g. the emulated test VM, needs a larger step to integrate in real time)")
      ->check(CLI::PositiveNumber);
  app.add_flag("--no-faults", no_faults, "ignore the scene's `faults:` list");
  app.add_flag("--ignore-host-faults", ignore_host_faults, "skip the scene's host-side faults "
               "(stale, out_of_order, repeated_frame) instead of refusing the scene");
  app.add_option("--duration", duration, "stop after this long [s] (0 = until Ctrl-C)")
      ->check(CLI::NonNegativeNumber)->capture_default_str();
  app.add_option("--status", status_every, "print a progress line every this many seconds (0 = off)")
      ->check(CLI::NonNegativeNumber)->capture_default_str();
  app.add_option("--bitrate", bitrate, "CAN nominal bit rate, for the frames' wire time [bit/s]")
      ->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--data-bitrate", data_bitrate, "CAN FD data-phase bit rate [bit/s]")
      ->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--baud", baud, "serial baud rate, for the packets' wire time [bit/s]")
      ->check(CLI::Range(9600, 12'000'000))->capture_default_str();
  app.add_option("--return-delay", return_delay_us, "serial: each module's return delay [µs]")
      ->check(CLI::NonNegativeNumber)->capture_default_str();
  app.add_flag("--no-wire", no_wire, "frames take no wire time (answers as fast as the host reads)");
  app.add_option("--clock-drift", drift_ppm, "module clocks' rate errors, spread over ±this [ppm]")
      ->check(CLI::Range(0.0, 1000.0))->capture_default_str();
  app.add_option("--priority", priority, "SCHED_FIFO priority of the modules' thread (0 = normal "
                 "scheduling; real modules are separate microcontrollers: they never wait for the "
                 "host's CPU)")->check(CLI::Range(0, 99))->capture_default_str();
  app.add_option("--devices", devices, "with --pty: what sits on the bus — pedalwave modules, or "
                 "x_series: per joint a stock DYNAMIXEL X-series servo (XM430-W350, ID j) in current "
                 "control and a deflection sensor (ID j + --sensor-id-offset), drivers/PROTOCOL.md §3.6")
      ->check(CLI::IsMember({"pedalwave", "x_series"}))->capture_default_str();
  app.add_option("--torque-constant", torque_constant, "x_series: the servos' output torque per "
                 "current [N·m/A]")->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--sensor-id-offset", sensor_id_offset, "x_series: sensor ID = servo ID + this")
      ->check(CLI::Range(1, 251))->capture_default_str();
  app.add_option("--protocol", protocol, "with --can: what the modules speak — the pedalwave module "
                 "protocol, or canopen: CiA 301/402 drives (node ids 1…N-1, drivers/PROTOCOL.md §7, "
                 "drivers/canopen/pedalwave_module.eds)")
      ->check(CLI::IsMember({"pedalwave", "canopen"}))->capture_default_str();
  app.add_option("--cpu", cpu, "pin the modules' thread to this CPU (−1 = no pinning)")
      ->check(CLI::Range(-1, 1023))->capture_default_str();
  bool print_eds = false;
  app.add_flag("--print-eds", print_eds, "print the CANopen drives' EDS (CiA 306; the shipped "
               "drivers/canopen/pedalwave_module.eds) and exit; needs no other option");
  for (int i = 1; i < argc; ++i)  // before the parse: --scene is not needed for it
    if (std::string(argv[i]) == "--print-eds") {
      std::fputs(pedalwave::drivers::canopen::module_eds().c_str(), stdout);
      return 0;
    }
  if (const auto rc = pedalwave::toolkit::cli::parse(app, argc, argv, "pedalwave_virtual_robot")) return *rc;
  if (can_if.empty() && !pty) return bad_input("give the bus: --can IFNAME [--fd] or --pty");
  if (fd && pty) return bad_input("--fd is a CAN option; the serial bus (--pty) has no FD frames");
  const bool x_series = devices == "x_series";
  if (x_series && !pty) return bad_input("--devices x_series is a serial bus: give --pty");
  const bool canopen = protocol == "canopen";
  if (canopen && pty) return bad_input("--protocol canopen is a CAN option: give --can IFNAME");
  if (canopen && fd) return bad_input("--protocol canopen sends classic CAN frames: no --fd");

  pedalwave::model::Scene scene;
  try {
    scene = pedalwave::config::load_scene(scene_path);
  } catch (const std::exception& e) {
    return bad_input(e.what());
  }
  if (h > 0) scene.integrator.h = h;
  else if (!pedalwave::model::is_adaptive(scene.integrator.method))
    scene.integrator.h = std::min(scene.integrator.h, 1.25e-4);  // VirtualRobotOptions::max_step
  const int joints = scene.robot.N - 1;

  vr::VirtualRobotOptions opt;
  opt.bus = pty ? vr::Bus::kSerial : canopen ? vr::Bus::kCanOpen : vr::Bus::kCan;
  opt.emulator.fd = fd;
  opt.emulator.command_timeout_ns = static_cast<std::int64_t>(timeout_ms * 1e6);
  opt.emulator.bus = {!no_wire, bitrate, data_bitrate, baud, return_delay_us * 1e-6};
  opt.emulator.joints = joints;
  if (x_series) {
    opt.emulator.serial_devices = pd::SerialDevices::kXSeries;
    opt.emulator.x.torque_constant = torque_constant;
    opt.emulator.x.sensor_id_offset = sensor_id_offset;
    if (sensor_id_offset < joints || sensor_id_offset + joints > 252)
      return bad_input("--sensor-id-offset " + std::to_string(sensor_id_offset) +
                       ": expected the sensor IDs clear of the servos' 1 … " + std::to_string(joints) +
                       " and ≤ 252, i.e. " + std::to_string(joints) + " … " + std::to_string(252 - joints));
  }
  pd::spread_module_clocks(opt.emulator, drift_ppm, seed);
  opt.thread_priority = priority;
  opt.thread_cpu = cpu;
  opt.max_step = h > 0 ? h : 1.25e-4;
  pd::FaultConfig& f = opt.emulator.faults;
  f.reply_latency_ns = static_cast<std::int64_t>(latency_ms * 1e6);
  f.frame_loss = loss;
  f.bit_error = bit_error;
  f.onset_sync = onset;
  f.seed = seed;
  for (int j : silent) {
    if (j < 1 || j > joints)
      return bad_input("--silent " + std::to_string(j) + ": expected a joint 1…" + std::to_string(joints));
    f.module[static_cast<std::size_t>(j - 1)].silent = true;
  }
  for (const std::string& c : counter_faults) {
    const auto colon = c.find(':');
    int j = 0;
    try {
      j = colon == std::string::npos ? 0 : std::stoi(c.substr(0, colon));
    } catch (const std::exception&) {
      j = 0;
    }
    const std::string kind = colon == std::string::npos ? "" : c.substr(colon + 1);
    if (j < 1 || j > joints || (kind != "repeat" && kind != "backwards"))
      return bad_input("--counter-fault " + c + ": expected J:repeat or J:backwards with J in 1…" +
                       std::to_string(joints));
    f.module[static_cast<std::size_t>(j - 1)].counter =
        kind == "repeat" ? pd::CounterFault::kRepeat : pd::CounterFault::kBackwards;
  }
  opt.plant.max_gap = max_gap;
  opt.plant.record_period = 0;  // the CLI reports progress only
  opt.plant.apply_scene_faults = !no_faults;
  opt.plant.ignore_host_side_faults = ignore_host_faults;

  // The transport.
  int bus_fd = -1;
  vr::Pty p;
  try {
    if (pty) {
      p = vr::open_pty();
      bus_fd = p.master;
    } else {
      bus_fd = canopen ? vr::open_canopen_module_socket(can_if) : vr::open_module_can_socket(can_if, fd);
    }
  } catch (const std::exception& e) {
    std::cerr << "pedalwave_virtual_robot: " << e.what() << '\n';
    return 1;
  }
  std::unique_ptr<vr::VirtualRobot> robot;
  try {
    robot = std::make_unique<vr::VirtualRobot>(scene, bus_fd, opt);
  } catch (const std::exception& e) {
    if (p.slave_keep >= 0) ::close(p.slave_keep);
    return bad_input(e.what());
  }
  if (pty && !link.empty()) {
    ::unlink(link.c_str());
    if (::symlink(p.slave_path.c_str(), link.c_str()) != 0) {
      std::perror(("pedalwave_virtual_robot: symlink " + link).c_str());
      return 1;
    }
  }

  std::printf("virtual robot: scene '%s', %d modules (%s), integrator step %g s\n",
              scene.name.c_str(), joints,
              pty ? (x_series ? "serial, DYNAMIXEL 2.0, stock X-series servos in current control + deflection sensors"
                              : "serial, DYNAMIXEL 2.0")
                  : (fd ? "CAN FD" : "classic CAN"),
              scene.integrator.h);
  if (x_series)
    std::printf("x-series: servos XM430-W350 at IDs 1 … %d (shipped in position control), torque "
                "constant %g N·m/A; sensors at IDs %d … %d\n",
                joints, torque_constant, 1 + sensor_id_offset, joints + sensor_id_offset);
  if (pty) std::printf("pty: %s%s%s\n", p.slave_path.c_str(), link.empty() ? "" : " (link ", link.empty() ? "" : (link + ")").c_str());
  else std::printf("can: %s\n", can_if.c_str());
  if (no_wire) std::printf("bus: no wire time (answers as fast as the host reads)\n");
  else if (pty) std::printf("bus: %d baud, return delay %g µs, wire time modeled\n", baud, return_delay_us);
  else std::printf("bus: %g Mbit/s%s, wire time modeled\n", bitrate / 1e6,
                   fd ? (", data phase " + std::to_string(data_bitrate / 1e6).substr(0, 4) + " Mbit/s").c_str() : "");
  if (x_series)
    std::printf("stock servos: no module clock (a servo samples when the Bulk Read arrives), no "
                "command lifetime (a servo holds its Goal Current until told)\n");
  else
    std::printf("module clocks: free-running µs counters, rate errors spread over ±%g ppm; command "
                "lifetime %g ms\n", drift_ppm, timeout_ms);
  {
    std::string applied, skipped;
    for (const pedalwave::model::FaultSpec& sf : robot->plant().faults())
      applied += (applied.empty() ? "" : "; ") + vr::describe(sf);
    for (const pedalwave::model::FaultSpec& sf : robot->plant().skipped_faults())
      skipped += (skipped.empty() ? "" : "; ") + vr::describe(sf);
    if (!applied.empty()) std::printf("faults (inside the modules): %s\n", applied.c_str());
    if (!skipped.empty())
      std::printf("faults not injected (%s): %s\n",
                  no_faults ? "--no-faults" : "host-side, --ignore-host-faults", skipped.c_str());
  }
  std::printf("waiting for the host's SYNC; Ctrl-C to stop\n");
  std::fflush(stdout);

  std::signal(SIGINT, on_signal);
  std::signal(SIGTERM, on_signal);
  robot->start();
  if (!robot->thread_note().empty()) std::printf("%s\n", robot->thread_note().c_str());
  const auto t0 = std::chrono::steady_clock::now();
  auto next_status = t0 + std::chrono::duration<double>(status_every);
  while (g_signal.load() == 0) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    const auto now = std::chrono::steady_clock::now();
    if (duration > 0 && now - t0 >= std::chrono::duration<double>(duration)) break;
    if (status_every > 0 && now >= next_status) {
      next_status += std::chrono::duration<double>(status_every);
      const vr::PlantProgress pr = robot->plant().progress();
      std::printf("  t = %.2f s, COM x = %.4f m, SYNCs %llu, replies %llu, commands %llu%s\n", pr.t,
                  pr.com_x, static_cast<unsigned long long>(robot->stats().syncs.load()),
                  static_cast<unsigned long long>(robot->stats().replies_sent.load()),
                  static_cast<unsigned long long>(robot->stats().commands.load()),
                  pr.all_off ? " (outputs off)" : "");
      std::fflush(stdout);
    }
  }
  robot->stop();
  const vr::PlantProgress pr = robot->plant().progress();
  std::printf("%s", robot->report().c_str());
  if (pr.t > 0)
    std::printf("  COM moved %.4f m in %.2f s of plant time: %.3f cm/s on average\n",
                pr.com_x - pr.com_x0, pr.t, 100.0 * (pr.com_x - pr.com_x0) / pr.t);
  if (p.slave_keep >= 0) ::close(p.slave_keep);
  if (pty && !link.empty()) ::unlink(link.c_str());
  return 0;
}
