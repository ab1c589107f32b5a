// The O(N) recursive forward dynamics (recursive_dynamics.cpp) against the dense reference solver
// (dynamics.cpp: assembled mass matrix, Schur complement of the motor block, Cholesky): the same
// q̈ to rounding for N = 2 … 64, flexible and rigid (both variants), in the air and under contact
// forces; no allocation; and a plant stepped with either solver following the same trajectory.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <cmath>
#include <cstdio>

#include <algorithm>
#include <random>
#include <string>

#include "alloc_counter.hpp"
#include "model_fixtures.hpp"
#include "pedalwave/model/plant.hpp"

using namespace pedalwave::model;
using pedalwave::model::testing::random_q;
using pedalwave::model::testing::random_v;

namespace {

constexpr double kRelTol = 1e-12;

struct Variant {
  const char* name;
  JointModel joints;
  RigidVariant rigid;
};
constexpr Variant kVariants[] = {
    {"flexible", JointModel::kFlexible, RigidVariant::kExactLimit},
    {"rigid", JointModel::kRigid, RigidVariant::kExactLimit},
    {"rigid_paper", JointModel::kRigid, RigidVariant::kPaper},
};

Params params_of(int N, const Variant& v) {
  Params p = paper_params(N);
  p.joints = v.joints;
  p.rigid_variant = v.rigid;
  // Unequal springs so a swapped index cannot hide.
  for (int j = 0; j < N - 1; ++j) p.K.push_back(2.0 + 0.5 * (j % 7));
  return p;
}

// Contact-like generalized forces: Σ J_kᵀ f_k over a few random body points (zero on β), the
// way the plant builds its ground, box and friction forces.
VectorXd contact_forces(const Model& m, Data& d, std::mt19937& rng) {
  std::uniform_int_distribution<int> point(0, m.points() - 1);
  std::uniform_real_distribution<double> f(-3.0, 3.0);
  VectorXd Q = VectorXd::Zero(m.nq());
  for (int c = 0; c < 4; ++c) add_point_force(m, d, point(rng), Vec2(f(rng), std::abs(f(rng))), Q);
  return Q;
}

// An extended-precision reference for q̈ (long double, 64-bit mantissa on x86-64): M and the bias
// assembled from the point masses' Jacobians in q (model-spec.md §2–4, independently of both
// solvers), M q̈ = B u + Q − bias solved by a pivoted LU. Its own error is ~cond(M)·1e-19.
using LD = long double;
using VecL = Eigen::Matrix<LD, Eigen::Dynamic, 1>;
using MatL = Eigen::Matrix<LD, Eigen::Dynamic, Eigen::Dynamic>;
VectorXd reference_qdd(const Model& m, const VectorXd& q, const VectorXd& v, const VectorXd& u,
                       const VectorXd& Q, double* cond = nullptr) {
  const Params& p = m.params();
  const int N = m.N(), n = m.nq(), n1 = m.nq1();
  // θ_i = θ_N + Σ_{k≥i} α_k: ∂θ_i/∂q is 1 on α_i … α_{N-2} and θ_N (columns i … N-1).
  VecL th(N), thd(N);
  th(N - 1) = q(m.i_theta_N());
  thd(N - 1) = v(m.i_theta_N());
  for (int i = N - 2; i >= 0; --i) {
    th(i) = th(i + 1) + LD(q(m.i_alpha(i)));
    thd(i) = thd(i + 1) + LD(v(m.i_alpha(i)));
  }
  MatL M = MatL::Zero(n, n);
  VecL bias = VecL::Zero(n);
  // Point masses: position p + Σ_i c_bi e(θ_i); ∂/∂α_k = Σ_{i≤k} c_bi J e(θ_i) (k < N: α_k, θ_N),
  // ∂/∂p = 1; J̇ q̇ = −Σ_i c_bi θ̇_i² e(θ_i). Only the first N+2 columns are nonzero.
  MatL Jb(2, n1);
  for (int b = 0; b < m.points(); ++b) {
    const LD mb = m.point_mass()(b);
    if (mb == 0) continue;
    LD sx = 0, sz = 0, ax = 0, az = 0;
    for (int i = 0; i < N; ++i) {
      const LD c = m.point_coeff()(b, i), ci = std::cos(th(i)), si = std::sin(th(i));
      sx -= c * si;
      sz += c * ci;
      Jb(0, i) = sx;
      Jb(1, i) = sz;
      ax -= c * thd(i) * thd(i) * ci;
      az -= c * thd(i) * thd(i) * si;
    }
    Jb(0, N) = 1, Jb(1, N) = 0, Jb(0, N + 1) = 0, Jb(1, N + 1) = 1;
    for (int r = 0; r < n1; ++r) {
      for (int c = 0; c < n1; ++c) M(r, c) += mb * (Jb(0, r) * Jb(0, c) + Jb(1, r) * Jb(1, c));
      bias(r) += mb * (Jb(0, r) * ax + Jb(1, r) * (az + LD(p.g)));
    }
  }
  // Link rotation I_l θ̇_i², rotor spin I_r (L q̇)_j² (L: rotor spin map, exact small integers and n).
  for (int i = 0; i < N; ++i)
    for (int r = i; r < N; ++r)
      for (int c = i; c < N; ++c) M(r, c) += LD(p.I_l);
  for (int j = 0; j < m.joints(); ++j) {
    int nz[kMaxLinks + 2], cnt = 0;
    for (int c = 0; c < n; ++c)
      if (m.L()(j, c) != 0.0) nz[cnt++] = c;
    for (int a = 0; a < cnt; ++a)
      for (int b = 0; b < cnt; ++b)
        M(nz[a], nz[b]) += LD(p.I_r) * LD(m.L()(j, nz[a])) * LD(m.L()(j, nz[b]));
  }
  VecL rhs = -bias;
  if (m.flexible())
    for (int j = 0; j < m.joints(); ++j) {
      const LD tau = LD(m.K()(j)) * (LD(q(m.i_beta(j))) - LD(q(m.i_alpha(j))));
      rhs(m.i_alpha(j)) += tau;
      rhs(m.i_beta(j)) -= tau;
    }
  if (Q.size() > 0) rhs += Q.cast<LD>();
  if (u.size() > 0) rhs.segment(m.flexible() ? m.i_beta(0) : 0, m.joints()) += u.cast<LD>();
  if (cond) {
    const Eigen::SelfAdjointEigenSolver<MatrixXd> es(M.cast<double>());
    *cond = es.eigenvalues().maxCoeff() / es.eigenvalues().minCoeff();
  }
  return M.llt().solve(rhs).cast<double>();
}

// Relative difference max|a − b| / max|b| (max(…, 1e-300) guards an all-zero b).
double rel_diff(const VectorXd& a, const VectorXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / std::max(b.cwiseAbs().maxCoeff(), 1e-300);
}

}  // namespace

