// The simulated-plant driver and the lockstep closed loop: deterministic, equal to a direct
// formulation of the same experiment, a command watchdog, a free-running mode, no allocation.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <thread>

#include "alloc_counter.hpp"
#include "pedalwave/config/scene.hpp"
#include "pedalwave/simloop/closed_loop.hpp"

using namespace pedalwave;

namespace {
model::Scene flat() {
  return config::load_scene(PEDALWAVE_CONFIG_DIR "/scenes/flat_high_friction.yaml");
}
double com_x(model::Simulation& sim) {
  auto& p = sim.plant();
  model::update_kinematics(p.model(), p.data(), sim.q(), sim.v());
  return model::center_of_mass(p.model(), p.data(), sim.q()).x();
}
}  // namespace

TEST(SimDriver, LockstepIsBitReproducible) {
  const model::Scene s = flat();
  simloop::ClosedLoop a(s, {}), b(s, {});
  for (int k = 0; k < 2000; ++k) {
    ASSERT_EQ(a.step(), model::StepStatus::kOk);
    ASSERT_EQ(b.step(), model::StepStatus::kOk);
  }
  EXPECT_EQ(a.t(), b.t());
  for (int i = 0; i < a.sim().q().size(); ++i) {
    EXPECT_EQ(a.sim().q()(i), b.sim().q()(i));  // bit-identical, not just close
    EXPECT_EQ(a.sim().v()(i), b.sim().v()(i));
  }
}

// The controller (k_c = 0, module-side PD) through the driver gives the same motion as writing
// the paper's gait straight into the plant's actuator input: two formulations, one answer.
TEST(SimDriver, ClosedLoopEqualsTheDirectFormulation) {
  const model::Scene s = flat();
  simloop::ClosedLoop loop(s, {.rate_hz = 1000, .controller = true, .k_c = 0.0});
  model::Simulation direct(s);
  auto& in = direct.plant().input();
  in.kp.setConstant(30);
  in.kd.setConstant(15);
  const double T = 3.0, dt = 1e-3;
  for (int k = 0; k * dt < T - 1e-9; ++k) {
    const double t = k * dt;
    for (int j = 0; j < 5; ++j) {
      const double ph = s.gait.omega * t + s.gait.eta * j;
      in.beta_ref(j) = s.gait.A_p * std::sin(ph);
      in.beta_dot_ref(j) = s.gait.A_p * s.gait.omega * std::cos(ph);
    }
    ASSERT_EQ(direct.advance_to(t + dt), model::StepStatus::kOk);
    ASSERT_EQ(loop.step(), model::StepStatus::kOk);
  }
  EXPECT_NEAR(loop.t(), direct.t(), 1e-12);
  EXPECT_LT((loop.sim().q() - direct.q()).cwiseAbs().maxCoeff(), 1e-9);
  // And the robot walks forward (+X: the head leads).
  EXPECT_GT(com_x(loop.sim()), 0.02);
}

TEST(SimDriver, WatchdogDropsTorqueWhenCommandsStop) {
  model::Scene s = flat();
  drivers::SimDriver d(s, {.clock = drivers::SimClock::kFreeRunning, .period = 1e-3, .command_timeout = 0.02});
  drivers::Command cmd{};
  cmd.joints = d.joints();
  cmd.kp.fill(30);
  cmd.kd.fill(15);
  d.start();
  drivers::Feedback fb{};
  // Commands flow for a while, then stop.
  for (int k = 0; k < 30; ++k) {
    d.write(cmd);
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  d.read(0, 0, fb);
  EXPECT_EQ(fb.status[0] & drivers::kStatusTorqueOff, 0);
  std::this_thread::sleep_for(std::chrono::milliseconds(200));  // ≫ command_timeout
  ASSERT_EQ(d.read(0, 0, fb), drivers::IoStatus::kOk);
  EXPECT_NE(fb.status[0] & drivers::kStatusTorqueOff, 0) << "modules must drop to torque off";
  d.stop();
  EXPECT_TRUE(d.torque_off_by_watchdog());
  EXPECT_GT(d.sim().t(), 0.05) << "the free-running plant advances with the wall clock";
}

// Lockstep under wake-up latency: the plant's time follows the loop's scheduled times
// (begin_cycle), so a cycle that wakes 1.06 periods late still sees exactly one period of plant
// motion, and a cycle after a skipped period sees two — what the loop's deadline-based dt says.
// (Inferring the skip from the wake-up times alone put the extra period one cycle early, and the
// observer then saw a spike: the demo's spurious encoder_jump after an overrun.)
TEST(SimDriver, LockstepFollowsTheScheduledTimeNotTheWakeUp) {
  drivers::SimDriver d(flat(), {});
  drivers::Command cmd{};
  cmd.joints = d.joints();
  cmd.kp.fill(30);
  cmd.kd.fill(15);
  drivers::Feedback fb{};
  constexpr std::int64_t T = 1'000'000, base = 5'000'000'000;
  struct Cycle { std::int64_t scheduled, wake; };
  const Cycle cycles[] = {{base, base + 10'000},           // on time
                          {base + T, base + T + 1'060'000},  // 1.06 periods late
                          {base + 3 * T, base + 3 * T + 20'000},  // the loop skipped base + 2T
                          {base + 4 * T, base + 4 * T + 900'000}};
  std::int64_t stamp0 = 0;
  for (const Cycle& c : cycles) {
    d.begin_cycle(c.scheduled);
    ASSERT_EQ(d.read(c.wake, c.wake + T / 2, fb), drivers::IoStatus::kOk);
    if (c.scheduled == base) stamp0 = fb.stamp_ns;
    EXPECT_EQ(fb.stamp_ns - stamp0, c.scheduled - base) << "plant time must equal the loop's scheduled time";
    d.write(cmd);
  }
}

TEST(SimDriver, SafeStopTurnsTorqueOff) {
  model::Scene s = flat();
  drivers::SimDriver d(s, {});
  d.safe_stop();
  drivers::Feedback fb{};
  d.read(0, 0, fb);
  for (int j = 0; j < d.joints(); ++j) EXPECT_NE(fb.status[static_cast<size_t>(j)] & drivers::kStatusTorqueOff, 0);
  // A command after the safe stop does not switch the torque back on.
  drivers::Command cmd{};
  cmd.joints = d.joints();
  cmd.tau.fill(0.5);
  d.write(cmd);
  EXPECT_TRUE(d.sim().plant().input().torque_off);
}

TEST(SimDriver, CycleAllocatesNothing) {
  const model::Scene s = flat();
  simloop::ClosedLoop loop(s, {});
  for (int k = 0; k < 10; ++k) loop.step();  // warm-up
  pedalwave::test::AllocationScope scope;
  for (int k = 0; k < 500; ++k) ASSERT_EQ(loop.step(), model::StepStatus::kOk);
  EXPECT_EQ(scope.count(), 0u) << "read → control → write → plant step allocated";
}
