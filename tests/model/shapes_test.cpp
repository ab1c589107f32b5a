// Thick links (scene robot.link_shape capsule / box; README "Link shapes"), checked against
// physics and against independent kinematics: a resting robot carries its weight, contact without
// damping or friction is a conservative spring over a bounce, a box corner pushes a thick link
// along the right normal through the right point, r → 0 gives the segment's results, both
// forward-dynamics solvers agree, the implicit Jacobians match finite differences, and nothing
// allocates.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "alloc_counter.hpp"
#include "model_fixtures.hpp"
#include "pedalwave/model/plant.hpp"

using namespace pedalwave::model;

namespace {

Scene flat_scene() {
  Scene s;
  s.name = "test-shapes";
  s.initial.pose = InitialPose::kFlat;
  s.integrator = {.method = Method::kImplicitVelocity, .h = 1e-4};
  return s;
}

Scene with_shape(Scene s, LinkShape shape, double size) {
  s.robot.link_shape = shape;
  if (shape == LinkShape::kCapsule) s.robot.link_radius = size;
  if (shape == LinkShape::kBox) s.robot.link_height = size;
  return s;
}

// Position of the material point of link i at body coordinates (s along the axis from its rear
// end, nb along its normal), from the body points' positions alone.
Vec2 material_point(const Model& m, const VectorXd& q, int i, double s, double nb) {
  Data d(m);
  update_kinematics(m, d, q, VectorXd());
  const Vec2 A = point_position(m, d, q, 2 * i);
  return A + s * Vec2(d.cos_t(i), d.sin_t(i)) + nb * Vec2(-d.sin_t(i), d.cos_t(i));
}

// Jᵀ f of a force f at that material point, J by central differences of its position.
VectorXd fd_generalized_force(const Model& m, const VectorXd& q, int i, double s, double nb, const Vec2& f) {
  VectorXd Q = VectorXd::Zero(m.nq());
  const double eps = 1e-7;
  for (int c = 0; c < m.nq(); ++c) {
    VectorXd qp = q, qm = q;
    qp(c) += eps;
    qm(c) -= eps;
    Q(c) = f.dot(material_point(m, qp, i, s, nb) - material_point(m, qm, i, s, nb)) / (2 * eps);
  }
  return Q;
}

// The plant's generalized contact force at (q, v).
VectorXd contact_Q(Plant& p, const VectorXd& q, const VectorXd& v) {
  update_kinematics(p.model(), p.data(), q, v);
  VectorXd Q = VectorXd::Zero(p.nq());
  p.contact_forces(q, v, Q, nullptr, nullptr);
  return Q;
}

// Explicit N = 2 state (rigid joints: q = [α, θ_N, p_x, p_z], p the joint) with link 0 at angle
// theta and the point at arc length s_c of link 0 at `point`.
std::vector<double> two_links_through(double theta, double l2, double s_c, const Vec2& point) {
  const Vec2 u(std::cos(theta), std::sin(theta));
  const Vec2 tail = point - s_c * u;
  const Vec2 joint = tail + l2 * u;
  return {0.0, theta, joint.x(), joint.y()};
}

}  // namespace

// At rest on flat ground the capsule's spheres or the box's corners carry exactly the weight, and
// the axis rests r (h_m/2) above the ground less the contact's sag.
TEST(LinkShapes, RestingRobotCarriesItsWeight) {
  for (const auto& [shape, size] : {std::pair{LinkShape::kCapsule, 0.015}, std::pair{LinkShape::kBox, 0.03}}) {
    SCOPED_TRACE(to_string(shape));
    Scene s = with_shape(flat_scene(), shape, size);
    s.robot.joints = JointModel::kRigid;
    Simulation sim(s);
    const Model& m = sim.plant().model();
    const double half = s.robot.half_thickness();
    ContactReport r;
    // The start rests the surface, not the axis, on the ground.
    sim.plant().report(sim.q(), sim.v(), r);
    EXPECT_NEAR(sim.q()(m.i_pz()), half, 1e-12);
    EXPECT_LE(r.max_penetration, 1e-12);
    ASSERT_EQ(sim.advance_to(3.0), StepStatus::kOk);
    sim.plant().report(sim.q(), sim.v(), r);
    EXPECT_NEAR(r.f_normal.sum(), m.total_mass() * s.robot.g, 1e-3);
    EXPECT_LT(sim.v().norm(), 1e-2);
    EXPECT_LT(std::abs(sim.q()(m.i_px())), 1e-3) << "a resting robot does not drift";
    EXPECT_LT(sim.q()(m.i_pz()), half);
    EXPECT_GT(sim.q()(m.i_pz()), half - s.robot.m_l * s.robot.g / s.ground.k);
    EXPECT_NEAR(sim.q()(m.i_pz()), half - r.max_penetration, 0.5 * r.max_penetration);
  }
}

