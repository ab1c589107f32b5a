// Hard cases of model-spec.md §10: each must stay finite, not gain energy where nothing puts energy
// in, keep penetrations bounded, and give either a correct result (checked against an independent
// computation: a limit model, a physics bound, a finer step) or a clear error — never silent garbage.
// "Passive" runs hold the motors with a constant PD set-point (hard_support.hpp): the passive energy
// may then only decrease.
#include <gtest/gtest.h>

#include <cmath>

#include "hard_support.hpp"
#include "pedalwave/model/stability.hpp"

using namespace pedalwave::model;
using hard::passive_energy;

namespace {

constexpr double kG = 9.81;

// Link N flat at the start (theta = 0), the start these cases were written and measured from.
// (From the leveled default start, HighGearRatioClosedLoop's reference, dopri45 at rtol 1e-8,
// stops with kStepTooSmall at t = 0.499 s: a finding on the adaptive reference, not on the case.)
Scene ground_scene(InitialPose pose = InitialPose::kGaitStart) {
  Scene s;
  s.name = "hard";
  s.initial.pose = pose;
  s.initial.theta = 0;
  return s;
}

// Depth at which one point would carry the whole robot's weight statically, W / k [m]: no point
// may sink deeper. (The gait's shapes rest on a few points; on k = 350 N/m they sink ~1.4 cm.)
double weight_depth(const Scene& s) {
  const Model m(s.robot);
  return m.total_mass() * s.robot.g / s.ground.k;
}

struct PassiveRun {
  bool ok = true;              // every step kOk and finite
  double E0 = 0.0;             // passive energy at the start [J]
  double E_max = -1e300;       // largest passive energy after the start [J]
  double pen_max = 0.0;        // deepest ground penetration [m]
  double vz_max = 0.0;         // largest |COM vertical speed| [m/s]
  double z_com_max = -1e300;   // highest COM [m]
};

// Holds the motors where they start (K_p = 30, K_D = 15) and runs for T with `integ`.
PassiveRun run_passive(Simulation& sim, double T, double sample = 1e-3) {
  Plant& p = sim.plant();
  hard::hold_pd(p, sim.q(), 30.0, 15.0);
  PassiveRun r;
  r.E0 = passive_energy(p, sim.q(), sim.v());
  const Model& m = p.model();
  Data& d = p.data();
  const double t_end = sim.t() + T;
  while (sim.t() < t_end - 1e-12) {
    if (sim.advance_to(std::min(t_end, sim.t() + sample)) != StepStatus::kOk ||
        !sim.q().allFinite() || !sim.v().allFinite()) {
      r.ok = false;
      return r;
    }
    r.E_max = std::max(r.E_max, passive_energy(p, sim.q(), sim.v()));
    if (p.scene().ground_on) r.pen_max = std::max(r.pen_max, hard::ground_penetration(p, sim.q()));
    update_kinematics(m, d, sim.q(), sim.v());
    r.vz_max = std::max(r.vz_max, std::abs(linear_momentum(m, d, sim.v()).y() / m.total_mass()));
    r.z_com_max = std::max(r.z_com_max, center_of_mass(m, d, sim.q()).y());
  }
  return r;
}

// Energy may not grow: the backward-Euler-type implicit scheme only dissipates, so the tolerance
// is round-off of the energy's magnitude.
void expect_no_energy_gain(const PassiveRun& r, double tol = 1e-9) {
  EXPECT_LE(r.E_max, r.E0 + tol * std::max(1.0, std::abs(r.E0)))
      << "passive energy grew from " << r.E0 << " J to " << r.E_max << " J";
}

// K = 1e4 N·m/rad (near rigid): the spring mode is at ω ≈ 2.4e4 rad/s. The implicit scheme runs
// it at h = 1e-4 (ωh ≈ 2.4) and converges to the rigid (exact-limit) model: the deflection under
// ~0.1 N·m is ~1e-5 rad, so joint angles agree to 1e-3 rad and the COM to 0.5 mm after 1 s.
// The check refuses semi-implicit Euler at that step (limit 8.4e-5 s, set by the spring).
TEST(HardCases, StiffSpringConvergesToRigid) {
  Scene s = ground_scene();
  s.robot.K_all = 1e4;
  const IntegratorOptions imp{.method = Method::kImplicitVelocity, .h = 1e-4};
  Simulation flex(s, imp);
  const PassiveRun r = run_passive(flex, 1.0);
  ASSERT_TRUE(r.ok);
  expect_no_energy_gain(r);
  EXPECT_LT(r.pen_max, weight_depth(s));

  Scene rigid = s;
  rigid.robot.joints = JointModel::kRigid;
  Simulation rig(rigid, imp);
  ASSERT_TRUE(run_passive(rig, 1.0).ok);
  const Model& mf = flex.plant().model();
  for (int j = 0; j < mf.joints(); ++j)
    EXPECT_NEAR(flex.q()(mf.i_alpha(j)), rig.q()(j), 1e-3) << "joint " << j;
  EXPECT_LT((hard::com(flex) - hard::com(rig)).norm(), 5e-4);

  const StabilityCheck c = check(s, {30, 15}, {.method = Method::kSemiImplicitEuler, .h = 1e-4}, 1.0);
  EXPECT_EQ(c.level, CheckLevel::kError) << c.message;
  EXPECT_EQ(c.report.semi_implicit.dominant, Effect::kSpring) << c.message;
}

// Ground k = 1e5 N/m, dropped from 2 cm: the impact energy m g h = 0.14 J bounds any point's
// penetration by √(2 E / k) = 1.7 mm even if one point took it all; at rest the depth is the
// weight over 13 points (5 µm), so < 50 µm after 1 s.
TEST(HardCases, StiffGroundDrop) {
  Scene s = ground_scene(InitialPose::kAir);
  s.initial.height = 0.02;
  s.ground.k = 1e5;
  Simulation sim(s, {.method = Method::kImplicitVelocity, .h = 1e-4});
  const PassiveRun r = run_passive(sim, 1.0);
  ASSERT_TRUE(r.ok);
  expect_no_energy_gain(r);
  const double E_drop = sim.plant().model().total_mass() * kG * 0.02;
  EXPECT_LT(r.pen_max, std::sqrt(2 * E_drop / s.ground.k));
  EXPECT_LT(hard::ground_penetration(sim.plant(), sim.q()), 5e-5);
  EXPECT_LT(sim.v().norm(), 0.05) << "comes to rest";
}

// Gear ratio n = 1000 (n² I_r = 0.05 kg·m², 15× the default): closed-loop gait for 2 s with the
// implicit scheme at the shipped step against dopri45 at rtol 1e-8: the COM agrees within 1 mm.
TEST(HardCases, HighGearRatioClosedLoop) {
  Scene s = ground_scene();
  s.robot.n = 1000;
  hard::GaitLoop a(s, {.method = Method::kImplicitVelocity, .h = 1e-4});
  hard::GaitLoop b(s, {.method = Method::kDormandPrince45, .h = 1e-4, .rtol = 1e-8, .atol = 1e-10});
  double pen = 0.0;
  for (int k = 0; k < 2000; ++k) {
    ASSERT_EQ(a.step(), StepStatus::kOk) << "t = " << a.t();
    ASSERT_EQ(b.step(), StepStatus::kOk) << "t = " << b.t();
    pen = std::max(pen, hard::ground_penetration(a.sim().plant(), a.sim().q()));
  }
  EXPECT_LT((hard::com(a.sim()) - hard::com(b.sim())).norm(), 1e-3);
  EXPECT_LT(pen, weight_depth(s));
}

// I_r = 1e-10 kg·m² with flexible joints: the motor mode's rate K_D / (n² I_r) = 2.3e6 1/s. The
// check refuses explicit schemes at 1e-4 s with the motor damping named; the implicit scheme runs
// (the motor becomes quasi-static), gains no energy, and converges: h = 1e-4 and 2.5e-5 agree on
// the joint angles within 1e-3 rad, and so does I_r = 1e-9 (continuity in I_r).
TEST(HardCases, TinyRotorInertia) {
  Scene s = ground_scene();
  s.robot.I_r = 1e-10;
  for (Method m : {Method::kExplicitEuler, Method::kRK4, Method::kSemiImplicitEuler}) {
    const StabilityCheck c = check(s, {30, 15}, {.method = m, .h = 1e-4}, 1.0);
    EXPECT_EQ(c.level, CheckLevel::kError) << c.message;
    EXPECT_NE(c.message.find("motor damping"), std::string::npos) << c.message;
  }
  Simulation a(s, {.method = Method::kImplicitVelocity, .h = 1e-4});
  const PassiveRun r = run_passive(a, 1.0);
  ASSERT_TRUE(r.ok);
  expect_no_energy_gain(r);
  Simulation b(s, {.method = Method::kImplicitVelocity, .h = 2.5e-5});
  ASSERT_TRUE(run_passive(b, 1.0).ok);
  Scene s9 = s;
  s9.robot.I_r = 1e-9;
  Simulation c9(s9, {.method = Method::kImplicitVelocity, .h = 1e-4});
  ASSERT_TRUE(run_passive(c9, 1.0).ok);
  const Model& m = a.plant().model();
  for (int j = 0; j < m.joints(); ++j) {
    EXPECT_NEAR(a.q()(m.i_alpha(j)), b.q()(m.i_alpha(j)), 1e-3) << "joint " << j;
    EXPECT_NEAR(a.q()(m.i_alpha(j)), c9.q()(m.i_alpha(j)), 1e-3) << "joint " << j;
  }
}

// N = 50 links (nq = 101) resting in the gait's shape: finite, no energy gain, depth below W / k,
// and at the end the ground carries the weight (Σ f_N = m g within 2 %).
TEST(HardCases, FiftyLinks) {
  Scene s = ground_scene();
  s.robot.N = 50;
  Simulation sim(s, {.method = Method::kImplicitVelocity, .h = 2e-4});
  const PassiveRun r = run_passive(sim, 1.0, 5e-3);
  ASSERT_TRUE(r.ok);
  expect_no_energy_gain(r);
  EXPECT_LT(r.pen_max, weight_depth(s));
  ContactReport rep;
  sim.plant().report(sim.q(), sim.v(), rep);
  const double W = sim.plant().model().total_mass() * kG;
  EXPECT_NEAR(rep.f_normal.sum(), W, 0.02 * W);
}

// A fast gait, ω = 4π (2 Hz), closed loop for 3 s: the motors track α^d (|β − α^d| < 0.05 rad;
// measured 0.005), the body stays on the ground (its COM never 1 cm above the start, where the
// gait's arched shape puts it at 6.7 cm; penetration below weight_depth), and the
// result is converged: implicit h = 1e-4 and 2.5e-5 agree on the COM within 2 mm.
TEST(HardCases, FastGaitClosedLoop) {
  Scene s = ground_scene();
  s.gait.omega = 4 * M_PI;
  hard::GaitLoop a(s, {.method = Method::kImplicitVelocity, .h = 1e-4});
  hard::GaitLoop b(s, {.method = Method::kImplicitVelocity, .h = 2.5e-5});
  double track = 0.0, pen = 0.0, z_max = -1.0;
  const Model& m = a.sim().plant().model();
  const double z0 = hard::com(a.sim()).y();
  for (int k = 0; k < 3000; ++k) {
    ASSERT_EQ(a.step(), StepStatus::kOk) << "t = " << a.t();
    ASSERT_EQ(b.step(), StepStatus::kOk) << "t = " << b.t();
    if (a.t() > 0.5)
      for (int j = 0; j < m.joints(); ++j)
        track = std::max(track, std::abs(a.sim().q()(m.i_beta(j)) - a.control().alpha_d[static_cast<std::size_t>(j)]));
    pen = std::max(pen, hard::ground_penetration(a.sim().plant(), a.sim().q()));
    z_max = std::max(z_max, hard::com(a.sim()).y());
  }
  EXPECT_LT(track, 0.05);
  EXPECT_LT(pen, weight_depth(s));
  EXPECT_LT(z_max, z0 + 0.01) << "the body does not hop off the ground";
  EXPECT_LT((hard::com(a.sim()) - hard::com(b.sim())).norm(), 2e-3);
}

// Starting 1 cm inside the ground: the stored contact energy E_c = ½ k P δ² (0.23 J) bounds what
// follows. The body is pushed out (depth back to the resting ~2 mm within 0.5 s), its COM speed
// stays below √(2 E_c / m), it rises no more than E_c / (m g) above its start, and no energy
// appears — with the implicit scheme and with RK4 at 1e-4 s.
TEST(HardCases, StartsInPenetration) {
  for (Method method : {Method::kImplicitVelocity, Method::kRK4}) {
    SCOPED_TRACE(std::string(to_string(method)));
    Scene s = ground_scene(InitialPose::kFlat);
    s.initial.height = -0.01;
    Simulation sim(s, {.method = method, .h = 1e-4});
    const Model& m = sim.plant().model();
    const double z0 = hard::com(sim).y();
    const double E_c = 0.5 * s.ground.k * m.points() * 0.01 * 0.01;
    const PassiveRun r = run_passive(sim, 1.0);
    ASSERT_TRUE(r.ok);
    expect_no_energy_gain(r, method == Method::kRK4 ? 1e-6 : 1e-9);
    EXPECT_LT(r.vz_max, std::sqrt(2 * E_c / m.total_mass()));
    EXPECT_LT(r.z_com_max, z0 + 0.01 + E_c / (m.total_mass() * kG));
    EXPECT_LT(hard::ground_penetration(sim.plant(), sim.q()), 3e-3) << "pushed out";
  }
}

// A link draped over the stair's near corner: links 0–1 slope up at 30°, link 1's middle resting
// on the corner, links 2–5 level just above the top. Ground/box k = 5000 N/m (so the corner's load
// of a few newtons means < 2 mm). For 2 s the corner holds it: no body point ends inside the box,
// the body still straddles the edge, corner/contact depth < 5 mm, no energy appears.
TEST(HardCases, DrapedOverTheStairCorner) {
  Scene s = ground_scene(InitialPose::kExplicit);
  s.ground.k = 5000;
  Box b;
  b.x_near = 0.0;
  b.width = 0.11;
  b.height = 0.06;
  s.boxes.push_back(b);
  const Model m(s.robot);
  const double l = s.robot.l, phi = M_PI / 6;
  // θ: links 0–1 at 30°, links 2–5 level. α_j = θ_j − θ_{j+1}: only α_1 = 30° is nonzero.
  std::vector<double> q(static_cast<size_t>(m.nq()), 0.0);
  q[1] = phi;
  // Link 1's COM sits 1 mm above the corner along its normal; place p through that COM.
  Data d(m);
  VectorXd qv = Eigen::Map<VectorXd>(q.data(), m.nq());
  update_kinematics(m, d, qv, VectorXd());
  const Vec2 com1 = point_position(m, d, qv, Model::point_com(1));  // with p = 0
  const Vec2 target = Vec2(0.0, b.height) + 1e-3 * Vec2(-std::sin(phi), std::cos(phi));
  q[static_cast<size_t>(m.i_px())] = target.x() - com1.x();
  q[static_cast<size_t>(m.i_pz())] = target.y() - com1.y();
  s.initial.q = q;
  (void)l;
  Simulation sim(s, {.method = Method::kImplicitVelocity, .h = 1e-4});
  const PassiveRun r = run_passive(sim, 2.0);
  ASSERT_TRUE(r.ok);
  expect_no_energy_gain(r);
  ContactReport rep;
  double deepest = 0.0;
  Plant& p = sim.plant();
  p.report(sim.q(), sim.v(), rep);
  deepest = rep.max_penetration;
  EXPECT_LT(deepest, 5e-3);
  update_kinematics(m, p.data(), sim.q(), VectorXd());
  double x_min = 1e9, x_max = -1e9;
  for (int k = 0; k < m.points(); ++k) {
    const Vec2 pt = point_position(m, p.data(), sim.q(), k);
    x_min = std::min(x_min, pt.x());
    x_max = std::max(x_max, pt.x());
    const bool inside = pt.x() > b.x_near + 1e-3 && pt.x() < b.x_near + b.width - 1e-3 &&
                        pt.y() < b.height - 5e-3 && pt.y() > 0;
    EXPECT_FALSE(inside) << "point " << k << " at (" << pt.x() << ", " << pt.y() << ") is inside the box";
  }
  EXPECT_LT(x_min, b.x_near);
  EXPECT_GT(x_max, b.x_near);
}

// Exact Coulomb friction, velocity crossing zero: a straight robot resting on the ground is
// launched along X at 0.2 m/s. It must stop after v²/(2 μ g) = 2.49 mm (±10 %: the contact
// springs and the body's flex take a little), then stay: the sign function chatters at v_t = 0
// with velocity jumps ≈ μ g h, so the COM speed stays below 10 μ g h and the body creeps less than
// 0.1 mm in the last 0.2 s; the passive energy never grows beyond round-off plus the chatter's
// ½ m (μ g h)² — with the implicit scheme and with RK4.
TEST(HardCases, CoulombZeroCrossing) {
  for (Method method : {Method::kImplicitVelocity, Method::kRK4}) {
    SCOPED_TRACE(std::string(to_string(method)));
    Scene s = ground_scene(InitialPose::kFlat);
    s.ground.law = FrictionLaw::kCoulomb;
    const double h = 1e-4, mu = s.ground.mu;
    Simulation sim(s, {.method = Method::kImplicitVelocity, .h = h});
    const Model& m = sim.plant().model();
    hard::hold_pd(sim.plant(), sim.q(), 30.0, 15.0);
    ASSERT_EQ(sim.advance_to(1.0), StepStatus::kOk);  // settle onto the ground
    Simulation run(s, {.method = method, .h = h});
    run.q() = sim.q();
    run.v().setZero();
    run.v()(m.i_px()) = 0.2;
    const double x0 = hard::com(run).x();
    const PassiveRun r = run_passive(run, 0.5);
    ASSERT_TRUE(r.ok);
    const double chatter = 0.5 * m.total_mass() * std::pow(mu * kG * h, 2);
    EXPECT_LE(r.E_max, r.E0 + chatter + 1e-9);
    const double stop = 0.2 * 0.2 / (2 * mu * kG);
    const double x_stop = hard::com(run).x() - x0;
    EXPECT_NEAR(x_stop, stop, 0.1 * stop);
    const double x_a = hard::com(run).x();
    const PassiveRun rest = run_passive(run, 0.2);
    ASSERT_TRUE(rest.ok);
    EXPECT_LT(std::abs(hard::com(run).x() - x_a), 1e-4) << "creeps at rest";
    update_kinematics(m, run.plant().data(), run.q(), run.v());
    const double vx = linear_momentum(m, run.plant().data(), run.v()).x() / m.total_mass();
    EXPECT_LT(std::abs(vx), 10 * mu * kG * h);
  }
}

}  // namespace
