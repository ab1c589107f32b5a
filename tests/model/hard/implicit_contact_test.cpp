// implicit_contact (integrators.hpp): the θ-trapezoid whose implicit stage is solved by Newton
// corrections with the plant's contact/friction Jacobians. Its order on a smooth case, its
// energy behaviour, its agreement with a tight reference at a small step, its stability on the
// hard cases at the 1 and 2 ms steps, and no allocation in a step.
#include <gtest/gtest.h>

#include <cmath>

#include "alloc_counter.hpp"
#include "hard_support.hpp"

using namespace pedalwave::model;

namespace {

Scene base_scene(InitialPose pose) {
  Scene s;
  s.name = "implicit_contact";
  s.initial.pose = pose;
  s.initial.theta = 0;
  return s;
}

// Free flight (no ground) from the gait's start shape with the joints bent and moving: smooth,
// undamped (no PD: zero inputs), the SEA modes ringing at ω ≈ 400 rad/s.
Scene smooth_scene() {
  Scene s = base_scene(InitialPose::kExplicit);
  s.ground_on = false;
  const Model m(s.robot);
  std::vector<double> q(static_cast<size_t>(m.nq()), 0.0), v(q.size(), 0.0);
  for (int j = 0; j < m.joints(); ++j) {
    q[static_cast<size_t>(m.i_alpha(j))] = 0.3 * std::sin(0.7 * j);
    q[static_cast<size_t>(m.i_beta(j))] = 0.3 * std::sin(0.7 * j) + 0.02;
    v[static_cast<size_t>(m.i_alpha(j))] = 0.5 * std::cos(0.9 * j);
  }
  v[static_cast<size_t>(m.i_px())] = 0.1;
  s.initial.q = q;
  s.initial.v = v;
  return s;
}

VectorXd run_to(const Scene& s, const IntegratorOptions& o, double T) {
  Simulation sim(s, o);
  EXPECT_EQ(sim.advance_to(T), StepStatus::kOk);
  VectorXd y(2 * sim.q().size());
  y << sim.q(), sim.v();
  return y;
}

IntegratorOptions ic(double h, double theta = 0.55) {
  IntegratorOptions o{.method = Method::kImplicitContact, .h = h};
  o.theta = theta;
  return o;
}

}  // namespace

// θ = ½ is the trapezoidal rule: second order on a smooth problem (the state error against RK4 at
// 1e-6 s falls 4× per halving of h); θ = 0.55 is first order, its error far below implicit_velocity's
// (backward Euler) at the same step.
TEST(ImplicitContact, ConvergenceOrderOnASmoothCase) {
  const Scene s = smooth_scene();
  const double T = 0.1;
  const VectorXd ref = run_to(s, {.method = Method::kRK4, .h = 1e-6}, T);
  double e_prev = 0.0;
  for (double h : {2e-4, 1e-4, 5e-5}) {
    const double e = (run_to(s, ic(h, 0.5), T) - ref).norm();
    if (e_prev > 0) {
      const double order = std::log2(e_prev / e);
      EXPECT_GT(order, 1.8) << "h = " << h;
      EXPECT_LT(order, 2.3) << "h = " << h;
    }
    e_prev = e;
  }
  for (double h : {2e-4, 1e-4}) {
    const double e_ic = (run_to(s, ic(h), T) - ref).norm();
    const double e_iv = (run_to(s, {.method = Method::kImplicitVelocity, .h = h}, T) - ref).norm();
    EXPECT_LT(e_ic, 0.2 * e_iv) << "h = " << h;
  }
}

// Undamped free flight: the energy (kinetic + gravity + springs) has nowhere to go. Measured on the
// scale of the motion's energy at the start (kinetic + springs, 8.9e-3 J), over 1 s at h = 1e-3 s:
// the trapezoid (θ = ½, M frozen at the step's start, two Newton corrections) gains less than
// 5e-4 of it and loses less than 1 %; θ = 0.55 never gains more than 1e-4 of it and damps the SEA
// ringing (ωh ≈ 0.4) far less than implicit_velocity does: after 0.1 s it has lost under a third of
// backward Euler's loss.
TEST(ImplicitContact, EnergyInFreeFlight) {
  const Scene s = smooth_scene();
  auto run = [&](const IntegratorOptions& o, double T, double& E0, double& E_min, double& E_max,
                 double& motion) {
    Simulation sim(s, o);
    Plant& p = sim.plant();
    E0 = E_min = E_max = p.energy(sim.q(), sim.v());
    motion = E0 - gravity_energy(p.model(), p.data(), sim.q());
    double E = E0;
    for (int k = 1; k <= static_cast<int>(std::lround(T / 1e-3)); ++k) {
      EXPECT_EQ(sim.advance_to(1e-3 * k), StepStatus::kOk);
      E = p.energy(sim.q(), sim.v());
      E_max = std::max(E_max, E);
      E_min = std::min(E_min, E);
    }
    return E;
  };
  double E0, E_min, E_max, motion;
  run(ic(1e-3, 0.5), 1.0, E0, E_min, E_max, motion);
  ASSERT_GT(motion, 1e-3);
  EXPECT_LT(E_max - E0, 5e-4 * motion) << "trapezoid: energy grew";
  EXPECT_LT(E0 - E_min, 0.01 * motion) << "trapezoid: energy lost";
  run(ic(1e-3), 1.0, E0, E_min, E_max, motion);
  EXPECT_LT(E_max - E0, 1e-4 * motion) << "theta 0.55: energy grew";
  const double loss_ic = E0 - run(ic(1e-3), 0.1, E0, E_min, E_max, motion);
  const double loss_iv =
      E0 - run({.method = Method::kImplicitVelocity, .h = 1e-3}, 0.1, E0, E_min, E_max, motion);
  EXPECT_GT(loss_iv, 0.0);
  EXPECT_LT(loss_ic, loss_iv / 3) << "implicit_contact loses " << loss_ic << " J, implicit_velocity "
                                  << loss_iv << " J";
}

