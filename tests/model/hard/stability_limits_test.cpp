// Stability limits predicted by model/stability.hpp, confirmed by simulation: for each explicit
// scheme on a scene where one effect dominates, the plant is settled, nudged by a small velocity
// perturbation and stepped at 0.8× and 1.25× the predicted limit. The passive energy (kinetic,
// gravity, springs, PD springs, contact; hard_support.hpp) relative to the rest state may only
// decay in the exact dynamics. Stable: no NaN and the perturbation energy stays below 3× its start
// (semi-implicit Euler conserves a shadow energy that differs from the true one by up to
// 1/(1 − (hω/2)²) ≈ 2.8× at hω = 1.6). Unstable: NaN, or the perturbation energy grows ≥ 10×.
// (Measured margins are far wider: stable at 0.95× and blown up at 1.05× in every case below.)
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>

#include "hard_support.hpp"
#include "pedalwave/model/stability.hpp"

using namespace pedalwave::model;

namespace {

Scene flat_ground() {
  Scene s;
  s.name = "stab-flat";
  s.initial.pose = InitialPose::kFlat;
  return s;
}
Scene air() {
  Scene s = flat_ground();
  s.name = "stab-air";
  s.ground_on = false;
  s.robot.g = 0.0;  // no fall: the rest state is an equilibrium
  return s;
}

struct Outcome {
  bool non_finite = false;
  double max_ratio = 0.0;  // max over the run of (E − E_rest) / (E(0) − E_rest)
};

// Settle (implicit, 1.5 s on the ground), perturb all velocities by ±eps, step with `method`.
Outcome run(const Scene& s, const ControlGains& g, Method method, double h, double T, double eps) {
  Plant p(s);
  VectorXd q, v;
  p.initial_state(q, v);
  const Model& m = p.model();
  p.input().torque_off = g.K_p == 0 && g.K_D == 0;
  hard::hold_pd(p, q, g.K_p, g.K_D);
  double t = 0.0;
  if (s.ground_on) {
    Integrator settle(m.nq(), {.method = Method::kImplicitVelocity, .h = 1e-4});
    EXPECT_EQ(settle.advance(p, t, 1.5, q, v), StepStatus::kOk);
    v.setZero();
  }
  const double E_rest = hard::passive_energy(p, q, v);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int i = 0; i < m.nq(); ++i) v(i) += eps * u(rng);
  const double dE0 = hard::passive_energy(p, q, v) - E_rest;
  EXPECT_GT(dE0, 0.0);
  Integrator it(m.nq(), {.method = method, .h = h});
  Outcome o;
  const int n = static_cast<int>(std::ceil(T / h));
  for (int i = 0; i < n; ++i) {
    if (it.step(p, t, h, q, v) != StepStatus::kOk) return {true, o.max_ratio};
    t += h;
    p.after_step(q, v);
    const double r = (hard::passive_energy(p, q, v) - E_rest) / dE0;
    if (!std::isfinite(r)) return {true, o.max_ratio};
    o.max_ratio = std::max(o.max_ratio, r);
    if (r > 1e4) break;  // clearly unstable; no need to wait for the overflow
  }
  return o;
}

struct Case {
  const char* name;
  Scene scene;
  ControlGains gains;
  Method method;
  Effect dominant;  // what the prediction must name
  double T;         // simulated time [s]
  double eps;       // velocity perturbation [SI], small enough for the linear regime
};

Scene with(Scene s, auto f) {
  f(s);
  return s;
}

std::vector<Case> cases() {
  const ControlGains paper{30.0, 15.0}, off{0.0, 0.0};
  // Regularized friction (μ f_N / v_s ≈ 8e3 1/s on the lightest points) is the stiffest effect of
  // the shipped ground scenes; eps = 1e-5 keeps tangential speeds far below v_s = 1e-3 m/s so the
  // instability has room to grow before the friction saturates.
  return {
      {"EulerFriction", flat_ground(), paper, Method::kExplicitEuler, Effect::kFriction, 0.2, 1e-5},
      {"EulerMotorDamping", flat_ground(), {30.0, 150.0}, Method::kExplicitEuler, Effect::kMotorPd,
       0.1, 1e-4},
      {"SemiImplicitSpringAir", air(), off, Method::kSemiImplicitEuler, Effect::kSpring, 0.3, 1e-2},
      {"SemiImplicitStiffSpring", with(flat_ground(), [](Scene& s) { s.robot.K_all = 1e4; }), paper,
       Method::kSemiImplicitEuler, Effect::kSpring, 0.1, 1e-4},
      {"SemiImplicitMotorDamping", air(), paper, Method::kSemiImplicitEuler, Effect::kMotorPd, 0.3,
       1e-2},
      {"RK4MotorDamping", air(), paper, Method::kRK4, Effect::kMotorPd, 0.3, 1e-2},
      {"RK4ContactStiffness", with(flat_ground(), [](Scene& s) { s.ground.k = 1e5, s.ground.mu = 0; }),
       off, Method::kRK4, Effect::kContactStiffness, 0.2, 1e-5},
      {"RK4Friction", flat_ground(), paper, Method::kRK4, Effect::kFriction, 0.2, 1e-6},
  };
}

