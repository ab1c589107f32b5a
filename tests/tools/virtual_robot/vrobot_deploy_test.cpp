// The deployment path (issue 12), as a robot runs it: the free-running runtime daemon with its
// real serial driver over a pty to the virtual robot (the scene's plant behind the DYNAMIXEL
// module emulator, wire times at 4 Mbaud, module clocks drifting ±30 ppm, commands applied on
// arrival), SCHED_FIFO for the loop (80) and for the modules' thread (70), memory locked, the
// daemon's derived timeouts, the onboard observer ON and DDS telemetry ON (loopback), under a
// background CPU load of one busy process per CPU.
//
//  - Walks 60 s with no event of any class (fault, warning, hold) and a forward speed within 10 %
//    of the in-process simulated plant's (the same controller in lockstep).
//  - Detects and isolates, over the bus, torque loss, a broken spring, a stuck encoder, an encoder
//    offset jump, a deflection-sensor bias and a silent module, each on the joint it was injected
//    on (faults applied inside the virtual robot's modules: the scene's `faults:` list).
// A machine that refuses SCHED_FIFO runs the same tests at normal priority and says so loudly.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstdio>
#include <string>
#include <vector>

#include "dds_domain_lease.hpp"
#include "pedalwave/runtime/run_events.hpp"
#include "pedalwave/toolkit/cpu_load.hpp"
#include "walk_rig.hpp"

using namespace pedalwave;
using test::Transport;
using test::WalkResult;
using test::WalkSetup;

namespace {

const model::Scene& scene() {
  static const model::Scene s = config::load_scene(test::kScenePath);
  return s;
}

int cpus() {
  const long n = ::sysconf(_SC_NPROCESSORS_ONLN);
  return n > 0 ? static_cast<int>(n) : 1;
}

// The robot's configuration: serial at 500 Hz (5 joints at 4 Mbaud fit there), derived timeouts.
WalkSetup deployment(double duration, std::uint32_t domain) {
  WalkSetup s;
  s.transport = Transport::kSerial;
  s.rate_hz = 500;
  s.duration = duration;
  s.stale_timeout = 0;  // the daemon's derived default
  s.read_budget = 0;    // the daemon's derived default
  s.command_timeout = 0.5;
  s.observer = true;
  s.priority = 80;
  s.robot_priority = 70;
  s.telemetry = true;
  s.telemetry_domain = domain;
  s.clock_drift_ppm = 30;
  return s;
}

std::string events_text(const WalkResult& r) {
  std::string t;
  for (const runtime::RunEvent& e : r.daemon.events)
    if (e.listed) t += "  " + runtime::format_event_short(e, r.daemon.event_log) + "\n";
  return t;
}

int listed(const WalkResult& r) {
  int n = 0;
  for (const runtime::RunEvent& e : r.daemon.events) n += e.listed ? 1 : 0;
  return n;
}

void print(const char* what, const WalkResult& r, double v_sim) {
  std::printf("[deploy] %s: %s\n  speed %.4f cm/s (in-process plant %.4f cm/s, %+.2f %%), plant "
              "%.2f s, cycles %llu, overruns %llu, host missing %llu, late %llu (used %llu); %s\n"
              "  link: modules' longest SYNC gap %.1f ms, host's longest silence %.1f ms; loop's "
              "longest stall %u periods; modules' thread held ≥ 20 ms %llu time(s), %.1f ms in "
              "all; plant kept at wall time %llu time(s)\n",
              what, r.daemon.exit_line.c_str(), 100 * r.speed, 100 * v_sim,
              100 * (r.speed - v_sim) / v_sim, r.plant_t,
              static_cast<unsigned long long>(r.daemon.run.cycles),
              static_cast<unsigned long long>(r.daemon.run.overruns),
              static_cast<unsigned long long>(r.counters.missing),
              static_cast<unsigned long long>(r.counters.late),
              static_cast<unsigned long long>(r.counters.late_used), r.robot_thread.c_str(),
              1e-6 * static_cast<double>(r.emu.sync_gap_max_ns),
              1e-6 * static_cast<double>(r.counters.rx_silence_max_ns), r.daemon.run.max_skipped,
              static_cast<unsigned long long>(r.emu.self_stalls),
              1e-6 * static_cast<double>(r.emu.self_stall_ns),
              static_cast<unsigned long long>(r.emu.keep_ups));
  std::fflush(stdout);
}

void say_if_not_realtime(const WalkResult& r) {
  if (r.robot_thread.find("refused") != std::string::npos || !r.daemon.run.rt.priority_granted)
    std::printf("######## NOTE: SCHED_FIFO was refused here (%s; loop: %s): the deployment tests "
                "ran at normal priority ########\n",
                r.robot_thread.c_str(), r.daemon.run.rt.describe().c_str());
}

}  // namespace