// Every N from 2 to 64, each variant, random states: in the air (u only), with contact forces, and
// with an arbitrary generalized force on every coordinate (β and θ_N rows included).
// - The recursive q̈ is within 1e-12 (relative, max norm) of the extended-precision reference.
// - It equals the dense solver's to 1e-12 plus the dense solver's own error against that reference:
//   M's condition number grows to ~1e7 at N = 64 and the dense factorization's error with it (to
//   ~1e-10, see AccuracyAgainstExtendedPrecision), so a plain 1e-12 between the two holds only
//   while the dense solver is itself that accurate: asserted for N ≤ 8.
TEST(RecursiveDynamics, EqualsDenseSolverForEveryN) {
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> uu(-0.5, 0.5);
  double worst_ref = 0.0, worst_dense = 0.0;
  std::string at_ref, at_dense;
  for (const Variant& var : kVariants) {
    for (int N = 2; N <= kMaxLinks; ++N) {
      const Model m(params_of(N, var));
      Data dr(m), dd(m);
      VectorXd u(m.joints()), ar(m.nq()), ad(m.nq());
      for (int trial = 0; trial < 3; ++trial) {
        const VectorXd q = random_q(m, rng), v = random_v(m, rng, 2.0);
        for (int j = 0; j < m.joints(); ++j) u(j) = uu(rng);
        update_kinematics(m, dd, q, v);
        VectorXd Q;  // 0: in the air; 1: contact forces; 2: everything
        if (trial == 1) Q = contact_forces(m, dd, rng);
        if (trial == 2) Q = VectorXd::Random(m.nq());
        ASSERT_TRUE(forward_dynamics(m, dd, q, v, u, Q, ad, ForwardSolver::kDense));
        ASSERT_TRUE(forward_dynamics(m, dr, q, v, u, Q, ar, ForwardSolver::kRecursive));
        const VectorXd ref = reference_qdd(m, q, v, u, Q);
        const double e_ref = rel_diff(ar, ref), e_dense = rel_diff(ar, ad);
        const std::string at = std::string(var.name) + " N=" + std::to_string(N) + " trial " +
                               std::to_string(trial);
        if (e_ref > worst_ref) worst_ref = e_ref, at_ref = at;
        if (e_dense > worst_dense) worst_dense = e_dense, at_dense = at;
        EXPECT_LE(e_ref, kRelTol) << at << "\nrecursive " << ar.transpose() << "\nreference "
                                  << ref.transpose();
        EXPECT_LE(e_dense, kRelTol + 1.5 * rel_diff(ad, ref)) << at;
        if (N <= 8) {
          EXPECT_LE(e_dense, kRelTol) << at;
        }
      }
    }
  }
  std::printf("worst relative difference: recursive vs extended precision %.3g (%s), "
              "recursive vs dense %.3g (%s)\n",
              worst_ref, at_ref.c_str(), worst_dense, at_dense.c_str());
}

