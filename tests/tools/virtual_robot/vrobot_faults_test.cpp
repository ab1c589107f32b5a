// The scene's faults inside the virtual robot's modules (SimulationPlant): sensor faults on what
// measure() reports are exactly drivers::FaultInjector's on the clean measurement, physical faults
// are in the plant's PlantFaults while active and healed after, module_silent silences the module
// (answering(), and end to end through the CAN module emulator over a socket pair), host-side
// faults are refused by name; measure()/advance_to() allocate nothing with faults active.
#include <gtest/gtest.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <system_error>
#include <thread>

#include "alloc_counter.hpp"
#include "pedalwave/drivers/can_protocol.hpp"
#include "pedalwave/drivers/fault_injector.hpp"
#include "pedalwave/vrobot/virtual_robot.hpp"

using namespace pedalwave;
using model::FaultSpec;
using model::FaultType;

namespace {

constexpr std::int64_t kOrigin = 1'000'000'000;  // the first SYNC's time [ns]
constexpr std::int64_t kPeriod = 1'000'000;      // SYNC period [ns]

model::Scene scene_with(const std::vector<FaultSpec>& faults) {
  model::Scene s;
  s.initial.pose = model::InitialPose::kGaitStart;
  s.integrator.h = 5e-4;
  s.faults = faults;
  return s;
}

FaultSpec fault(FaultType type, int joint, double t_start, double value, double duration) {
  FaultSpec f;
  f.type = type;
  f.joint = joint;
  f.t_start = t_start;
  f.value = value;
  f.duration = duration;
  return f;
}

// A moving robot: the module PD tracks a travelling wave.
drivers::Command wave(double t, int joints) {
  drivers::Command c{};
  c.joints = joints;
  for (int j = 0; j < joints; ++j) {
    const auto k = static_cast<std::size_t>(j);
    c.beta_ref[k] = 0.5 * std::sin(3 * t + j);
    c.beta_dot_ref[k] = 1.5 * std::cos(3 * t + j);
    c.kp[k] = 30;
    c.kd[k] = 15;
  }
  return c;
}

// One SYNC as the module bank does it: command, integrate to the SYNC, sample.
drivers::Feedback sync(vrobot::SimulationPlant& p, int k) {
  p.apply(wave(k * 1e-3, p.joints()));
  p.advance_to(kOrigin + k * kPeriod);
  drivers::Feedback fb{};
  p.measure(fb);
  return fb;
}

// Bitwise equality of the reported channels (NaN == NaN).
bool same(const drivers::Feedback& a, const drivers::Feedback& b, int joints) {
  const auto n = static_cast<std::size_t>(joints) * sizeof(double);
  return std::memcmp(a.beta.data(), b.beta.data(), n) == 0 &&
         std::memcmp(a.beta_dot.data(), b.beta_dot.data(), n) == 0 &&
         std::memcmp(a.deflection.data(), b.deflection.data(), n) == 0 &&
         std::memcmp(a.status.data(), b.status.data(), static_cast<std::size_t>(joints) * 2) == 0;
}

TEST(VrobotFaults, SensorFaultsInMeasureAreTheInjectorsOnTheCleanMeasurement) {
  for (FaultType type : {FaultType::kEncoderStuck, FaultType::kEncoderOffset, FaultType::kEncoderNoise,
                         FaultType::kDeflectionStuck, FaultType::kDeflectionBias,
                         FaultType::kDeflectionScale, FaultType::kNaN, FaultType::kImplausible}) {
    SCOPED_TRACE(std::string(model::to_string(type)));
    const FaultSpec f = fault(type, 2, 0.010, type == FaultType::kDeflectionScale ? 1.7 : 0.05, 0.020);
    vrobot::SimulationPlant faulty(scene_with({f}));
    vrobot::PlantOptions off;
    off.apply_scene_faults = false;
    vrobot::SimulationPlant clean(scene_with({f}), off);
    ASSERT_EQ(faulty.faults().size(), 1u);
    ASSERT_TRUE(clean.faults().empty());
    ASSERT_EQ(clean.skipped_faults().size(), 1u);
    drivers::FaultInjector ref(clean.joints(), true);
    ref.add(f);

    int changed = 0;
    for (int k = 0; k < 40; ++k) {
      const drivers::Feedback got = sync(faulty, k);
      drivers::Feedback want = sync(clean, k);
      const double t = clean.progress().t;
      ASSERT_EQ(t, faulty.progress().t);
      const bool active = t >= f.t_start && t < f.t_start + f.duration;
      const drivers::Feedback truth = want;
      ref.apply_sensors(t, want);
      EXPECT_TRUE(same(got, want, faulty.joints())) << "k = " << k << ", t = " << t;
      if (!active) {
        EXPECT_TRUE(same(got, truth, faulty.joints())) << "no effect at t = " << t;
      }
      if (active && !same(got, truth, faulty.joints())) ++changed;
    }
    EXPECT_GT(changed, 5) << "the fault changed the report while active";
    // The module's own loop used the true signals: the faulty plant moved exactly as the clean one.
    EXPECT_TRUE(faulty.sim().q() == clean.sim().q());
    EXPECT_NEAR(faulty.fault_onset(0), f.t_start, 1e-9);
  }
}

TEST(VrobotFaults, PhysicalFaultsActOnThePlantWhileActiveAndAreHealedAfter) {
  for (FaultType type : {FaultType::kTorqueGain, FaultType::kMotorFriction, FaultType::kSpringScale,
                         FaultType::kJointLoad}) {
    SCOPED_TRACE(std::string(model::to_string(type)));
    const FaultSpec f = fault(type, 1, 0.010, 0.3, 0.010);
    vrobot::SimulationPlant p(scene_with({f}));
    const model::PlantFaults& pf = p.sim().plant().faults();
    auto field = [&] {
      switch (type) {
        case FaultType::kTorqueGain: return pf.torque_gain(1);
        case FaultType::kMotorFriction: return pf.motor_friction(1);
        case FaultType::kSpringScale: return pf.spring_scale(1);
        default: return pf.joint_load(1);
      }
    };
    const double healthy = field();
    EXPECT_TRUE(healthy == 0.0 || healthy == 1.0);
    int active_advances = 0;
    sync(p, 0);  // plant time 0
    for (int k = 1; k < 40; ++k) {
      const double t_begin = p.progress().t;  // the advance starts here
      sync(p, k);
      const bool active = t_begin >= f.t_start && t_begin < f.t_start + f.duration;
      EXPECT_EQ(field(), active ? f.value : healthy) << "advance from t = " << t_begin;
      active_advances += active;
      // Only this joint, only this field.
      EXPECT_EQ(pf.torque_gain(0), 1.0);
      EXPECT_EQ(pf.spring_scale(3), 1.0);
    }
    EXPECT_GE(active_advances, 9);
    EXPECT_LE(active_advances, 11);
    EXPECT_NEAR(p.fault_onset(0), f.t_start, 1e-9);
  }
}

TEST(VrobotFaults, AFaultBeyondTheRunNeverActs) {
  vrobot::SimulationPlant p(scene_with({fault(FaultType::kTorqueGain, 0, 5.0, 0.0, 1.0),
                                        fault(FaultType::kEncoderOffset, 0, 5.0, 0.1, 1.0)}));
  for (int k = 0; k < 20; ++k) sync(p, k);
  EXPECT_TRUE(std::isnan(p.fault_onset(0)));
  EXPECT_TRUE(std::isnan(p.fault_onset(1)));
  EXPECT_EQ(p.sim().plant().faults().torque_gain(0), 1.0);
}

TEST(VrobotFaults, ModuleSilentStopsAnsweringFromOnsetToEnd) {
  const FaultSpec f = fault(FaultType::kModuleSilent, 3, 0.010, 0.0, 0.010);
  vrobot::SimulationPlant p(scene_with({f}));
  for (int k = 0; k < 40; ++k) {
    sync(p, k);
    const double t = p.progress().t;
    const bool active = t >= f.t_start && t < f.t_start + f.duration;
    EXPECT_EQ(p.answering(3), !active) << "t = " << t;
    for (int j : {0, 1, 2, 4}) EXPECT_TRUE(p.answering(j));
  }
  EXPECT_NEAR(p.fault_onset(0), f.t_start, 1e-9);
}

TEST(VrobotFaults, MeasureAndAdvanceAllocateNothingWithFaultsActive) {
  vrobot::SimulationPlant p(scene_with({fault(FaultType::kEncoderNoise, 0, 0.0, 0.01, 1.0),
                                        fault(FaultType::kEncoderStuck, 1, 0.005, 0.0, 1.0),
                                        fault(FaultType::kTorqueGain, 2, 0.005, 0.5, 0.01),
                                        fault(FaultType::kModuleSilent, 3, 0.005, 0.0, 1.0)}));
  sync(p, 0);
  sync(p, 1);
  const drivers::Command c = wave(0.0, p.joints());
  drivers::Feedback fb{};
  bool answering = true;
  test::AllocationScope scope;
  for (int k = 2; k < 40; ++k) {
    p.apply(c);
    p.advance_to(kOrigin + k * kPeriod);
    p.measure(fb);
    answering &= p.answering(3);
  }
  EXPECT_EQ(scope.count(), 0u);
  EXPECT_FALSE(answering);
}

TEST(VrobotFaults, HostSideFaultsAreRefusedByNameUnlessIgnored) {
  for (FaultType type : {FaultType::kStale, FaultType::kOutOfOrder, FaultType::kRepeatedFrame}) {
    const std::string name(model::to_string(type));
    SCOPED_TRACE(name);
    const model::Scene s = scene_with({fault(FaultType::kEncoderOffset, 0, 1.0, 0.1, 1.0),
                                       fault(type, 2, 1.0, 2.0, 1.0)});
    try {
      vrobot::SimulationPlant p(s);
      FAIL() << "accepted a host-side fault";
    } catch (const std::invalid_argument& e) {
      const std::string what = e.what();
      EXPECT_NE(what.find("faults[1]"), std::string::npos) << what;
      EXPECT_NE(what.find(name), std::string::npos) << what;
      EXPECT_NE(what.find("counter"), std::string::npos) << what;
    }
    vrobot::PlantOptions o;
    o.ignore_host_side_faults = true;
    vrobot::SimulationPlant p(s, o);
    ASSERT_EQ(p.faults().size(), 1u);
    EXPECT_EQ(p.faults()[0].type, FaultType::kEncoderOffset);
    ASSERT_EQ(p.skipped_faults().size(), 1u);
    EXPECT_EQ(p.skipped_faults()[0].type, type);
  }
}

TEST(VrobotFaults, InvalidFaultsAreRefusedWithTheirIndex) {
  try {
    vrobot::SimulationPlant p(scene_with({fault(FaultType::kNaN, 0, 0.0, 0.0, 1.0),
                                          fault(FaultType::kSpringScale, 7, 0.0, 0.2, 1.0)}));
    FAIL();
  } catch (const std::invalid_argument& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("faults[1]"), std::string::npos) << what;
    EXPECT_NE(what.find("joint = 7"), std::string::npos) << what;
  }
}

