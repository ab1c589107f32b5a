// Effects composed by the Plant, checked against physics: static equilibrium on the ground,
// sliding under friction, boxes and their corners, patches, torque limits, and the implicit
// scheme's Jacobians against finite differences.
#include <gtest/gtest.h>

#include <cmath>

#include "alloc_counter.hpp"
#include "pedalwave/model/plant.hpp"

using namespace pedalwave::model;

namespace {
Scene flat_scene() {
  Scene s;
  s.name = "test-flat";
  s.initial.pose = InitialPose::kFlat;
  s.integrator = {.method = Method::kImplicitVelocity, .h = 1e-4};
  return s;
}
}  // namespace

// At rest on flat ground the normal forces carry exactly the weight.
TEST(Plant, RestingOnTheGroundCarriesTheWeight) {
  // Rigid joints: free SEA motors with no damping would ring forever (physically right).
  Scene s = flat_scene();
  s.robot.joints = JointModel::kRigid;
  Simulation sim(s);
  ASSERT_EQ(sim.advance_to(3.0), StepStatus::kOk);
  ContactReport r;
  sim.plant().report(sim.q(), sim.v(), r);
  const Model& m = sim.plant().model();
  EXPECT_NEAR(r.f_normal.sum(), m.total_mass() * s.robot.g, 1e-3);
  EXPECT_LT(sim.v().norm(), 1e-2);
  EXPECT_LT(std::abs(sim.q()(m.i_px())), 1e-3) << "a resting robot does not drift";
  // Depth: between the uniform-load value and what one link's weight on a single point gives.
  const double uniform = m.total_mass() * s.robot.g / (s.ground.k * m.points());
  EXPECT_GT(r.max_penetration, uniform);
  EXPECT_LT(r.max_penetration, s.robot.m_l * s.robot.g / s.ground.k);
}

// A straight robot launched along X on flat ground decelerates at μ g (regularized law, sliding).
TEST(Plant, SlidingDeceleratesAtMuG) {
  for (double mu : {0.82, 0.4}) {
    Scene s = flat_scene();
    s.ground.mu = mu;
    s.robot.joints = JointModel::kRigid;
    Simulation sim(s);
    ASSERT_EQ(sim.advance_to(1.0), StepStatus::kOk);  // settle
    const Model& m = sim.plant().model();
    sim.v()(m.i_px()) = 1.0;
    const double t0 = sim.t();
    ASSERT_EQ(sim.advance_to(t0 + 0.05), StepStatus::kOk);
    const double v1 = sim.v()(m.i_px());
    ASSERT_EQ(sim.advance_to(t0 + 0.10), StepStatus::kOk);
    const double decel = (v1 - sim.v()(m.i_px())) / 0.05;
    EXPECT_NEAR(decel, mu * s.robot.g, 0.02 * mu * s.robot.g) << "mu = " << mu;
  }
}

// The friction coefficient follows the patches along X.
TEST(Plant, PatchesChangeFrictionAlongX) {
  Scene s = flat_scene();
  s.robot.joints = JointModel::kRigid;
  s.ground.patches = {{0.5, 0.4}};
  s.initial.x = 1.0;  // on the low-friction patch
  Simulation sim(s);
  ASSERT_EQ(sim.advance_to(1.0), StepStatus::kOk);
  const Model& m = sim.plant().model();
  sim.v()(m.i_px()) = 1.0;
  const double t0 = sim.t();
  ASSERT_EQ(sim.advance_to(t0 + 0.05), StepStatus::kOk);
  const double v1 = sim.v()(m.i_px());
  ASSERT_EQ(sim.advance_to(t0 + 0.10), StepStatus::kOk);
  EXPECT_NEAR((v1 - sim.v()(m.i_px())) / 0.05, 0.4 * s.robot.g, 0.1);
}

