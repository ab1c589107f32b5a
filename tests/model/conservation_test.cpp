// Invariants of the free robot (no contact, no damping): energy, momentum, free fall, and the
// K → ∞ limit. Each with a stated tolerance over a stated time.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "model_fixtures.hpp"

using namespace pedalwave::model;
using pedalwave::model::testing::FreeRobot;
using pedalwave::model::testing::random_q;
using pedalwave::model::testing::random_v;

namespace {
// Integrates (q, v) for duration T with a fixed-step method; returns the max |E(t) − E(0)|.
double energy_drift(const Model& m, Method method, double h, double T, VectorXd q, VectorXd v) {
  FreeRobot robot(m);
  Integrator integ(m.nq(), {.method = method, .h = h});
  const double E0 = robot.energy(q, v);
  double t = 0.0, worst = 0.0;
  const int steps = static_cast<int>(std::lround(T / h));
  for (int s = 0; s < steps; ++s) {
    EXPECT_EQ(integ.step(robot, t, h, q, v), StepStatus::kOk);
    t += h;
    worst = std::max(worst, std::abs(robot.energy(q, v) - E0));
  }
  return worst;
}
}  // namespace

// Energy (kinetic + gravity + spring) is conserved: RK4 at the paper's step 1e-4 s over 2 s keeps
// the drift below 1e-9 of the energy scale, and the drift falls at order 4 with the step.
TEST(Conservation, EnergyIsConservedAndDriftShrinksAtTheIntegratorsOrder) {
  const Model m(paper_params(6));
  std::mt19937 rng(21);
  const VectorXd q = random_q(m, rng, 0.1);
  const VectorXd v = random_v(m, rng, 0.5);
  FreeRobot robot(m);
  const double E0 = robot.energy(q, v);
  (void)E0;
  // Energy scale: kinetic + spring energy at the start (gravity's zero is arbitrary).
  Data& d = robot.data();
  update_kinematics(m, d, q, v);
  compute_mass_matrix(m, d);
  const double scale = kinetic_energy(d, v) + spring_energy(m, q);
  const double drift = energy_drift(m, Method::kRK4, 1e-4, 2.0, q, v);
  RecordProperty("rk4_1e-4_drift_J", std::to_string(drift));
  EXPECT_LT(drift, 1e-6 * scale) << "drift " << drift << " J, energy scale " << scale << " J";

  // Order: halve h; log2 of successive drift ratios. RK4's energy error shrinks at least at its
  // order 4; for oscillatory modes it is 5 (its amplitude error per step is O((ωh)^6)).
  // Explicit Euler: order 1.
  double prev = 0.0;
  for (double h : {8e-4, 4e-4, 2e-4}) {
    const double e = energy_drift(m, Method::kRK4, h, 0.5, q, v);
    if (prev > 0) {
      const double order = std::log2(prev / e);
      EXPECT_GT(order, 3.8) << "RK4 energy drift order at h=" << h << ": " << order;
      EXPECT_LT(order, 5.5) << "RK4 energy drift order at h=" << h << ": " << order;
    }
    prev = e;
  }
  prev = 0.0;
  for (double h : {4e-5, 2e-5, 1e-5}) {
    const double e = energy_drift(m, Method::kExplicitEuler, h, 0.05, q, v);
    if (prev > 0) {
      const double order = std::log2(prev / e);
      EXPECT_NEAR(order, 1.0, 0.25) << "explicit Euler drift order at h=" << h;
    }
    prev = e;
  }
}

TEST(Conservation, AdaptiveDormandPrinceMeetsItsTolerance) {
  const Model m(paper_params(6));
  std::mt19937 rng(22);
  VectorXd q = random_q(m, rng, 0.1), v = random_v(m, rng, 0.5);
  FreeRobot robot(m);
  const double E0 = robot.energy(q, v);
  Integrator integ(m.nq(), {.method = Method::kDormandPrince45, .h = 1e-4, .rtol = 1e-10, .atol = 1e-12});
  double t = 0.0;
  ASSERT_EQ(integ.advance(robot, t, 2.0, q, v), StepStatus::kOk);
  EXPECT_NEAR(robot.energy(q, v), E0, 1e-8);
  EXPECT_GT(integ.stats().steps, 10u);
}