// Closed-loop gait on flat ground for 2 s: at h = 1e-4 s the COM follows dopri45 at rtol 1e-8
// within 50 µm, and at the 1 ms step within 1 mm.
TEST(ImplicitContact, AgreesWithTheReferenceClosedLoop) {
  const Scene s = base_scene(InitialPose::kGaitStart);
  hard::GaitLoop ref(s, {.method = Method::kDormandPrince45, .h = 1e-4, .rtol = 1e-8, .atol = 1e-10});
  hard::GaitLoop fine(s, ic(1e-4));
  hard::GaitLoop coarse(s, ic(1e-3));
  double e_fine = 0.0, e_coarse = 0.0;
  for (int k = 0; k < 2000; ++k) {
    ASSERT_EQ(ref.step(), StepStatus::kOk);
    ASSERT_EQ(fine.step(), StepStatus::kOk);
    ASSERT_EQ(coarse.step(), StepStatus::kOk);
    const Vec2 c = hard::com(ref.sim());
    e_fine = std::max(e_fine, (hard::com(fine.sim()) - c).norm());
    e_coarse = std::max(e_coarse, (hard::com(coarse.sim()) - c).norm());
  }
  EXPECT_LT(e_fine, 5e-5);
  EXPECT_LT(e_coarse, 1e-3);
  EXPECT_GT(hard::com(ref.sim()).x() - 0.0, -1.0);  // it ran
}

// The hard cases at the 1 and 2 ms steps: stiff ground (k = 1e5 N/m) dropped from 2 cm, near-rigid
// SEA springs (K = 1e4 N·m/rad), and a link draped over the stair's corner (k = 5000 N/m). With the
// motors held by the PD nothing puts energy in: every run stays finite, its passive energy never
// exceeds the start's by more than 1 % of the drop energy, penetrations stay within the impact
// bound; on the flat ground the robot comes to rest, over the corner (it keeps rocking on the edge
// under the PD: RK4 at 2e-5 s shows the same) its COM after 2 s is within 1.5 mm per ms of step
// of implicit_velocity at 1e-4 s.
TEST(ImplicitContact, StableOnTheHardCasesAt1And2ms) {
  for (double h : {1e-3, 2e-3}) {
    for (int c = 0; c < 3; ++c) {
      Scene s = base_scene(InitialPose::kAir);
      s.initial.height = 0.02;
      const char* name = "stiff ground";
      if (c == 0) {
        s.ground.k = 1e5;
      } else if (c == 1) {
        name = "near-rigid springs";
        s.robot.K_all = 1e4;
      } else {
        name = "stair corner";
        s.ground.k = 5000;
        s.initial.pose = InitialPose::kFlat;
        s.initial.height = 0.08;
        s.initial.x = 0.05;
        s.boxes.push_back(Box{.x_near = 0.0, .width = 0.11, .height = 0.06});
      }
      SCOPED_TRACE(std::string(name) + ", h = " + std::to_string(h));
      Simulation sim(s, ic(h));
      Plant& p = sim.plant();
      hard::hold_pd(p, sim.q(), 30.0, 15.0);
      const double E0 = hard::passive_energy(p, sim.q(), sim.v());
      const double drop = sim.plant().model().total_mass() * 9.81 * s.initial.height;
      double E_max = E0, pen = 0.0;
      for (int k = 1; k <= static_cast<int>(std::lround(2.0 / h)); ++k) {
        ASSERT_EQ(sim.advance_to(h * k), StepStatus::kOk) << "t = " << h * k;
        ASSERT_TRUE(sim.q().allFinite() && sim.v().allFinite());
        E_max = std::max(E_max, hard::passive_energy(p, sim.q(), sim.v()));
        pen = std::max(pen, hard::ground_penetration(p, sim.q()));
      }
      EXPECT_LT(E_max, E0 + 0.01 * drop) << "energy grew";
      EXPECT_LT(pen, std::sqrt(2 * drop / s.ground.k)) << "deeper than the impact bound";
      if (c < 2) {
        EXPECT_LT(sim.v().norm(), 0.05) << "comes to rest";
      } else {
        Simulation ref(s, {.method = Method::kImplicitVelocity, .h = 1e-4});
        hard::hold_pd(ref.plant(), ref.q(), 30.0, 15.0);
        ASSERT_EQ(ref.advance_to(2.0), StepStatus::kOk);
        EXPECT_LT((hard::com(sim) - hard::com(ref)).norm(), 1.5 * h);
      }
    }
  }
}