// The hard parameter corners of model-spec.md §10 (heavy gearing with a tiny rotor, stiff springs
// with heavy rotors, long chains), under contact forces: the same two checks.
TEST(RecursiveDynamics, EqualsDenseSolverInHardCases) {
  std::mt19937 rng(7);
  for (const Variant& var : kVariants) {
    for (const int N : {2, 6, 50, 64}) {
      for (const int c : {0, 1, 2}) {
        Params p = params_of(N, var);
        if (c == 1) {
          p.n = 1000.0;
          p.I_r = 1e-9;
        }
        if (c == 2) {
          for (double& k : p.K) k = 1e4;
          p.m_r = 0.2;
        }
        const Model m(p);
        Data dr(m), dd(m);
        VectorXd ar(m.nq()), ad(m.nq());
        const VectorXd u = VectorXd::Random(m.joints());
        for (int trial = 0; trial < 3; ++trial) {
          const VectorXd q = random_q(m, rng, 0.01), v = random_v(m, rng, 3.0);
          update_kinematics(m, dd, q, v);
          const VectorXd Q = contact_forces(m, dd, rng);
          ASSERT_TRUE(forward_dynamics(m, dd, q, v, u, Q, ad, ForwardSolver::kDense));
          ASSERT_TRUE(forward_dynamics(m, dr, q, v, u, Q, ar, ForwardSolver::kRecursive));
          const VectorXd ref = reference_qdd(m, q, v, u, Q);
          EXPECT_LE(rel_diff(ar, ref), kRelTol) << var.name << " N = " << N << " case " << c;
          EXPECT_LE(rel_diff(ar, ad), kRelTol + 1.5 * rel_diff(ad, ref))
              << var.name << " N = " << N << " case " << c;
        }
      }
    }
  }
}

// The recursive result solves the equations of motion with the assembled M (an independent check
// of the reference itself: the residual of M q̈ + bias − B u − Q).
TEST(RecursiveDynamics, SolvesTheEquationsOfMotion) {
  std::mt19937 rng(3);
  for (const Variant& var : kVariants) {
    for (const int N : {2, 7, 33}) {
      const Model m(params_of(N, var));
      Data d(m);
      const VectorXd q = random_q(m, rng), v = random_v(m, rng);
      const VectorXd u = VectorXd::Random(m.joints()), Q = VectorXd::Random(m.nq());
      VectorXd a(m.nq());
      ASSERT_TRUE(forward_dynamics(m, d, q, v, u, Q, a, ForwardSolver::kRecursive));
      compute_mass_matrix(m, d);
      compute_bias(m, d, q);
      VectorXd Bu = VectorXd::Zero(m.nq());
      Bu.segment(m.flexible() ? m.i_beta(0) : 0, m.joints()) = u;
      const VectorXd r = d.M * a + d.bias - Bu - Q;
      EXPECT_LT(r.norm(), 1e-12 * (d.M.norm() * a.norm() + Q.norm() + d.bias.norm() + u.norm()))
          << var.name << " N = " << N;
    }
  }
}