class StabilityLimit : public ::testing::TestWithParam<Case> {};

TEST_P(StabilityLimit, PredictionConfirmedBySimulation) {
  const Case& c = GetParam();
  const StabilityReport r = predict_stability(c.scene, c.gains);
  const MethodLimit lim = r.limit(c.method);
  ASSERT_TRUE(std::isfinite(lim.h_max) && lim.h_max > 0) << c.name;
  EXPECT_EQ(lim.dominant, c.dominant) << "predicted dominant effect " << to_string(lim.dominant);
  const Outcome below = run(c.scene, c.gains, c.method, 0.8 * lim.h_max, c.T, c.eps);
  EXPECT_FALSE(below.non_finite) << "0.8 × limit " << 0.8 * lim.h_max << " s went non-finite";
  EXPECT_LT(below.max_ratio, 3.0) << "0.8 × limit " << 0.8 * lim.h_max << " s: energy grew";
  const Outcome above = run(c.scene, c.gains, c.method, 1.25 * lim.h_max, c.T, c.eps);
  EXPECT_TRUE(above.non_finite || above.max_ratio >= 10.0)
      << "1.25 × limit " << 1.25 * lim.h_max << " s stayed stable: energy ratio " << above.max_ratio;
}

INSTANTIATE_TEST_SUITE_P(Hard, StabilityLimit, ::testing::ValuesIn(cases()),
                         [](const ::testing::TestParamInfo<Case>& p) { return std::string(p.param.name); });

// The closed forms of model-spec.md §10 come out of the general machinery: an overdamped motor
// mode λ ≈ −K_D/(n² I_r) gives h = 2 n² I_r / K_D (Euler, semi-implicit) and 2.785 n² I_r / K_D
// (RK4's real-axis limit); an undamped mode gives ωh = 2 (semi-implicit) and 2√2 (RK4).
TEST(StabilityPrediction, ClosedFormsOfTheTimeScales) {
  const Scene s = air();
  const StabilityReport r = predict_stability(s, {30.0, 15.0});
  const double J = s.robot.n * s.robot.n * s.robot.I_r;
  // The exact root of J s² + K_D s + (K_p + K) = 0 differs from K_D / J by (K_p+K)/K_D / (K_D/J).
  EXPECT_NEAR(r.semi_implicit.h_max, 2 * J / 15.0, 0.01 * 2 * J / 15.0);
  EXPECT_NEAR(r.rk4.h_max, 2.785 * J / 15.0, 0.01 * 2.785 * J / 15.0);
  EXPECT_NEAR(r.motor_time_scale, J / 15.0, 1e-12);
  EXPECT_EQ(r.semi_implicit.dominant, Effect::kMotorPd);

  const StabilityReport u = predict_stability(s, {0.0, 0.0});
  ASSERT_GT(u.omega_max, 0.0);
  EXPECT_NEAR(u.semi_implicit.h_max * u.omega_max, 2.0, 2e-3);
  EXPECT_NEAR(u.rk4.h_max * u.omega_max, 2.0 * std::sqrt(2.0), 3e-3);
  EXPECT_EQ(u.euler.h_max, 0.0) << "explicit Euler grows an undamped mode at every step";
  EXPECT_NEAR(u.euler_undamped_omega, u.omega_max, 1e-6 * u.omega_max);
  EXPECT_EQ(u.rk4.dominant, Effect::kSpring);
  // The spring mode's frequency: between √(K / I_link) of a free link and its coupled value; a
  // stiffer spring scales it by √(K'/K).
  Scene stiff = s;
  stiff.robot.K_all = 300.0;
  const StabilityReport u2 = predict_stability(stiff, {0.0, 0.0});
  EXPECT_NEAR(u2.effects[static_cast<int>(Effect::kSpring)].omega_max,
              10.0 * u.effects[static_cast<int>(Effect::kSpring)].omega_max,
              0.05 * 10.0 * u.effects[static_cast<int>(Effect::kSpring)].omega_max);
}