// A robot dropped onto a box rests on its top face at the box's height.
TEST(Plant, BoxTopFaceSupports) {
  Scene s = flat_scene();
  s.robot.N = 2;  // 14 cm long: fits on the box
  s.robot.joints = JointModel::kRigid;
  s.boxes = {Box{.x_near = -0.1, .width = 0.2, .height = 0.06}};
  s.initial.pose = InitialPose::kAir;
  s.initial.height = 0.1;
  Simulation sim(s);
  ASSERT_EQ(sim.advance_to(2.0), StepStatus::kOk);
  const Model& m = sim.plant().model();
  EXPECT_NEAR(sim.q()(m.i_pz()), 0.06, 0.005);
  EXPECT_LT(sim.v().norm(), 1e-2);
}

// A link crossing the box's top corner, with every body point outside the box, is pushed by the
// corner alone (distance from the corner to the link segment): f_N = k·δ at rest.
TEST(Plant, BoxCornerPushesALinkCrossingTheEdge) {
  Scene s = flat_scene();
  s.robot.N = 2;
  s.robot.joints = JointModel::kRigid;
  s.boxes = {Box{.x_near = -0.5, .width = 0.5, .height = 0.06}};  // top corner at (0, 0.06)
  const double theta = -0.5, depth = 1e-3, l2 = 2 * s.robot.l;
  const Vec2 u(std::cos(theta), std::sin(theta)), n(-std::sin(theta), std::cos(theta));
  const Vec2 corner(0.0, 0.06);
  const Vec2 tail = corner - 0.25 * l2 * u - depth * n;  // corner at a quarter of link 0
  const Vec2 joint = tail + l2 * u;                      // N = 2: p is the joint
  s.initial.pose = InitialPose::kExplicit;
  s.initial.q = {0.0, theta, joint.x(), joint.y()};
  for (bool with_corner : {false, true}) {
    s.boxes[0].corner_contact = with_corner;
    Plant p(s);
    VectorXd q, v;
    p.initial_state(q, v);
    ContactReport r;
    p.report(q, v, r);
    if (with_corner) {
      EXPECT_NEAR(r.f_normal.sum(), s.ground.k * depth, 1e-9);
      EXPECT_NEAR(r.max_penetration, depth, 1e-12);
    } else {
      EXPECT_EQ(r.f_normal.sum(), 0.0) << "no body point is inside the box";
    }
  }
}

// The corner-vs-link contact slides with its own friction coefficient: a link crossing the corner
// and sliding along itself at 0.1 m/s (≫ v_s) gets |f_T| = μ_edge f_N, μ_edge = edge_mu when set,
// the box's mu otherwise; the box's faces keep mu.
TEST(Plant, BoxCornerFrictionUsesEdgeMu) {
  Scene s = flat_scene();
  s.robot.N = 2;
  s.robot.joints = JointModel::kRigid;
  s.boxes = {Box{.x_near = -0.5, .width = 0.5, .height = 0.06, .mu = 0.82}};
  const double theta = -0.5, depth = 1e-3, l2 = 2 * s.robot.l;
  const Vec2 u(std::cos(theta), std::sin(theta)), n(-std::sin(theta), std::cos(theta));
  const Vec2 tail = Vec2(0.0, 0.06) - 0.25 * l2 * u - depth * n;
  const Vec2 joint = tail + l2 * u;
  s.initial.pose = InitialPose::kExplicit;
  s.initial.q = {0.0, theta, joint.x(), joint.y()};
  for (const double edge : {std::nan(""), 1.5, 0.0}) {
    s.boxes[0].edge_mu = edge;
    Plant p(s);
    VectorXd q, v;
    p.initial_state(q, v);
    v.setZero();
    v(p.model().i_px()) = 0.1 * u.x();
    v(p.model().i_pz()) = 0.1 * u.y();
    ContactReport r;
    p.report(q, v, r);
    const double mu = std::isnan(edge) ? 0.82 : edge;
    ASSERT_GT(r.f_normal.sum(), 0.0);
    EXPECT_NEAR(std::abs(r.f_tangent.sum()) / r.f_normal.sum(), mu, 1e-9) << "edge_mu " << edge;
  }
}

