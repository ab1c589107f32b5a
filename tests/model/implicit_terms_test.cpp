// ImplicitTerms without the Jacobian (with_jacobian false), what implicit_contact's evaluations ask
// for while they keep a factored Jacobian (IntegratorOptions::jacobian_age): the same F, the same
// contact signature, D_q v from the contact point forces equal to the one from the Jacobian rows
// (to 1e-12 relative), dFdq and dFdv untouched; M without its Cholesky (check_mass false) the same
// M. Random states in contact with the ground and a box, segment, capsule and box links, flexible
// and rigid, N = 3 and 6. The signature follows the contacts carrying force and their friction
// branch.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "model_fixtures.hpp"
#include "pedalwave/model/plant.hpp"

using namespace pedalwave::model;

namespace {

Scene scene_of(int N, bool flexible, LinkShape shape) {
  Scene s;
  s.name = "implicit_terms";
  s.robot = paper_params(N);
  s.robot.joints = flexible ? JointModel::kFlexible : JointModel::kRigid;
  s.robot.link_shape = shape;
  if (shape == LinkShape::kCapsule) s.robot.link_radius = 0.01;
  if (shape == LinkShape::kBox) s.robot.link_height = 0.02;
  s.initial.theta = 0;
  s.boxes = {Box{.x_near = -0.05, .width = 0.11, .height = 0.06}};
  return s;
}

ImplicitTerms sized(int n, double s) {
  ImplicitTerms t;
  t.M = MatrixXd::Zero(n, n);
  t.F = VectorXd::Zero(n);
  t.dFdq = MatrixXd::Zero(n, n);
  t.dFdv = MatrixXd::Zero(n, n);
  t.dq_in_dv = s;
  t.dFdq_v = VectorXd::Zero(n);
  return t;
}

}  // namespace

TEST(ImplicitTerms, WithoutTheJacobianTheSameForcesSignatureAndDqv) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double s = 0.55e-3;
  const double nan = std::numeric_limits<double>::quiet_NaN();
  for (LinkShape shape : {LinkShape::kSegment, LinkShape::kCapsule, LinkShape::kBox}) {
    for (int N : {3, 6}) {
      for (bool flexible : {true, false}) {
        SCOPED_TRACE("shape " + std::to_string(static_cast<int>(shape)) + ", N = " + std::to_string(N) +
                     (flexible ? " flexible" : " rigid"));
        Plant p(scene_of(N, flexible, shape));
        const Model& m = p.model();
        const int n = m.nq();
        for (int j = 0; j < m.joints(); ++j) {
          p.input().kp(j) = 2.0 + 0.1 * j;
          p.input().kd(j) = 0.05;
        }
        p.faults().spring_scale(0) = 0.5;
        ImplicitTerms full = sized(n, s), lean = sized(n, s);
        lean.with_jacobian = false;
        lean.check_mass = false;
        int contacts = 0;
        for (int k = 0; k < 20; ++k) {
          VectorXd q = pedalwave::model::testing::random_q(m, rng);
          q(m.i_theta_N()) = 0.3 * u(rng);
          q(m.i_px()) = 0.1 * u(rng);
          q(m.i_pz()) = 0.02 * u(rng);
          const VectorXd v = pedalwave::model::testing::random_v(m, rng, k % 3 == 0 ? 1e-3 : 0.3);
          ASSERT_TRUE(p.implicit_terms(0.0, q, v, full));
          lean.dFdq.setConstant(nan);
          lean.dFdv.setConstant(nan);
          ASSERT_TRUE(p.implicit_terms(0.0, q, v, lean));
          ContactReport rep;
          p.report(q, v, rep);
          contacts += rep.active;
          EXPECT_EQ(lean.F, full.F) << "state " << k;
          EXPECT_EQ(lean.M, full.M) << "state " << k;
          EXPECT_EQ(lean.signature, full.signature) << "state " << k;
          EXPECT_EQ(lean.signature == 0, rep.active == 0) << "state " << k;
          EXPECT_LE((lean.dFdq_v - full.dFdq_v).norm(), 1e-12 * (1.0 + full.dFdq_v.norm())) << "state " << k;
          EXPECT_TRUE(lean.dFdq.array().isNaN().all() && lean.dFdv.array().isNaN().all())
              << "state " << k << ": the Jacobian was written";
        }
        EXPECT_GT(contacts, 20) << "too few contacts to test anything";
      }
    }
  }
}

// One robot lying on the flat ground: the signature stays while only the contact forces' size
// changes (pressed 0.1 mm deeper), changes when a point's friction leaves the stick band (a slide
// faster than v_s) or changes direction, and is 0 in the air.
TEST(ImplicitTerms, SignatureFollowsContactsAndFrictionBranches) {
  Scene s;
  s.name = "signature";
  s.initial.theta = 0;
  Plant p(s);
  const Model& m = p.model();
  VectorXd q, v;
  p.initial_state(q, v);
  q(m.i_pz()) -= 1e-3;  // 1 mm into the ground: every point carries force
  ImplicitTerms t = sized(m.nq(), 0.55e-3);
  t.with_jacobian = false;
  auto sig = [&](const VectorXd& qq, const VectorXd& vv) {
    EXPECT_TRUE(p.implicit_terms(0.0, qq, vv, t));
    return t.signature;
  };
  const std::uint64_t rest = sig(q, v);
  EXPECT_NE(rest, 0u);
  VectorXd q2 = q;
  q2(m.i_pz()) -= 1e-4;
  EXPECT_EQ(sig(q2, v), rest) << "deeper, same branches";
  VectorXd v2 = v;
  v2(m.i_px()) = 0.5 * s.ground.v_s;
  EXPECT_EQ(sig(q, v2), rest) << "inside the stick band";
  v2(m.i_px()) = 10 * s.ground.v_s;
  const std::uint64_t slide = sig(q, v2);
  EXPECT_NE(slide, rest) << "sliding forward";
  v2(m.i_px()) = -10 * s.ground.v_s;
  EXPECT_NE(sig(q, v2), slide) << "sliding backward";
  EXPECT_NE(sig(q, v2), rest);
  q2(m.i_pz()) += 0.1;
  EXPECT_EQ(sig(q2, v), 0u) << "in the air";
}