// One step allocates nothing (the Newton corrections included), in contact on a box scene.
TEST(ImplicitContact, StepAllocatesNothing) {
  Scene s = base_scene(InitialPose::kGaitStart);
  s.boxes = {Box{.x_near = 0.1}};
  Simulation sim(s, ic(1e-3));
  ASSERT_EQ(sim.advance_to(0.05), StepStatus::kOk);
  pedalwave::test::AllocationScope scope;
  for (int i = 0; i < 50; ++i) ASSERT_EQ(sim.integrator().step(sim.plant(), 0, 1e-3, sim.q(), sim.v()), StepStatus::kOk);
  EXPECT_EQ(scope.count(), 0u);
}

TEST(ImplicitContact, BadOptionsAreRefused) {
  IntegratorOptions o = ic(1e-3, 0.4);
  EXPECT_THROW(validate(o), std::invalid_argument);
  o.theta = 0.55;
  o.newton_iterations = -1;
  EXPECT_THROW(validate(o), std::invalid_argument);
  EXPECT_EQ(parse_method("implicit_contact"), Method::kImplicitContact);
}

// A straight robot resting on the ground, launched along X at 0.2 m/s (regularized friction,
// v_s = 1 mm/s): it must stop and then stick. At h = 1e-3 s the stick band's slope μ f_N / v_s
// against the tips' small mass is a rate of ~1e5 1/s: a Newton correction from a sliding iterate
// sees no slope and lands in the other slip direction. With the stick slope for contacts that
// crossed the band (ImplicitTerms::v_start) every point ends every step of the last 0.3 s inside
// the band |v_t| < v_s, the friction never at ±μ f_N.
TEST(ImplicitContact, StopsAndSticksAt1ms) {
  Scene s = base_scene(InitialPose::kFlat);
  Simulation sim(s, ic(1e-3));
  Plant& p = sim.plant();
  const Model& m = p.model();
  hard::hold_pd(p, sim.q(), 30.0, 15.0);
  ASSERT_EQ(sim.advance_to(0.5), StepStatus::kOk);  // settle onto the ground
  sim.v()(m.i_px()) += 0.2;
  ASSERT_EQ(sim.advance_to(1.0), StepStatus::kOk);  // slides v²/(2 μ g) ≈ 2.5 mm, then stops
  double vt_max = 0.0;
  for (int k = 1; k <= 300; ++k) {
    ASSERT_EQ(sim.advance_to(1.0 + 1e-3 * k), StepStatus::kOk);
    update_kinematics(m, p.data(), sim.q(), sim.v());
    for (int i = 0; i < m.points(); ++i)
      vt_max = std::max(vt_max, std::abs(point_velocity(m, p.data(), sim.v(), i).x()));
  }
  EXPECT_LT(vt_max, s.ground.v_s) << "a point slides at the end of a step after the robot stopped";
}