TEST(Deployment, SerialPtyWalks60sObserverAndTelemetryOnUnderCpuLoad) {
  test::DomainLease lease;
  const WalkSetup s = deployment(60, lease.id());
  WalkSetup ref = s;
  ref.telemetry = false;
  const WalkResult sim = test::walk_sim(ref, scene());  // the same loop in lockstep, in-process
  toolkit::CpuLoad load;
  int void_runs = 0;
  const WalkResult bus = test::walk_unless_machine_stalled("60 s walk", s.rate_hz, void_runs, [&] {
    load.start(cpus());
    WalkResult r = test::walk_bus(s, scene());
    load.stop();
    return r;
  });
  print("serial pty 500 Hz, 60 s, observer + telemetry, CPU load", bus, sim.speed);
  std::printf("[deploy] void runs (machine stalls ≥ %.0f ms): %d\n", 1e3 * test::kMachineStall,
              void_runs);
  EXPECT_LT(test::stall_of(bus, s.rate_hz).worst(), test::kMachineStall)
      << "the machine stalled the loop in every attempt";
  std::printf("%s%s", bus.report.c_str(), events_text(bus).c_str());
  say_if_not_realtime(bus);
  EXPECT_GT(load.cpu_seconds(), 0.5 * 60 * (1 + void_runs))
      << "the load generator did load the machine";
  EXPECT_EQ(bus.daemon.run.reason, runtime::ExitReason::kCycleLimit);
  EXPECT_EQ(bus.daemon.run.fault, runtime::FaultClass::kNone) << runtime::to_string(bus.daemon.run.fault);
  EXPECT_EQ(listed(bus), 0) << "no fault, warning or hold event:\n" << events_text(bus);
  EXPECT_EQ(bus.daemon.run.cycles, 30000u);
  EXPECT_TRUE(bus.daemon.telemetry_active);
  EXPECT_GE(bus.plant_t, 59.9);
  EXPECT_TRUE(bus.all_modules_off) << "safe stop: torque off reached every module";
  EXPECT_EQ(bus.emu.lifetime_expired, 0u);
  ASSERT_TRUE(std::isfinite(bus.speed));
  EXPECT_NEAR(bus.speed, sim.speed, 0.10 * sim.speed);
}

struct BusFault {
  model::FaultType type;
  int joint;          // 0-based
  double value;
  runtime::FaultClass expect;
  const char* name;
};

void PrintTo(const BusFault& f, std::ostream* os) { *os << f.name << " on joint " << f.joint + 1; }

class DeploymentFaults : public ::testing::TestWithParam<BusFault> {};