// The implicit scheme's Jacobians match finite differences of the generalized force
// (contact in the smooth region, springs, module PD).
TEST(Plant, ImplicitTermsMatchFiniteDifferences) {
  Scene s = flat_scene();
  s.initial.pose = InitialPose::kGaitStart;
  s.ground.v_s = 0.5;  // keep every point inside the smooth part of the friction law
  Plant p(s);
  VectorXd q, v;
  p.initial_state(q, v);
  q(p.model().i_pz()) -= 0.003;  // press into the ground
  v.setConstant(0.01);
  p.input().kp.setConstant(30);
  p.input().kd.setConstant(15);
  ImplicitTerms it;
  const int n = p.nq();
  it.M = MatrixXd::Zero(n, n);
  it.F = VectorXd::Zero(n);
  it.dFdq = MatrixXd::Zero(n, n);
  it.dFdv = MatrixXd::Zero(n, n);
  ASSERT_TRUE(p.implicit_terms(0, q, v, it));
  const VectorXd F0 = it.F;
  const MatrixXd Dq = it.dFdq, Dv = it.dFdv;
  ImplicitTerms it2 = it;
  const double eps = 1e-7;
  for (int c = 0; c < n; ++c) {
    VectorXd vp = v, vm = v;
    vp(c) += eps;
    vm(c) -= eps;
    // Coriolis is left out of D_v on purpose (not stiff): add it back before differencing.
    p.implicit_terms(0, q, vp, it2);
    const VectorXd Fp = it2.F + p.data().coriolis;
    p.implicit_terms(0, q, vm, it2);
    const VectorXd col = (Fp - it2.F - p.data().coriolis) / (2 * eps);
    for (int r = 0; r < n; ++r)
      EXPECT_NEAR(Dv(r, c), col(r), 1e-6 + 1e-5 * std::abs(col(r))) << "dF/dv " << r << "," << c;
  }
  (void)F0;
  (void)Dq;
}

TEST(Plant, AccelerationAllocatesNothing) {
  Scene s = flat_scene();
  s.initial.pose = InitialPose::kGaitStart;
  s.boxes = {Box{.x_near = 0.1}};
  s.ground.patches = {{0.2, 0.4}};
  Plant p(s);
  VectorXd q, v, a(p.nq());
  p.initial_state(q, v);
  ASSERT_TRUE(p.acceleration(0, q, v, a));
  ImplicitTerms it;
  it.M = MatrixXd::Zero(p.nq(), p.nq());
  it.F = VectorXd::Zero(p.nq());
  it.dFdq = it.M;
  it.dFdv = it.M;
  pedalwave::test::AllocationScope scope;
  for (int i = 0; i < 100; ++i) {
    ASSERT_TRUE(p.acceleration(0, q, v, a));
    ASSERT_TRUE(p.implicit_terms(0, q, v, it));
  }
  EXPECT_EQ(scope.count(), 0u);
}

TEST(Plant, TorqueLimitClampsTheModuleTorque) {
  Scene s = flat_scene();
  s.torque_limit_on = true;
  s.torque_limit.u_max = 0.5;
  Plant p(s);
  VectorXd q, v, u(p.model().joints());
  p.initial_state(q, v);
  p.input().tau.setConstant(3.0);
  p.motor_torques(q, v, u);
  EXPECT_DOUBLE_EQ(u.maxCoeff(), 0.5);
  p.input().tau.setConstant(-3.0);
  p.motor_torques(q, v, u);
  EXPECT_DOUBLE_EQ(u.minCoeff(), -0.5);
}

