// Very long run (label slow): 10 min simulated, flat high-friction scene, closed loop (gait at
// 1 kHz, module-side PD), the shipped implicit scheme at h = 5e-4 s. Over 1.2 million steps
// round-off and the scheme's dissipation could make the body sink into the ground or pump energy
// in; neither may happen: the body's mean COM height in the last minute equals the first minute's
// (after 10 s of start-up) within 1 mm (the gait cycle is 2 s, so both means average 30 cycles),
// the mechanical energy (kinetic + springs + m g (z_COM − ground)) peaks no higher in the last
// minute than 1.2× its first-minute peak, penetration stays below W / k.
#include <gtest/gtest.h>

#include <cmath>

#include "hard_support.hpp"

using namespace pedalwave::model;

namespace {

TEST(HardCasesSlow, TenMinutesClosedLoopNoDrift) {
  Scene s;
  s.name = "long-run";
  s.initial.pose = InitialPose::kGaitStart;
  s.ground.mu = 0.82;
  hard::GaitLoop loop(s, {.method = Method::kImplicitVelocity, .h = 5e-4});
  Simulation& sim = loop.sim();
  Plant& p = sim.plant();
  const Model& m = p.model();
  const double W = m.total_mass() * s.robot.g;
  double z_first = 0, z_last = 0, e_first = 0, e_last = 0, pen = 0;
  int n_first = 0, n_last = 0;
  const int cycles = 600000;  // 600 s at 1 kHz
  for (int k = 0; k < cycles; ++k) {
    ASSERT_EQ(loop.step(), StepStatus::kOk) << "t = " << loop.t();
    if (k % 10 != 0) continue;  // sample every 10 ms
    const double t = loop.t();
    const Vec2 c = hard::com(sim);
    update_kinematics(m, p.data(), sim.q(), sim.v());
    compute_mass_matrix(m, p.data());
    const double E = kinetic_energy(p.data(), sim.v()) + spring_energy(m, sim.q()) +
                     W * (c.y() - s.ground.z);
    pen = std::max(pen, hard::ground_penetration(p, sim.q()));
    if (t >= 10.0 && t < 70.0) z_first += c.y(), ++n_first, e_first = std::max(e_first, E);
    if (t >= 540.0) z_last += c.y(), ++n_last, e_last = std::max(e_last, E);
  }
  z_first /= n_first;
  z_last /= n_last;
  EXPECT_NEAR(z_last, z_first, 1e-3) << "COM height drifted";
  EXPECT_LE(e_last, 1.2 * e_first) << "energy grew";
  EXPECT_LT(pen, W / s.ground.k);
  std::printf("long run: z_first %.6f z_last %.6f  E_first %.5f E_last %.5f pen %.4f x %.3f\n",
              z_first, z_last, e_first, e_last, pen, hard::com(sim).x());
}

}  // namespace
