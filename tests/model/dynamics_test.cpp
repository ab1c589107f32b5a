// The equations of motion checked against themselves: the mass matrix against an independent
// point-mass assembly, Coriolis against Christoffel symbols of M, gravity and springs against the
// gradients of their potentials, and the evaluation allocating nothing.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <random>

#include "alloc_counter.hpp"
#include "model_fixtures.hpp"

using namespace pedalwave::model;
using pedalwave::model::testing::random_q;
using pedalwave::model::testing::random_v;

namespace {
struct Case {
  int N;
  JointModel joints;
};
std::string name(const ::testing::TestParamInfo<Case>& info) {
  std::string s = "N";  // (built with += : GCC 12 warns falsely on operator+ here)
  s += std::to_string(info.param.N);
  s += info.param.joints == JointModel::kFlexible ? "_flexible" : "_rigid";
  return s;
}
Params params_of(const Case& c) {
  Params p = paper_params(c.N);
  p.joints = c.joints;
  // Unequal springs so a swapped index cannot hide.
  if (c.joints == JointModel::kFlexible)
    for (int j = 0; j < c.N - 1; ++j) p.K.push_back(2.0 + 0.5 * j);
  return p;
}
// ∂θ_i/∂q straight from θ_i = θ_N + Σ_{k≥i} α_k.
Eigen::RowVectorXd dtheta_dq(const Model& m, int i) {
  Eigen::RowVectorXd r = Eigen::RowVectorXd::Zero(m.nq());
  for (int k = i; k < m.N() - 1; ++k) r(m.i_alpha(k)) = 1.0;
  r(m.i_theta_N()) = 1.0;
  return r;
}
MatrixXd mass_at(const Model& m, Data& d, const VectorXd& q) {
  update_kinematics(m, d, q, VectorXd());
  compute_mass_matrix(m, d);
  return d.M;
}
}  // namespace

class Dynamics : public ::testing::TestWithParam<Case> {};

TEST_P(Dynamics, MassMatrixIsSymmetricPositiveDefinite) {
  const Model m(params_of(GetParam()));
  Data d(m);
  std::mt19937 rng(11);
  for (int trial = 0; trial < 50; ++trial) {
    const MatrixXd M = mass_at(m, d, random_q(m, rng));
    EXPECT_LT((M - M.transpose()).norm(), 1e-15 * M.norm());
    const Eigen::SelfAdjointEigenSolver<MatrixXd> es(M);
    EXPECT_GT(es.eigenvalues().minCoeff(), 0.0);
    EXPECT_TRUE(d.mass_valid);
  }
}

TEST_P(Dynamics, MassMatrixEqualsPointMassAssembly) {
  const Model m(params_of(GetParam()));
  const Params& p = m.params();
  Data d(m);
  std::mt19937 rng(12);
  MatrixXd J(2, m.nq());
  for (int trial = 0; trial < 20; ++trial) {
    const VectorXd q = random_q(m, rng);
    const MatrixXd M = mass_at(m, d, q);
    // Σ over point masses Jᵀ m J (links at their COMs, rotors at the joints) ...
    MatrixXd Mref = MatrixXd::Zero(m.nq(), m.nq());
    for (int i = 0; i < m.N(); ++i) {
      point_jacobian(m, d, Model::point_com(i), J);
      Mref += p.m_l * J.transpose() * J;
    }
    for (int j = 0; j < m.joints(); ++j) {
      point_jacobian(m, d, Model::point_joint(j), J);
      Mref += p.m_r * J.transpose() * J;
    }
    // ... plus link rotation I_l and rotor spin I_r (θ̇^r_j = θ̇_j − n β̇_j).
    for (int i = 0; i < m.N(); ++i) {
      const Eigen::RowVectorXd c = dtheta_dq(m, i);
      Mref += p.I_l * c.transpose() * c;
    }
    for (int j = 0; j < m.joints(); ++j) {
      Eigen::RowVectorXd r = dtheta_dq(m, j);
      if (m.flexible())
        r(m.i_beta(j)) -= p.n;
      else
        r(m.i_alpha(j)) -= p.n;
      Mref += p.I_r * r.transpose() * r;
    }
    EXPECT_LT((M - Mref).cwiseAbs().maxCoeff(), 1e-12 * std::max(1.0, Mref.cwiseAbs().maxCoeff()))
        << "max |M - Mref| = " << (M - Mref).cwiseAbs().maxCoeff();
  }
}

