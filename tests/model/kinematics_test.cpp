// Kinematics checked against an independent, direct transcription of model-spec.md §2
// (tail-tip recursion, x_0 eliminated through p), and Jacobians against finite differences.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "model_fixtures.hpp"

using namespace pedalwave::model;
using pedalwave::model::testing::random_q;
using pedalwave::model::testing::random_v;

namespace {
// Positions of the 2N+1 body points straight from the spec (no shared code with the model).
std::vector<Vec2> spec_points(const Params& p, const VectorXd& q) {
  const int N = p.N;
  std::vector<double> th(N);
  th[N - 1] = q(N - 1);
  for (int i = N - 2; i >= 0; --i) th[i] = th[i + 1] + q(i);
  // Link COMs relative to the tail tip, then x_0 from p = mean of the COMs.
  std::vector<Vec2> com(N);
  Vec2 run(0, 0), mean(0, 0);
  for (int i = 0; i < N; ++i) {
    com[i] = run + p.l * Vec2(std::cos(th[i]), std::sin(th[i]));
    run += 2 * p.l * Vec2(std::cos(th[i]), std::sin(th[i]));
    mean += com[i] / N;
  }
  const Vec2 x0 = Vec2(q(N), q(N + 1)) - mean;
  std::vector<Vec2> pts;
  Vec2 tip = x0;
  pts.push_back(tip);
  for (int i = 0; i < N; ++i) {
    pts.push_back(x0 + com[i]);
    tip += 2 * p.l * Vec2(std::cos(th[i]), std::sin(th[i]));
    pts.push_back(tip);
  }
  return pts;
}
}  // namespace

class Kinematics : public ::testing::TestWithParam<int> {};

TEST_P(Kinematics, PointsMatchTheSpecTranscription) {
  const Model m(paper_params(GetParam()));
  Data d(m);
  std::mt19937 rng(1);
  for (int trial = 0; trial < 20; ++trial) {
    const VectorXd q = random_q(m, rng);
    update_kinematics(m, d, q, VectorXd());
    const auto ref = spec_points(m.params(), q);
    ASSERT_EQ(static_cast<int>(ref.size()), m.points());
    for (int k = 0; k < m.points(); ++k)
      EXPECT_LT((point_position(m, d, q, k) - ref[k]).norm(), 1e-13) << "point " << k;
    // p is the mean of the link COMs, and links are 2l long.
    Vec2 mean(0, 0);
    for (int i = 0; i < m.N(); ++i) mean += point_position(m, d, q, Model::point_com(i)) / m.N();
    EXPECT_LT((mean - Vec2(q(m.i_px()), q(m.i_pz()))).norm(), 1e-13);
    for (int j = 0; j < m.joints(); ++j) {
      const double len = (point_position(m, d, q, Model::point_joint(j)) -
                          point_position(m, d, q, Model::point_joint(j) - 2)).norm();
      EXPECT_NEAR(len, 2 * m.params().l, 1e-13);
    }
  }
}

TEST_P(Kinematics, JacobiansMatchFiniteDifferencesAndVelocities) {
  const Model m(paper_params(GetParam()));
  Data d(m);
  std::mt19937 rng(2);
  MatrixXd J(2, m.nq());
  for (int trial = 0; trial < 5; ++trial) {
    const VectorXd q = random_q(m, rng);
    const VectorXd v = random_v(m, rng);
    update_kinematics(m, d, q, v);
    for (int k = 0; k < m.points(); ++k) {
      point_jacobian(m, d, k, J);
      // Central differences of the independent spec transcription.
      const double eps = 1e-6;
      for (int c = 0; c < m.nq(); ++c) {
        VectorXd qp = q, qm = q;
        qp(c) += eps;
        qm(c) -= eps;
        const Vec2 fd = (spec_points(m.params(), qp)[k] - spec_points(m.params(), qm)[k]) / (2 * eps);
        EXPECT_NEAR(J(0, c), fd.x(), 1e-8) << "point " << k << " col " << c;
        EXPECT_NEAR(J(1, c), fd.y(), 1e-8) << "point " << k << " col " << c;
      }
      // Velocity is J q̇, and add_point_force is Jᵀ f.
      EXPECT_LT((point_velocity(m, d, v, k) - J * v).norm(), 1e-12);
      const Vec2 f(0.3, -1.7);
      VectorXd Q = VectorXd::Zero(m.nq());
      add_point_force(m, d, k, f, Q);
      EXPECT_LT((Q - J.transpose() * f).norm(), 1e-12);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(N, Kinematics, ::testing::Values(2, 3, 6, 12));

TEST(KinematicsExtra, LinkTorqueIsTheAngleGradient) {
  const Model m(paper_params(5));
  std::mt19937 rng(3);
  const VectorXd q = random_q(m, rng);
  VectorXd th(m.N()), thp(m.N()), thm(m.N());
  for (int i = 0; i < m.N(); ++i) {
    VectorXd Q = VectorXd::Zero(m.nq());
    add_link_torque(m, i, 1.0, Q);
    for (int c = 0; c < m.nq(); ++c) {
      VectorXd qp = q, qm = q;
      qp(c) += 1e-6;
      qm(c) -= 1e-6;
      absolute_angles(m, qp, thp);
      absolute_angles(m, qm, thm);
      EXPECT_NEAR(Q(c), (thp(i) - thm(i)) / 2e-6, 1e-8);
    }
  }
}