// The message names the effect and the fix; check() refuses what would blow up.
TEST(StabilityPrediction, MessageNamesTheEffectAndTheFix) {
  Scene s = flat_ground();
  s.ground.law = FrictionLaw::kCoulomb;  // no friction slope: the motor damping sets the limit
  s.duration = 10.0;
  const StabilityReport r = predict_stability(s, {30.0, 15.0});
  EXPECT_EQ(r.euler.dominant, Effect::kMotorPd);
  EXPECT_NE(r.notes.find("Coulomb"), std::string::npos) << r.notes;
  const std::string msg = stability_message(r, Method::kExplicitEuler, 2e-3);
  EXPECT_NE(msg.find("h = 2e-3 s is above explicit Euler's stability limit 4.33e-4 s"),
            std::string::npos) << msg;
  EXPECT_NE(msg.find("motor damping K_D / (n² I_r)"), std::string::npos) << msg;
  EXPECT_NE(msg.find("use h ≤ 4e-4 s, or implicit_velocity"), std::string::npos) << msg;

  const StabilityCheck bad = check(s, {30.0, 15.0}, {.method = Method::kExplicitEuler, .h = 2e-3}, 10.0);
  EXPECT_EQ(bad.level, CheckLevel::kError) << bad.message;
  EXPECT_GE(bad.growth, 10.0);
  const StabilityCheck ok = check(s, {30.0, 15.0}, {.method = Method::kExplicitEuler, .h = 1e-4}, 10.0);
  EXPECT_EQ(ok.level, CheckLevel::kOk) << ok.message;
  const StabilityCheck close = check(s, {30.0, 15.0}, {.method = Method::kExplicitEuler, .h = 4e-4}, 10.0);
  EXPECT_EQ(close.level, CheckLevel::kWarning) << close.message;
  const StabilityCheck imp =
      check(s, {30.0, 15.0}, {.method = Method::kImplicitVelocity, .h = 2e-3}, 10.0);
  EXPECT_EQ(imp.level, CheckLevel::kOk) << imp.message;
}

// Friction's slope sets the shipped ground scenes' limits, but only inside the stick band: above
// it a run chatters with bounded amplitude (the work-precision study runs RK4 at 5e-4 s > 3.46e-4 s
// for 10 s in closed loop with 1.3 mm error); it blows up above the limit without friction, the
// motor damping's. check() warns in between and refuses above.
TEST(StabilityPrediction, FrictionLimitIsSoft) {
  Scene s = flat_ground();
  const StabilityReport r = predict_stability(s, {30.0, 15.0});
  EXPECT_EQ(r.rk4.dominant, Effect::kFriction);
  EXPECT_EQ(r.rk4.blowup_dominant, Effect::kMotorPd);
  const double J = s.robot.n * s.robot.n * s.robot.I_r;
  EXPECT_NEAR(r.rk4.h_blowup, 2.785 * J / 15.0, 0.01 * 2.785 * J / 15.0);
  EXPECT_LT(r.rk4.h_max, r.rk4.h_blowup);
  const StabilityCheck soft = check(s, {30.0, 15.0}, {.method = Method::kRK4, .h = 5e-4}, 10.0);
  EXPECT_EQ(soft.level, CheckLevel::kWarning) << soft.message;
  EXPECT_NE(soft.message.find("chatters"), std::string::npos) << soft.message;
  const StabilityCheck hard = check(s, {30.0, 15.0}, {.method = Method::kRK4, .h = 7e-4}, 10.0);
  EXPECT_EQ(hard.level, CheckLevel::kError) << hard.message;
  // Blow-up confirmed on both sides of h_blowup (perturbation far above v_s: sliding contacts).
  EXPECT_LT(run(s, {30.0, 15.0}, Method::kRK4, 0.8 * r.rk4.h_blowup, 0.2, 1e-5).max_ratio, 1e4);
  const Outcome above = run(s, {30.0, 15.0}, Method::kRK4, 1.25 * r.rk4.h_blowup, 0.2, 1e-5);
  EXPECT_TRUE(above.non_finite || above.max_ratio >= 1e4) << above.max_ratio;
}

// Open loop in the air (the free-fall scene without PD): every SEA mode is undamped, so explicit
// Euler's amplitude grows by √(1 + h²ω²) per step — ×e^{½ h ω² t}: ~4000× in 1 s at h = 1e-4.
TEST(StabilityPrediction, ExplicitEulerOnUndampedModesIsRefused) {
  Scene s = air();
  s.duration = 1.0;
  const StabilityCheck c = check(s, {0.0, 0.0}, {.method = Method::kExplicitEuler, .h = 1e-4}, 1.0);
  EXPECT_EQ(c.level, CheckLevel::kError) << c.message;
  EXPECT_NE(c.message.find("unstable at every step"), std::string::npos) << c.message;
  const double w = c.report.euler_undamped_omega;
  EXPECT_NEAR(std::log(c.growth), 0.5 * 1e4 * std::log1p(1e-8 * w * w), 1e-6 * std::log(c.growth));
}
}  // namespace