TEST_P(Dynamics, CoriolisMatchesChristoffelSymbolsOfM) {
  const Model m(params_of(GetParam()));
  Data d(m);
  std::mt19937 rng(13);
  const int n = m.nq();
  for (int trial = 0; trial < 5; ++trial) {
    const VectorXd q = random_q(m, rng);
    const VectorXd v = random_v(m, rng, 2.0);
    // dM[k] = ∂M/∂q_k by central differences.
    std::vector<MatrixXd> dM(n);
    const double eps = 1e-6;
    for (int k = 0; k < n; ++k) {
      VectorXd qp = q, qm = q;
      qp(k) += eps;
      qm(k) -= eps;
      dM[k] = (mass_at(m, d, qp) - mass_at(m, d, qm)) / (2 * eps);
    }
    // c_i = Σ_jk (∂_k M_ij − ½ ∂_i M_jk) v_j v_k
    VectorXd cref = VectorXd::Zero(n);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j)
        for (int k = 0; k < n; ++k) cref(i) += (dM[k](i, j) - 0.5 * dM[i](j, k)) * v(j) * v(k);
    update_kinematics(m, d, q, v);
    compute_mass_matrix(m, d);
    compute_bias(m, d, q);
    EXPECT_LT((d.coriolis - cref).norm(), 1e-7 * std::max(1e-3, cref.norm()))
        << "c = " << d.coriolis.transpose() << "\nref = " << cref.transpose();
    // Ṁ − 2C skew: equivalently q̇ᵀ (Ṁ q̇ − 2 c) = 0 along any velocity (power balance).
    MatrixXd Mdot = MatrixXd::Zero(n, n);
    for (int k = 0; k < n; ++k) Mdot += dM[k] * v(k);
    EXPECT_NEAR(v.dot(Mdot * v - 2 * d.coriolis), 0.0, 1e-7 * std::max(1.0, (Mdot * v).norm()));
  }
}

TEST_P(Dynamics, GravityAndSpringAreGradientsOfTheirPotentials) {
  const Model m(params_of(GetParam()));
  Data d(m);
  std::mt19937 rng(14);
  const VectorXd q = random_q(m, rng);
  update_kinematics(m, d, q, VectorXd::Zero(m.nq()));
  compute_mass_matrix(m, d);
  compute_bias(m, d, q);
  Data dd(m);
  for (int c = 0; c < m.nq(); ++c) {
    VectorXd qp = q, qm = q;
    qp(c) += 1e-6;
    qm(c) -= 1e-6;
    update_kinematics(m, dd, qp, VectorXd());
    const double vgp = gravity_energy(m, dd, qp), vsp = spring_energy(m, qp);
    update_kinematics(m, dd, qm, VectorXd());
    const double vgm = gravity_energy(m, dd, qm), vsm = spring_energy(m, qm);
    EXPECT_NEAR(d.gravity(c), (vgp - vgm) / 2e-6, 1e-7) << "coordinate " << c;
    EXPECT_NEAR(d.spring(c), (vsp - vsm) / 2e-6, 1e-7) << "coordinate " << c;
  }
}