// The corrections stop once one moves v₁ by ≤ newton_tol (1 + |v₁|∞): on the closed-loop gait at
// 1 ms the default (1e-2, at most 3 corrections) takes one correction in nearly every step
// (between 2 and 2.3 evaluations per step), where newton_tol = 0 with 2 corrections is always 3;
// the two follow each other within 1 mm over 2 s. A negative or NaN tolerance is refused.
TEST(ImplicitContact, NewtonToleranceStopsTheCorrections) {
  const Scene s = base_scene(InitialPose::kGaitStart);
  IntegratorOptions full = ic(1e-3);
  full.newton_iterations = 2;
  full.newton_tol = 0.0;
  // Both with a fresh Jacobian at every evaluation (jacobian_age 0), so that every evaluation is
  // a correction's: the kept Jacobian (the default) repeats an evaluation where the contact
  // branches change (ImplicitContact.KeptJacobian*).
  full.jacobian_age = 0;
  IntegratorOptions tol = ic(1e-3);
  tol.jacobian_age = 0;
  hard::GaitLoop adaptive(s, tol);
  hard::GaitLoop always(s, full);
  double diff = 0.0;
  for (int k = 0; k < 2000; ++k) {
    ASSERT_EQ(adaptive.step(), StepStatus::kOk);
    ASSERT_EQ(always.step(), StepStatus::kOk);
    diff = std::max(diff, (hard::com(adaptive.sim()) - hard::com(always.sim())).norm());
  }
  const auto per_step = [](hard::GaitLoop& g) {
    const IntegratorStats& st = g.sim().integrator().stats();
    return static_cast<double>(st.evaluations) / static_cast<double>(st.steps);
  };
  EXPECT_GE(per_step(adaptive), 2.0);
  EXPECT_LT(per_step(adaptive), 2.3);
  EXPECT_DOUBLE_EQ(per_step(always), 3.0);
  EXPECT_LT(diff, 1e-3);
  IntegratorOptions o = ic(1e-3);
  o.newton_tol = -1e-3;
  EXPECT_THROW(validate(o), std::invalid_argument);
  o.newton_tol = std::nan("");
  EXPECT_THROW(validate(o), std::invalid_argument);
}

// The kept Jacobian (jacobian_age, default 5): a factored Jacobian serves the later steps'
// predictors and corrections while the contacts' branches stay and for at most 5 steps. On the
// closed-loop gait at 1 ms over its first 2 s, on the flat and against a box: at most one Jacobian
// per step (0.81–0.83 measured; a fresh one at every evaluation: ≥ 2), under 2.5 evaluations per step (the repeated evaluations
// where the branches change included), and the COM within 1 mm of dopri45 (rtol 1e-8), as with
// fresh Jacobians. A change of h, and the age, expire it; a negative or too large age is refused.
TEST(ImplicitContact, KeptJacobianFollowsTheReference) {
  for (bool box : {false, true}) {
    SCOPED_TRACE(box ? "box" : "flat");
    Scene s = base_scene(InitialPose::kGaitStart);
    if (box) s.boxes = {Box{.ahead_of_head = -0.1, .width = 0.11, .height = 0.01}};
    IntegratorOptions fresh = ic(1e-3);
    fresh.jacobian_age = 0;
    hard::GaitLoop ref(s, {.method = Method::kDormandPrince45, .h = 1e-4, .rtol = 1e-8, .atol = 1e-10});
    hard::GaitLoop kept(s, ic(1e-3));
    hard::GaitLoop always(s, fresh);
    double e_kept = 0.0, e_always = 0.0;
    for (int k = 0; k < 2000; ++k) {
      ASSERT_EQ(ref.step(), StepStatus::kOk);
      ASSERT_EQ(kept.step(), StepStatus::kOk);
      ASSERT_EQ(always.step(), StepStatus::kOk);
      const Vec2 c = hard::com(ref.sim());
      e_kept = std::max(e_kept, (hard::com(kept.sim()) - c).norm());
      e_always = std::max(e_always, (hard::com(always.sim()) - c).norm());
    }
    const auto per_step = [](hard::GaitLoop& g, bool jacobians) {
      const IntegratorStats& st = g.sim().integrator().stats();
      return static_cast<double>(jacobians ? st.jacobians : st.evaluations) / static_cast<double>(st.steps);
    };
    EXPECT_LE(per_step(kept, true), 1.0);
    EXPECT_GE(per_step(always, true), 2.0);
    EXPECT_LT(per_step(kept, false), 2.5);
    EXPECT_LT(e_kept, 1e-3);
    EXPECT_LT(e_always, 1e-3);
  }
  // Expiry: at rest on the ground (the branches stay), a Jacobian every 6th step; one more when h
  // changes.
  Scene s = base_scene(InitialPose::kFlat);
  Simulation sim(s, ic(1e-3));
  hard::hold_pd(sim.plant(), sim.q(), 30.0, 15.0);
  ASSERT_EQ(sim.advance_to(0.5), StepStatus::kOk);
  Integrator& in = sim.integrator();
  in.reset_stats();
  for (int i = 0; i < 60; ++i) ASSERT_EQ(in.step(sim.plant(), 0.5, 1e-3, sim.q(), sim.v()), StepStatus::kOk);
  EXPECT_EQ(in.stats().jacobians, 10u);
  ASSERT_EQ(in.step(sim.plant(), 0.56, 5e-4, sim.q(), sim.v()), StepStatus::kOk);
  EXPECT_EQ(in.stats().jacobians, 11u);
  IntegratorOptions o = ic(1e-3);
  o.jacobian_age = -1;
  EXPECT_THROW(validate(o), std::invalid_argument);
  o.jacobian_age = 1001;
  EXPECT_THROW(validate(o), std::invalid_argument);
}