// With d = 0 and μ = 0 every contact is a spring of potential ½ k δ²: a passive robot dropped
// tilted onto the ground and a box edge keeps kinetic + gravity + contact energy over the bounce
// (RK4, small step: the drift is the integrator's, far below the energy exchanged).
TEST(LinkShapes, EnergyIsConservedWithoutDampingOrFriction) {
  for (const auto& [shape, size] : {std::pair{LinkShape::kCapsule, 0.015}, std::pair{LinkShape::kBox, 0.03}}) {
    SCOPED_TRACE(to_string(shape));
    Scene s = with_shape(flat_scene(), shape, size);
    s.robot.joints = JointModel::kRigid;  // passive, unactuated joints (u = 0)
    s.ground.d = 0.0;
    s.ground.mu = 0.0;
    s.boxes = {Box{.x_near = 0.02, .width = 0.3, .height = 0.05, .mu = 0.0}};
    // A box link's test of the box's corners against its faces jumps where a corner crosses from
    // one module into the next at a bent joint (README "Link shapes"): conservative elsewhere, so
    // here the box link meets the box's faces only (its corner test: BoxCornerPushesAThickLink…).
    if (shape == LinkShape::kBox) s.boxes[0].corner_contact = false;
    s.initial.pose = InitialPose::kAir;
    s.initial.height = 0.04;
    s.initial.theta = 0.25;  // tilted: the tail lands on the ground, the body across the box edge
    s.integrator = {.method = Method::kRK4, .h = 2e-5};
    Simulation sim(s);
    Plant& p = sim.plant();
    ContactReport r;
    auto energy = [&] {
      p.report(sim.q(), sim.v(), r);
      return p.energy(sim.q(), sim.v()) + r.elastic_energy;
    };
    const double e0 = energy();
    double drift = 0.0, stored = 0.0, box_force = 0.0;
    for (int k = 1; k <= 300; ++k) {
      ASSERT_EQ(sim.advance_to(k * 1e-3), StepStatus::kOk);
      drift = std::max(drift, std::abs(energy() - e0));
      stored = std::max(stored, r.elastic_energy);
      // Contacts on the box: at body points right of its near edge, above the ground.
      update_kinematics(p.model(), p.data(), sim.q(), sim.v());
      for (int q = 0; q < p.model().points(); ++q)
        if (point_position(p.model(), p.data(), sim.q(), q).x() > 0.02) box_force = std::max(box_force, r.f_normal(q));
    }
    EXPECT_GT(stored, 0.01) << "the robot bounced: energy went into the contacts";
    EXPECT_GT(box_force, 0.5) << "the box carried part of it";
    EXPECT_LT(drift, 1e-6 * stored) << "energy drift over the bounce";
  }
}