TEST(VrobotFaults, DescribeIsOneBasedAndReadable) {
  EXPECT_EQ(vrobot::describe(fault(FaultType::kEncoderStuck, 2, 4.0, 0.0, INFINITY)),
            "encoder_stuck on joint 3 from 4.0 s");
  EXPECT_EQ(vrobot::describe(fault(FaultType::kTorqueGain, 1, 1.5, 0.25, 2.0)),
            "torque_gain 0.25 on joint 2 from 1.5 s for 2.0 s");
}

// ---- End to end: the CAN module emulator over a socket pair ----------------------------------

// Sends `n` SYNCs (classic CAN records) and counts the feedback frames per node that arrive
// until the bus has been quiet for 200 ms.
std::array<int, drivers::kMaxJoints + 1> syncs_and_replies(int fd, int n, std::uint8_t& counter) {
  namespace can = drivers::can;
  for (int i = 0; i < n; ++i) {
    can_frame f{};
    can::encode_sync(counter++, f);
    if (::send(fd, &f, sizeof f, MSG_NOSIGNAL) != static_cast<ssize_t>(sizeof f))
      throw std::system_error(errno, std::generic_category(), "send SYNC");
  }
  std::array<int, drivers::kMaxJoints + 1> per_node{};
  pollfd pf{fd, POLLIN, 0};
  while (::poll(&pf, 1, 200) > 0) {
    can_frame f{};
    if (::recv(fd, &f, sizeof f, 0) <= 0) break;
    const canid_t id = f.can_id & CAN_SFF_MASK;
    if (id > can::kFeedbackBase && id <= can::kFeedbackBase + drivers::kMaxJoints)
      ++per_node[id - can::kFeedbackBase];
  }
  return per_node;
}