// Both solvers against the extended-precision reference: how far each is from the exact q̈ (the
// conditioning of M bounds what any double-precision solver can reach).
TEST(RecursiveDynamics, AccuracyAgainstExtendedPrecision) {
  std::mt19937 rng(9);
  for (const Variant& var : kVariants) {
    for (const int N : {2, 6, 16, 32, 64}) {
      const Model m(params_of(N, var));
      Data d(m);
      double worst_r = 0, worst_d = 0, worst_cond = 0;
      for (int trial = 0; trial < 5; ++trial) {
        const VectorXd q = random_q(m, rng), v = random_v(m, rng, 2.0);
        const VectorXd u = VectorXd::Random(m.joints()), Q = VectorXd::Random(m.nq());
        double cond = 0;
        const VectorXd ref = reference_qdd(m, q, v, u, Q, &cond);
        VectorXd ar(m.nq()), ad(m.nq());
        ASSERT_TRUE(forward_dynamics(m, d, q, v, u, Q, ar, ForwardSolver::kRecursive));
        ASSERT_TRUE(forward_dynamics(m, d, q, v, u, Q, ad, ForwardSolver::kDense));
        worst_r = std::max(worst_r, rel_diff(ar, ref));
        worst_d = std::max(worst_d, rel_diff(ad, ref));
        worst_cond = std::max(worst_cond, cond);
      }
      std::printf("%-12s N=%2d cond(M) ≤ %.2g  |rec − ref| %.2g  |dense − ref| %.2g (relative)\n",
                  var.name, N, worst_cond, worst_r, worst_d);
    }
  }
}

TEST(RecursiveDynamics, AllocatesNothing) {
  for (const Variant& var : kVariants) {
    const Model m(params_of(64, var));
    Data d(m);
    std::mt19937 rng(5);
    const VectorXd q = random_q(m, rng), v = random_v(m, rng);
    const VectorXd u = VectorXd::Random(m.joints()), Q = VectorXd::Random(m.nq());
    VectorXd a(m.nq());
    ASSERT_TRUE(forward_dynamics(m, d, q, v, u, Q, a, ForwardSolver::kRecursive));  // warm-up
    pedalwave::test::AllocationScope scope;
    for (int i = 0; i < 100; ++i)
      ASSERT_TRUE(forward_dynamics(m, d, q, v, u, Q, a, ForwardSolver::kRecursive));
    EXPECT_EQ(scope.count(), 0u) << var.name << ": recursive forward_dynamics allocated";
  }
}

// A mass matrix that is not positive definite is reported, not turned into NaN: a NaN state
// makes the recursion fail the same way the dense Cholesky does.
TEST(RecursiveDynamics, ReportsAFailureOnNaN) {
  const Model m(params_of(6, kVariants[0]));
  Data d(m);
  VectorXd q = VectorXd::Zero(m.nq()), v = VectorXd::Zero(m.nq()), a = VectorXd::Zero(m.nq());
  q(m.i_alpha(2)) = std::nan("");
  EXPECT_FALSE(forward_dynamics(m, d, q, v, VectorXd(), VectorXd(), a, ForwardSolver::kRecursive));
  EXPECT_FALSE(forward_dynamics(m, d, q, v, VectorXd(), VectorXd(), a, ForwardSolver::kDense));
}

// The plant stepped in lockstep with either solver (contacts, friction, PD motors on the shipped
// effects): the trajectories agree to rounding. (They are not bit-identical: the solvers round
// differently; the plant's default is the recursive solver.)
TEST(RecursiveDynamics, PlantTrajectoriesAgreeAcrossSolvers) {
  for (const Variant& var : {kVariants[0], kVariants[1]}) {
    Scene scene;
    scene.robot = params_of(6, var);
    scene.ground_on = true;
    scene.integrator.method = Method::kSemiImplicitEuler;
    scene.integrator.h = 2.5e-4;
    Simulation dense(scene), rec(scene);
    dense.plant().set_forward_solver(ForwardSolver::kDense);
    ASSERT_EQ(rec.plant().forward_solver(), ForwardSolver::kRecursive);
    for (Simulation* s : {&dense, &rec}) {
      auto& in = s->plant().input();
      in.kp.setConstant(30.0);
      in.kd.setConstant(15.0);
      for (int j = 0; j < s->plant().model().joints(); ++j) in.beta_ref(j) = 0.6 * std::sin(1.3 * j);
    }
    double max_dq = 0.0;
    for (int k = 1; k <= 100; ++k) {  // 0.5 s
      ASSERT_EQ(dense.advance_to(0.005 * k), StepStatus::kOk);
      ASSERT_EQ(rec.advance_to(0.005 * k), StepStatus::kOk);
      max_dq = std::max(max_dq, (dense.q() - rec.q()).cwiseAbs().maxCoeff());
    }
    EXPECT_GT((dense.q() - Simulation(scene).q()).norm(), 1e-3) << "the robot did not move";
    EXPECT_LT(max_dq, 1e-10) << var.name;
    std::printf("%s: max |q_dense − q_recursive| over 0.5 s = %.3g\n", var.name, max_dq);
  }
}