TEST_P(Dynamics, ForwardDynamicsSolvesTheEquationsAndAllocatesNothing) {
  const Model m(params_of(GetParam()));
  Data d(m);
  std::mt19937 rng(15);
  const VectorXd q = random_q(m, rng), v = random_v(m, rng);
  VectorXd u = VectorXd::Random(m.joints()), Q = VectorXd::Random(m.nq()), a(m.nq());
  for (const ForwardSolver s : {ForwardSolver::kRecursive, ForwardSolver::kDense}) {
    ASSERT_TRUE(forward_dynamics(m, d, q, v, u, Q, a, s));  // warm-up
    {
      pedalwave::test::AllocationScope scope;
      for (int i = 0; i < 100; ++i) ASSERT_TRUE(forward_dynamics(m, d, q, v, u, Q, a, s));
      EXPECT_EQ(scope.count(), 0u) << "forward_dynamics allocated";
    }
    // Residual of M a + bias − B u − Q, with the assembled M and the bias at (q, v) (forward
    // dynamics only factors M, or with the recursive solver forms neither).
    compute_mass_matrix(m, d);
    compute_bias(m, d, q);
    VectorXd Bu = VectorXd::Zero(m.nq());
    Bu.segment(m.flexible() ? m.i_beta(0) : 0, m.joints()) = u;
    EXPECT_LT((d.M * a + d.bias - Bu - Q).norm(), 1e-9 * (1 + Q.norm() + d.bias.norm()))
        << (s == ForwardSolver::kDense ? "dense" : "recursive");
  }
}

// solve_mass eliminates the motor block through its Schur complement: it must agree with a
// general dense factorization of the assembled M, including where M is badly conditioned (heavy
// gearing n = 1000 with a tiny rotor, the hard cases of model-spec.md §10).
TEST_P(Dynamics, StructuredSolveAgreesWithDenseFactorization) {
  for (const double n_gear : {255.0, 1000.0}) {
    Params p = params_of(GetParam());
    p.n = n_gear;
    if (n_gear > 300) p.I_r = 1e-9;
    const Model m(p);
    Data d(m);
    std::mt19937 rng(17);
    for (int trial = 0; trial < 20; ++trial) {
      const MatrixXd M = mass_at(m, d, random_q(m, rng));
      const VectorXd b = VectorXd::Random(m.nq());
      VectorXd x = b;
      solve_mass(m, d, x);
      const VectorXd ref = M.ldlt().solve(b);
      const Eigen::SelfAdjointEigenSolver<MatrixXd> es(M);
      const double cond = es.eigenvalues().maxCoeff() / es.eigenvalues().minCoeff();
      EXPECT_LT((x - ref).norm(), 1e-14 * cond * ref.norm()) << "n = " << n_gear << ", cond " << cond;
      EXPECT_LT((M * x - b).norm(), 1e-12 * (M.norm() * x.norm() + b.norm())) << "n = " << n_gear;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Cases, Dynamics,
                         ::testing::Values(Case{2, JointModel::kFlexible}, Case{6, JointModel::kFlexible},
                                           Case{6, JointModel::kRigid}, Case{13, JointModel::kFlexible},
                                           Case{13, JointModel::kRigid}, Case{64, JointModel::kFlexible}),
                         name);

TEST(DynamicsExtra, PaperRigidVariantDropsTheReflectedInertia) {
  Params p = paper_params(6);
  p.joints = JointModel::kRigid;
  const Model exact(p);
  p.rigid_variant = RigidVariant::kPaper;
  const Model paper(p);
  Data de(exact), dp(paper);
  std::mt19937 rng(16);
  const VectorXd q = random_q(exact, rng);
  const MatrixXd diff = mass_at(exact, de, q) - mass_at(paper, dp, q);
  // Difference = I_r Σ_j [(c_j − n e_j)ᵀ(c_j − n e_j) − c_jᵀ c_j]: diagonal α_j entries grow by n² I_r.
  for (int j = 0; j < 5; ++j)
    EXPECT_NEAR(diff(j, j), p.I_r * (p.n * p.n - 2 * p.n), 1e-12);
}