// Three injections per fault class, each on another joint at another onset (3.0, 4.5, 6.0 s: the
// observer settled, the gait in its second to fourth period); runs of onset + 6 s: residual classes
// need ≈ 2.5 s (a gait period of fit), data checks a few cycles. Each must be detected after its
// onset, within 4 s, and isolated to the injected class and joint (every trial, see the end);
// a stop-severity fault must put the safe command on the bus within 2 cycles. Prints one row of
// the README's over-the-bus table.
TEST_P(DeploymentFaults, DetectedAndIsolatedOverTheBus) {
  const BusFault f = GetParam();
  constexpr int kTrials = 3;
  int isolated = 0, false_alarms = 0, void_runs = 0;
  std::vector<double> latency_ms;
  for (int k = 0; k < kTrials; ++k) {
    const int joint = (f.joint + 2 * k) % 5;
    const double onset = 3.0 + 1.5 * k;
    test::DomainLease lease;
    const WalkSetup s = deployment(onset + 6.0, lease.id());
    model::Scene sc = scene();
    sc.faults.push_back({.type = f.type, .joint = joint, .t_start = onset, .value = f.value});
    char what[96];
    std::snprintf(what, sizeof what, "%s on joint %d from %.1f s", f.name, joint + 1, onset);
    const WalkResult bus = test::walk_unless_machine_stalled(what, s.rate_hz, void_runs, [&] {
      toolkit::CpuLoad load;
      load.start(cpus());
      WalkResult r = test::walk_bus(s, sc);
      load.stop();
      return r;
    });
    EXPECT_LT(test::stall_of(bus, s.rate_hz).worst(), test::kMachineStall)
        << what << ": the machine stalled the loop in every attempt";
    print(what, bus, bus.speed);
    std::printf("%s", events_text(bus).c_str());
    say_if_not_realtime(bus);
    // The first fault event names the injected class on the injected joint, after the onset.
    const runtime::RunEvent* first = nullptr;
    for (const runtime::RunEvent& e : bus.daemon.events)
      if (e.listed && e.sample.fault != runtime::FaultClass::kNone) {
        first = &e;
        break;
      }
    if (first == nullptr) {
      ADD_FAILURE() << what << ": not detected\n" << bus.daemon.summary;
      continue;
    }
    const double t = bus.daemon.event_log.seconds(first->sample);
    if (first->sample.fault != f.expect || first->sample.joint != joint)
      std::printf("[deploy] %s: isolated as %s on joint %d\n", what,
                  runtime::to_string(first->sample.fault), first->sample.joint + 1);
    // A verdict before the onset is a false alarm on the healthy bus. Seen once in about 40
    // trials before the modules' clock estimate slewed at 20 ppm instead of 1000 ppm
    // (drivers/module_clock.hpp): actuator_torque on another joint at 2.55 s, the residual above
    // half its threshold for 30 % of the 2 s window from 0.55 s — the start-up signature of the
    // converging estimate (BusModel.TheModulesClockEstimateConvergingAt100HzIsNoFault).
    if (t < onset) {
      ++false_alarms;
      std::printf("######## FINDING: %s: a false alarm before the onset, %s at %.2f s ########\n",
                  what, runtime::format_event_short(*first, bus.daemon.event_log).c_str(), t);
      continue;
    }
    EXPECT_LE(t, onset + 4.0) << what << ": detected within 4 s of the onset";
    if (first->sample.fault == f.expect && first->sample.joint == joint) {
      ++isolated;
      latency_ms.push_back(1e3 * (t - onset));
    }
    // A stop-severity fault ends in the safe stop: the torque-off reaches every module within 2
    // cycles of the detection (cycle k sent SYNC k+1; the safe stop goes out in cycle k itself).
    if (bus.daemon.run.reason == runtime::ExitReason::kFault) {
      EXPECT_TRUE(bus.all_modules_off);
      EXPECT_EQ(bus.daemon.run.fault_joint, joint);
      EXPECT_GT(bus.emu.first_off_sync, 0u);
      EXPECT_LE(bus.emu.first_off_sync, first->sample.seq + 1 + 2)
          << "safe command on the bus " << bus.emu.first_off_sync - (first->sample.seq + 1)
          << " cycles after the detection";
    }
  }
  std::sort(latency_ms.begin(), latency_ms.end());
  std::printf("[deploy-table] | %s | %s | %d/%d | %.0f / %.0f | %d |\n", f.name,
              runtime::to_string(f.expect), isolated, kTrials,
              latency_ms.empty() ? NAN : latency_ms[latency_ms.size() / 2],
              latency_ms.empty() ? NAN : latency_ms.back(), void_runs);
  // Every trial isolated to class and joint, no false alarm (the rows used to allow one miss and
  // one false alarm in three: the start-up excursion of the clock estimate's 1000 ppm slew).
  EXPECT_EQ(false_alarms, 0) << f.name;
  EXPECT_EQ(isolated, kTrials) << f.name;
}

INSTANTIATE_TEST_SUITE_P(
    SerialPty, DeploymentFaults,
    ::testing::Values(
        BusFault{model::FaultType::kTorqueGain, 2, 0.0, runtime::FaultClass::kActuatorTorque, "torque_loss"},
        BusFault{model::FaultType::kSpringScale, 1, 0.2, runtime::FaultClass::kSpringBroken, "broken_spring"},
        BusFault{model::FaultType::kEncoderStuck, 3, 0.0, runtime::FaultClass::kEncoderStuck, "encoder_stuck"},
        BusFault{model::FaultType::kEncoderOffset, 0, 0.02, runtime::FaultClass::kEncoderJump, "encoder_jump"},
        BusFault{model::FaultType::kDeflectionBias, 2, 0.05, runtime::FaultClass::kDeflectionBias, "deflection_bias"},
        BusFault{model::FaultType::kModuleSilent, 4, 0.0, runtime::FaultClass::kModuleSilent, "silent_module"}),
    [](const auto& param_info) { return std::string(param_info.param.name); });

