// StructuredLU (integrators.hpp): implicit_contact's linear solve, the diagonal motor block
// eliminated first (ImplicitTerms::n_diag), against a dense pivoted LU of the same matrix
// A = M − θh ∂F/∂v − θ²h² ∂F/∂q assembled by the plant at random states in contact (ground and a
// box, regularized friction inside and outside the stick band, module PD, a spring fault), N = 2 … 64,
// flexible and rigid, both within cond(A)·ε of an extended-precision solution (and to 1e-10 of the
// dense LU where cond(A) < 1e5); the motor block it assumes diagonal is; a zero pivot is reported;
// no allocation.
#include <gtest/gtest.h>

#include <Eigen/LU>
#include <Eigen/SVD>
#include <limits>
#include <cmath>
#include <random>

#include "alloc_counter.hpp"
#include "model_fixtures.hpp"
#include "pedalwave/model/plant.hpp"

using namespace pedalwave::model;

namespace {

Scene scene_of(int N, bool flexible) {
  Scene s;
  s.name = "structured_solve";
  s.robot = paper_params(N);
  s.robot.joints = flexible ? JointModel::kFlexible : JointModel::kRigid;
  s.initial.theta = 0;
  s.boxes = {Box{.x_near = -0.05, .width = 0.11, .height = 0.06}};
  return s;
}

// A random state with part of the body under the ground (z = 0) or inside the box: joint angles
// within ±1 rad, the mean position near the box; velocities of ±0.3 m/s or, every third state,
// within the stick band (±v_s).
void random_state(const Model& m, std::mt19937& rng, int k, VectorXd& q, VectorXd& v) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  q = pedalwave::model::testing::random_q(m, rng);
  q(m.i_theta_N()) = 0.3 * u(rng);
  q(m.i_px()) = 0.1 * u(rng);
  q(m.i_pz()) = 0.02 * u(rng);
  v = pedalwave::model::testing::random_v(m, rng, k % 3 == 0 ? 1e-3 : 0.3);
}

}  // namespace

TEST(StructuredSolve, EqualsTheDenseLUOnThePlantsMatrices) {
  using MatL = Eigen::Matrix<long double, Eigen::Dynamic, Eigen::Dynamic>;
  using VecL = Eigen::Matrix<long double, Eigen::Dynamic, 1>;
  const double eps = std::numeric_limits<double>::epsilon();
  std::mt19937 rng(19);
  const double h = 1e-3, th = 0.55, a = th * h, b = th * th * h * h;
  for (int N : {2, 3, 6, 12, 24, 64}) {
    for (bool flexible : {true, false}) {
      SCOPED_TRACE("N = " + std::to_string(N) + (flexible ? " flexible" : " rigid"));
      Plant p(scene_of(N, flexible));
      const Model& m = p.model();
      const int n = m.nq();
      for (int j = 0; j < m.joints(); ++j) {
        p.input().kp(j) = 2.0 + 0.1 * j;
        p.input().kd(j) = 0.05;
      }
      p.faults().spring_scale(0) = 0.5;
      ImplicitTerms t;
      t.M = MatrixXd::Zero(n, n);
      t.F = VectorXd::Zero(n);
      t.dFdq = MatrixXd::Zero(n, n);
      t.dFdv = MatrixXd::Zero(n, n);
      StructuredLU slu(n);
      int with_contact = 0;
      for (int k = 0; k < 12; ++k) {
        VectorXd q, v;
        random_state(m, rng, k, q, v);
        ASSERT_TRUE(p.implicit_terms(0.0, q, v, t));
        EXPECT_EQ(t.n_diag, flexible ? N - 1 : 0);
        // The block StructuredLU takes as diagonal is.
        const int n1 = n - t.n_diag;
        for (int r = n1; r < n; ++r)
          for (int c = n1; c < n; ++c)
            if (r != c) {
              ASSERT_EQ(t.M(r, c), 0.0);
              ASSERT_EQ(t.dFdq(r, c), 0.0);
              ASSERT_EQ(t.dFdv(r, c), 0.0);
            }
        ContactReport rep;
        p.report(q, v, rep);
        with_contact += rep.active > 0;
        const MatrixXd A = t.M - a * t.dFdv - b * t.dFdq;
        const VectorXd rhs = h * t.F;
        const VectorXd x_ref = A.partialPivLu().solve(rhs);
        slu.matrix() = A;
        ASSERT_TRUE(slu.factor(t.n_diag));
        VectorXd x = rhs;
        slu.solve(x);
        slu.matrix() = A;
        ASSERT_TRUE(slu.factor(0));
        VectorXd x0 = rhs;
        slu.solve(x0);
        // Against the solution in extended precision (long double, full pivoting): both solves are
        // backward stable, so each is within ~cond(A)·ε of it (cond up to 1e9 at N = 64: the dense
        // LU itself is 1e-8 off there, StructuredLU as close or closer).
        const VecL xl = MatL(A.cast<long double>()).fullPivLu().solve(VecL(rhs.cast<long double>()));
        const Eigen::JacobiSVD<MatrixXd> svd(A);
        const double cond = svd.singularValues()(0) / svd.singularValues()(n - 1);
        const double bound = 1e-10 + cond * eps;
        const auto rel = [&](const VectorXd& y) {
          return static_cast<double>((xl - y.cast<long double>()).norm() / xl.norm());
        };
        EXPECT_LE(rel(x), bound) << "state " << k << ", cond " << cond;
        EXPECT_LE(rel(x0), bound) << "state " << k << ", nd = 0, cond " << cond;
        EXPECT_LE(rel(x_ref), bound) << "state " << k << ", Eigen's LU, cond " << cond;
        // And against today's dense solve directly.
        EXPECT_LE((x - x_ref).norm(), 2 * bound * x_ref.norm()) << "state " << k;
        if (cond < 1e5) {
          EXPECT_LE((x - x_ref).norm(), 1e-10 * x_ref.norm()) << "state " << k;
        }
      }
      EXPECT_GE(with_contact, 8) << "the states must exercise the contact Jacobians";
    }
  }
}

// A zero on the diagonal block, or a singular Schur complement, is reported, never a crash.
TEST(StructuredSolve, ZeroPivotIsReported) {
  StructuredLU slu(4);
  slu.matrix() = MatrixXd::Identity(4, 4);
  slu.matrix()(3, 3) = 0.0;
  EXPECT_FALSE(slu.factor(1));
  slu.matrix() = MatrixXd::Identity(4, 4);
  slu.matrix()(1, 1) = 0.0;
  EXPECT_FALSE(slu.factor(2));
  slu.matrix() = MatrixXd::Identity(4, 4);
  EXPECT_TRUE(slu.factor(2));
}

TEST(StructuredSolve, AllocatesNothing) {
  const int n = 13;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  MatrixXd A = MatrixXd::Zero(n, n);
  for (int r = 0; r < n; ++r)
    for (int c = 0; c < n; ++c) A(r, c) = (r >= 8 && c >= 8) ? (r == c ? 2.0 : 0.0) : u(rng);
  A.topLeftCorner(8, 8) += 5.0 * MatrixXd::Identity(8, 8);
  StructuredLU slu(n);
  VectorXd x = VectorXd::Ones(n);
  pedalwave::test::AllocationScope scope;
  slu.matrix() = A;
  const bool ok = slu.factor(5);
  slu.solve(x);
  EXPECT_EQ(scope.count(), 0u);
  EXPECT_TRUE(ok);
  EXPECT_LE((A * x - VectorXd::Ones(n)).norm(), 1e-12);
}