// With no gravity and no input the total linear momentum is constant.
TEST(Conservation, LinearMomentumWithoutGravity) {
  Params p = paper_params(6);
  p.g = 0.0;
  const Model m(p);
  std::mt19937 rng(23);
  VectorXd q = random_q(m, rng), v = random_v(m, rng, 2.0);
  FreeRobot robot(m);
  Data& d = robot.data();
  update_kinematics(m, d, q, v);
  const Vec2 P0 = linear_momentum(m, d, v);
  ASSERT_GT(P0.norm(), 1e-3);
  Integrator integ(m.nq(), {.method = Method::kRK4, .h = 1e-4});
  double t = 0.0;
  ASSERT_EQ(integ.advance(robot, t, 1.0, q, v), StepStatus::kOk);
  update_kinematics(m, d, q, v);
  EXPECT_LT((linear_momentum(m, d, v) - P0).norm(), 1e-10 * (1 + P0.norm()));
}

// Under gravity with no contact the centre of mass falls at exactly g, whatever the body does.
TEST(Conservation, CenterOfMassFallsAtG) {
  for (JointModel jm : {JointModel::kFlexible, JointModel::kRigid}) {
    Params p = paper_params(6);
    p.joints = jm;
    const Model m(p);
    std::mt19937 rng(24);
    VectorXd q = random_q(m, rng), v = random_v(m, rng, 2.0);
    FreeRobot robot(m);
    robot.u() = VectorXd::Constant(m.joints(), 0.05);  // internal torques do not move the COM
    Data& d = robot.data();
    update_kinematics(m, d, q, v);
    const Vec2 c0 = center_of_mass(m, d, q);
    const Vec2 v0 = linear_momentum(m, d, v) / m.total_mass();
    Integrator integ(m.nq(), {.method = Method::kRK4, .h = 1e-4});
    double t = 0.0;
    const double T = 0.5;
    ASSERT_EQ(integ.advance(robot, t, T, q, v), StepStatus::kOk);
    update_kinematics(m, d, q, v);
    const Vec2 expect = c0 + v0 * T + Vec2(0, -0.5 * p.g * T * T);
    EXPECT_LT((center_of_mass(m, d, q) - expect).norm(), 1e-9);
  }
}

// The flexible model converges to the rigid model (the exact K → ∞ limit) as K grows: same start,
// same torques; the max over 0.2 s (sampled every 1 ms) of the body-coordinate difference falls
// ∝ 1/K. (The difference at one instant is not monotone: it oscillates through zero.)
TEST(Conservation, FlexibleConvergesToRigidAsStiffnessGrows) {
  Params pr = paper_params(6);
  pr.joints = JointModel::kRigid;
  const Model rigid(pr);
  std::mt19937 rng(25);
  const VectorXd q1 = random_q(rigid, rng), v1 = random_v(rigid, rng, 0.5);
  const VectorXd u = VectorXd::Constant(5, 0.02);
  const double T = 0.2, dt = 1e-3;

  // Rigid reference, sampled every dt.
  std::vector<VectorXd> ref;
  {
    VectorXd q = q1, v = v1;
    FreeRobot robot(rigid);
    robot.u() = u;
    Integrator integ(rigid.nq(), {.method = Method::kRK4, .h = 1e-5});
    double t = 0.0;
    for (int k = 1; k * dt <= T + 1e-12; ++k) {
      ASSERT_EQ(integ.advance(robot, t, k * dt, q, v), StepStatus::kOk);
      ref.push_back(q);
    }
  }
  std::vector<double> errors;
  for (double K : {30.0, 300.0, 3000.0, 30000.0}) {
    Params pf = paper_params(6);
    pf.K_all = K;
    const Model flex(pf);
    VectorXd q(flex.nq()), v(flex.nq());
    q << q1, q1.head(5);  // β = α: springs relaxed
    v << v1, v1.head(5);
    FreeRobot robot(flex);
    robot.u() = u;
    // Fast mode ~ sqrt(K / link inertia): keep RK4 well inside its stability region.
    const double h = std::min(1e-5, 0.3 / std::sqrt(K / 1e-4));
    Integrator integ(flex.nq(), {.method = Method::kRK4, .h = h});
    double t = 0.0, err = 0.0;
    for (size_t k = 0; k < ref.size(); ++k) {
      ASSERT_EQ(integ.advance(robot, t, (k + 1) * dt, q, v), StepStatus::kOk) << "K = " << K;
      err = std::max(err, (q.head(rigid.nq()) - ref[k]).cwiseAbs().maxCoeff());
    }
    errors.push_back(err);
    RecordProperty("max_err_K_" + std::to_string(static_cast<int>(K)), std::to_string(err));
  }
  for (size_t i = 1; i < errors.size(); ++i)
    EXPECT_LT(errors[i], errors[i - 1] / 4.0) << "max error must fall ~10x per 10x K: "
                                              << errors[i - 1] << " -> " << errors[i];
  EXPECT_LT(errors.back(), 1e-4);
}