TEST(VrobotFaults, ModuleSilentSilencesTheEmulatedCanModule) {
  // Joint 2 = node 3, silent from 0.2 s to 0.5 s of plant time (time since the first SYNC).
  const model::Scene s = scene_with({fault(FaultType::kModuleSilent, 2, 0.2, 0.0, 0.3)});
  int sv[2];
  ASSERT_EQ(::socketpair(AF_UNIX, SOCK_SEQPACKET | SOCK_CLOEXEC, 0, sv), 0);
  vrobot::VirtualRobotOptions o;
  o.bus = vrobot::Bus::kCan;
  vrobot::VirtualRobot robot(s, sv[0], o);
  robot.start();
  std::uint8_t counter = 1;
  const auto t0 = std::chrono::steady_clock::now();
  const auto before = syncs_and_replies(sv[1], 5, counter);  // plant time ≈ 0
  std::this_thread::sleep_until(t0 + std::chrono::milliseconds(300));
  const auto during = syncs_and_replies(sv[1], 5, counter);  // plant time ≥ 0.3 s
  std::this_thread::sleep_until(t0 + std::chrono::milliseconds(700));
  const auto after = syncs_and_replies(sv[1], 5, counter);   // plant time ≥ 0.7 s
  robot.stop();
  ::close(sv[1]);
  for (int node = 1; node <= 5; ++node) {
    SCOPED_TRACE("node " + std::to_string(node));
    EXPECT_EQ(before[static_cast<std::size_t>(node)], 5);
    EXPECT_EQ(during[static_cast<std::size_t>(node)], node == 3 ? 0 : 5);
    EXPECT_EQ(after[static_cast<std::size_t>(node)], 5);
  }
  EXPECT_EQ(robot.stats().replies_dropped.load(), 5u);
  const std::string report = robot.report();
  EXPECT_NE(report.find("module_silent on joint 3 from 0.2 s for 0.3 s: active from"),
            std::string::npos) << report;
}

}  // namespace