// A box's top corner pressing into a capsule link (the axis r − δ from the corner) or into a box
// link (the corner δ inside its bottom face): f_N = k δ along the link's normal, away from the box,
// applied at the link's surface — Q equals Jᵀ f of that material point (J by finite differences of
// the point's position, not the plant's kinematics).
TEST(LinkShapes, BoxCornerPushesAThickLinkAlongItsNormal) {
  const double theta = -0.5, delta = 1e-3, r = 0.012, h = 0.03;
  const Vec2 corner(0.0, 0.06);
  const Vec2 nu(-std::sin(theta), std::cos(theta));  // link normal, up and away from the box
  for (LinkShape shape : {LinkShape::kCapsule, LinkShape::kBox}) {
    SCOPED_TRACE(to_string(shape));
    const double half = shape == LinkShape::kCapsule ? r : 0.5 * h;
    Scene s = with_shape(flat_scene(), shape, shape == LinkShape::kCapsule ? r : h);
    s.robot.N = 2;
    s.robot.joints = JointModel::kRigid;
    s.ground.z = -1.0;  // far below: only the box
    s.boxes = {Box{.x_near = -0.5, .width = 0.5, .height = 1.06}};  // top corner (0, 0.06)
    const double l2 = 2 * s.robot.l, s_c = 0.3 * l2;
    // The axis point over the corner: half − δ above it along ν.
    s.initial.pose = InitialPose::kExplicit;
    s.initial.q = two_links_through(theta, l2, s_c, corner + (half - delta) * nu);
    Plant p(s);
    VectorXd q, v;
    p.initial_state(q, v);
    ContactReport rep;
    p.report(q, v, rep);
    EXPECT_EQ(rep.active, 1);
    EXPECT_NEAR(rep.f_normal.sum(), s.ground.k * delta, 1e-9);
    EXPECT_NEAR(rep.max_penetration, delta, 1e-12);
    const VectorXd Q = contact_Q(p, q, v);
    // The contact point: the capsule's surface under the corner (−r ν from the axis), the corner
    // itself inside the box link; both on the line of action through the corner along ν.
    const double nb = shape == LinkShape::kCapsule ? -r : -(half - delta);
    const VectorXd expected = fd_generalized_force(p.model(), q, 0, s_c, nb, s.ground.k * delta * nu);
    EXPECT_LT((Q - expected).norm(), 1e-6 * expected.norm()) << "Q " << Q.transpose() << "\nJᵀf " << expected.transpose();
    // Moving the link away by 2δ along ν ends the contact.
    VectorXd q2 = q;
    q2(p.model().i_px()) += 2 * delta * nu.x();
    q2(p.model().i_pz()) += 2 * delta * nu.y();
    EXPECT_EQ(contact_Q(p, q2, v).norm(), 0.0);
  }
}

// A corner just beyond the tip of a capsule link meets its end cap: f_N = k (r − |tip − corner|)
// along the line from the corner to the tip.
TEST(LinkShapes, BoxCornerAgainstACapsuleEndCap) {
  const double r = 0.012, dist = 0.008;
  Scene s = with_shape(flat_scene(), LinkShape::kCapsule, r);
  s.robot.N = 2;
  s.robot.joints = JointModel::kRigid;
  s.ground.z = -1.0;
  s.boxes = {Box{.x_near = 0.0, .width = 0.5, .height = 1.06}};  // near top corner (0, 0.06)
  const double l2 = 2 * s.robot.l;
  // A straight robot ending left of and above the corner, the corner beyond its head tip.
  const Vec2 dir = Vec2(-1.0, 1.0).normalized();  // from the corner to the head tip
  const Vec2 head = Vec2(0.0, 0.06) + dist * dir;
  s.initial.pose = InitialPose::kExplicit;
  s.initial.q = {0.0, 0.0, head.x() - l2, head.y()};  // θ = 0: the head tip is 2l ahead of the joint
  Plant p(s);
  VectorXd q, v;
  p.initial_state(q, v);
  ContactReport rep;
  p.report(q, v, rep);
  EXPECT_EQ(rep.active, 2) << "the head tip's sphere and link 1's end cap: the same corner twice";
  EXPECT_NEAR(rep.f_normal.sum(), 2 * s.ground.k * (r - dist), 1e-9);
  const VectorXd Q = contact_Q(p, q, v);
  const VectorXd expected = fd_generalized_force(p.model(), q, 1, l2 - r * dir.x(), -r * dir.y(),
                                                 2 * s.ground.k * (r - dist) * dir);
  EXPECT_LT((Q - expected).norm(), 1e-6 * expected.norm());
}