TEST(Plant, BadScenesAreRejectedWithTheKey) {
  Scene s = flat_scene();
  s.ground.k = -1;
  try {
    Plant p(s);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("ground.k = -1"), std::string::npos) << e.what();
  }
  s = flat_scene();
  s.boxes = {Box{.width = 0}};
  EXPECT_THROW(Plant{s}, std::invalid_argument);
}

// The gait_start pose is as high as the gait's wave, whatever N: its base angle levels the chain's
// chord (head and tail tips at one height), so no point is more than A_p / sin²(η/2) link lengths
// above the ground (the wave's own height: link angles of amplitude A_p / (2 sin(η/2)), summed
// once more along the chain). With link N laid flat (theta: 0, the shipped 6-link scenes' start)
// a 12-link robot's head started 32 cm up and the body fell at t = 0.
TEST(Plant, GaitStartIsAsHighAsItsWaveForEveryN) {
  const GaitParams gaits[] = {{}, {.A_p = 0.5, .omega = M_PI, .eta = -M_PI / 4}, {.A_p = 1.0}};
  for (const GaitParams& g : gaits)
    for (int N = 2; N <= 64; ++N) {
      Scene s = flat_scene();
      s.robot = paper_params(N);
      s.ground_on = true;
      s.gait = g;
      s.initial.pose = InitialPose::kGaitStart;
      Plant p(s);
      VectorXd q, v;
      p.initial_state(q, v);
      Data d(p.model());
      update_kinematics(p.model(), d, q, v);
      const Model& m = p.model();
      double z_lo = 1e9, z_hi = -1e9;
      for (int k = 0; k < m.points(); ++k) {
        z_lo = std::min(z_lo, point_position(m, d, q, k).y());
        z_hi = std::max(z_hi, point_position(m, d, q, k).y());
      }
      const double link = 2 * s.robot.l, bound = g.A_p / std::pow(std::sin(g.eta / 2), 2) * link;
      EXPECT_NEAR(z_lo, s.ground.z, 1e-12) << "N = " << N << ": the lowest point on the ground";
      EXPECT_LE(z_hi - z_lo, bound) << "N = " << N << ", A_p = " << g.A_p << ", eta = " << g.eta;
      EXPECT_NEAR(point_position(m, d, q, m.point_head()).y(),
                  point_position(m, d, q, Model::point_tail()).y(), 1e-12)
          << "N = " << N << ": head and tail tips at one height";
      for (int j = 0; j < m.joints(); ++j)
        ASSERT_DOUBLE_EQ(q(m.i_alpha(j)), g.A_p * std::sin(g.eta * j)) << "the gait's shape at t = 0";
    }
  // The check can fail: link N flat (theta = 0) puts a 12-link robot's head 32 cm up.
  Scene s = flat_scene();
  s.robot = paper_params(12);
  s.ground_on = true;
  s.initial.pose = InitialPose::kGaitStart;
  s.initial.theta = 0;
  Plant p(s);
  VectorXd q, v;
  p.initial_state(q, v);
  Data d(p.model());
  update_kinematics(p.model(), d, q, v);
  EXPECT_EQ(q(p.model().i_theta_N()), 0.0);
  EXPECT_GT(point_position(p.model(), d, q, p.model().point_head()).y(), 0.3);
}

// Boxes placed ahead_of_head are measured from the head tip of that start pose.
TEST(Plant, BoxesAheadOfTheHeadAreMeasuredFromTheStartPose) {
  Scene s = flat_scene();
  s.robot = paper_params(12);
  s.ground_on = true;
  s.initial.pose = InitialPose::kGaitStart;
  s.boxes = {Box{.ahead_of_head = 0.05}};
  Plant p(s);
  VectorXd q, v;
  p.initial_state(q, v);
  Data d(p.model());
  update_kinematics(p.model(), d, q, v);
  EXPECT_NEAR(p.scene().boxes[0].x_near,
              point_position(p.model(), d, q, p.model().point_head()).x() + 0.05, 1e-12);
}