// r → 0: the capsule's contacts are the segment's (ground, body points inside the box, the box's
// corners against the links), at random states in contact and over a closed-loop-like run.
TEST(LinkShapes, CapsuleOfVanishingRadiusIsTheSegment) {
  Scene seg = flat_scene();
  seg.initial.pose = InitialPose::kGaitStart;
  seg.initial.theta = 0.0;
  seg.boxes = {Box{.x_near = 0.08, .width = 0.11, .height = 0.04, .mu = 0.82, .edge_mu = 1.2}};
  // States: a box right under the robot (body points inside it, its corners across links).
  Scene seg_b = seg;
  seg_b.boxes[0].x_near = -0.05;
  Plant ps(seg_b), pc(with_shape(seg_b, LinkShape::kCapsule, 1e-12));
  ASSERT_DOUBLE_EQ(ps.scene().boxes[0].x_near, pc.scene().boxes[0].x_near);
  VectorXd q, v;
  ps.initial_state(q, v);
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  int compared = 0;
  for (int trial = 0; trial < 200; ++trial) {
    VectorXd qt = q, vt = pedalwave::model::testing::random_v(ps.model(), rng, 0.2);
    for (int j = 0; j < ps.model().joints(); ++j) qt(j) += 0.3 * u(rng);
    qt(ps.model().i_px()) += 0.15 * u(rng);
    qt(ps.model().i_pz()) += -0.01 + 0.02 * u(rng);
    const VectorXd Qs = contact_Q(ps, qt, vt), Qc = contact_Q(pc, qt, vt);
    if (Qs.norm() == 0.0) continue;
    ++compared;
    EXPECT_LT((Qs - Qc).norm(), 1e-9 * (1.0 + Qs.norm())) << "trial " << trial;
  }
  EXPECT_GT(compared, 150);
  // A run: the module PD drives a bent shape over the box edge.
  Simulation ss(seg), sc(with_shape(seg, LinkShape::kCapsule, 1e-12));
  for (Simulation* sim : {&ss, &sc}) {
    auto& in = sim->plant().input();
    in.kp.setConstant(30);
    in.kd.setConstant(15);
    for (int j = 0; j < sim->plant().model().joints(); ++j) in.beta_ref(j) = 0.6 * std::sin(1.3 * j);
  }
  ASSERT_EQ(ss.advance_to(1.0), StepStatus::kOk);
  ASSERT_EQ(sc.advance_to(1.0), StepStatus::kOk);
  EXPECT_LT((ss.q() - sc.q()).cwiseAbs().maxCoeff(), 1e-8);
  EXPECT_LT((ss.v() - sc.v()).cwiseAbs().maxCoeff(), 1e-6);
}

// Both forward-dynamics solvers agree with the thick links' contact forces on.
TEST(LinkShapes, RecursiveAndDenseSolversAgree) {
  for (const auto& [shape, size] : {std::pair{LinkShape::kCapsule, 0.015}, std::pair{LinkShape::kBox, 0.03}}) {
    SCOPED_TRACE(to_string(shape));
    Scene s = with_shape(flat_scene(), shape, size);
    s.initial.pose = InitialPose::kGaitStart;
    s.boxes = {Box{.x_near = 0.1, .width = 0.11, .height = 0.04}};
    Plant p(s);
    VectorXd q, v, a_rec(p.nq()), a_dense(p.nq());
    p.initial_state(q, v);
    std::mt19937 rng(3);
    p.input().kp.setConstant(30);
    p.input().kd.setConstant(15);
    for (int trial = 0; trial < 50; ++trial) {
      VectorXd qt = q;
      qt(p.model().i_pz()) -= 0.004;
      qt(p.model().i_px()) += 0.002 * trial;
      const VectorXd vt = pedalwave::model::testing::random_v(p.model(), rng, 0.02);
      ASSERT_GT(contact_Q(p, qt, vt).norm(), 0.0);
      p.set_forward_solver(ForwardSolver::kRecursive);
      ASSERT_TRUE(p.acceleration(0, qt, vt, a_rec));
      p.set_forward_solver(ForwardSolver::kDense);
      ASSERT_TRUE(p.acceleration(0, qt, vt, a_dense));
      EXPECT_LT((a_rec - a_dense).norm(), 1e-9 * (1.0 + a_dense.norm())) << "trial " << trial;
    }
  }
}

// The implicit scheme's contact Jacobian in v (levers included) matches finite differences of the
// generalized contact force (as the segment's test: dF/dq keeps the normal's rotation out).
TEST(LinkShapes, ImplicitTermsMatchFiniteDifferences) {
  for (const auto& [shape, size] : {std::pair{LinkShape::kCapsule, 0.015}, std::pair{LinkShape::kBox, 0.03}}) {
    SCOPED_TRACE(to_string(shape));
    Scene s = with_shape(flat_scene(), shape, size);
    s.initial.pose = InitialPose::kGaitStart;
    s.ground.v_s = 0.5;  // the smooth part of the friction law
    Plant p(s);
    VectorXd q, v;
    p.initial_state(q, v);
    q(p.model().i_pz()) -= 0.003;
    v.setConstant(0.01);
    const int n = p.nq();
    ImplicitTerms it{MatrixXd::Zero(n, n), VectorXd::Zero(n), MatrixXd::Zero(n, n), MatrixXd::Zero(n, n)};
    ASSERT_TRUE(p.implicit_terms(0, q, v, it));
    const VectorXd Q0 = contact_Q(p, q, v);
    ASSERT_GT(Q0.norm(), 0.0);
    const double eps = 1e-7;
    for (int c = 0; c < n; ++c) {
      VectorXd vp = v, vm = v;
      vp(c) += eps;
      vm(c) -= eps;
      const VectorXd col = (contact_Q(p, q, vp) - contact_Q(p, q, vm)) / (2 * eps);
      for (int r = 0; r < p.model().nq1(); ++r)
        EXPECT_NEAR(it.dFdv(r, c), col(r), 1e-6 + 1e-5 * std::abs(col(r))) << "dF/dv " << r << "," << c;
    }
  }
}

TEST(LinkShapes, AccelerationAllocatesNothing) {
  for (const auto& [shape, size] : {std::pair{LinkShape::kCapsule, 0.015}, std::pair{LinkShape::kBox, 0.03}}) {
    Scene s = with_shape(flat_scene(), shape, size);
    s.initial.pose = InitialPose::kGaitStart;
    s.boxes = {Box{.x_near = 0.1}};
    Plant p(s);
    VectorXd q, v, a(p.nq());
    p.initial_state(q, v);
    q(p.model().i_pz()) -= 0.003;
    ASSERT_TRUE(p.acceleration(0, q, v, a));
    ImplicitTerms it{MatrixXd::Zero(p.nq(), p.nq()), VectorXd::Zero(p.nq()), MatrixXd::Zero(p.nq(), p.nq()),
                     MatrixXd::Zero(p.nq(), p.nq())};
    pedalwave::test::AllocationScope scope;
    for (int i = 0; i < 100; ++i) {
      ASSERT_TRUE(p.acceleration(0, q, v, a));
      ASSERT_TRUE(p.implicit_terms(0, q, v, it));
    }
    EXPECT_EQ(scope.count(), 0u) << to_string(shape);
  }
}

TEST(LinkShapes, BadShapeParametersAreRejected) {
  Scene s = flat_scene();
  s.robot.link_shape = LinkShape::kCapsule;  // no radius
  try {
    Plant p(s);
    FAIL() << "accepted a capsule of radius 0";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("link_radius = 0"), std::string::npos) << e.what();
  }
  s = with_shape(flat_scene(), LinkShape::kBox, 0.03);
  s.ground.law = FrictionLaw::kStickSlip;
  EXPECT_THROW(Plant{s}, std::invalid_argument);
}
