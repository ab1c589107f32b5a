// LanePlant (lanes.hpp): several members evaluated at once, one SIMD lane each, give each member
// what Plant::implicit_terms gives it alone — F, M, D_q v, the Jacobian ∂F/∂v + a ∂F/∂q (also for a
// Newton iterate, with its step's start) to 1e-12 relative and the same contact signature — over random states in contact with the ground (two friction patches) and a box (its
// faces and its top corners against the links), with different commands per member, N = 3 and 6,
// at every lane width this machine runs. The scenes it cannot run are named, not run.
#include <gtest/gtest.h>

#include <cstdio>
#include <limits>
#include <random>

#include "model_fixtures.hpp"
#include "pedalwave/model/lanes.hpp"

using namespace pedalwave::model;

namespace {

Scene stair_like(int N) {
  Scene s;
  s.name = "lanes";
  s.robot = paper_params(N);
  s.initial.theta = 0;
  s.ground.patches = {SurfacePatch{.x_begin = 0.02, .mu = 0.4}};
  s.boxes = {Box{.x_near = -0.05, .width = 0.11, .height = 0.06}};
  return s;
}

double rel_diff(const VectorXd& a, const VectorXd& b) {
  return (a - b).lpNorm<Eigen::Infinity>() / (1.0 + b.lpNorm<Eigen::Infinity>());
}

std::vector<int> widths() {
  std::vector<int> w;
  for (int x : {8, 4})
    if (x <= LanePlant::machine_width()) w.push_back(x);
  return w;
}

}  // namespace

TEST(LanePlant, EachMemberAsThePlantEvaluatesIt) {
  if (widths().empty())
    GTEST_SKIP() << "SKIPPED LOUDLY: this machine has neither AVX-512 nor AVX2+FMA; LanePlant cannot run here";
  std::mt19937 rng(41);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const double a = 0.5e-3;  // θh of the sweep's step
  for (int width : widths()) {
    for (int N : {3, 6}) {
      SCOPED_TRACE("width " + std::to_string(width) + ", N = " + std::to_string(N));
      Plant plant(stair_like(N));
      Scene no_corners_scene = stair_like(N);
      no_corners_scene.boxes[0].corner_contact = false;
      Plant no_corners(no_corners_scene);  // to count the states where the box's corners act
      LanePlant lanes(plant, width);
      const Model& m = plant.model();
      const int n = m.nq(), n1 = m.nq1(), J = m.joints();
      ASSERT_EQ(lanes.nq(), n);
      ImplicitTerms ref;
      ref.M = MatrixXd::Zero(n, n);
      ref.F = VectorXd::Zero(n);
      ref.dFdq = MatrixXd::Zero(n, n);
      ref.dFdv = MatrixXd::Zero(n, n);
      ref.dFdq_v = VectorXd::Zero(n);
      ref.dq_in_dv = a;
      ref.with_jacobian = false;
      ref.check_mass = false;
      LaneTerms out = lanes.make_terms();
      LaneInputs in = lanes.make_inputs();
      std::vector<double> q(static_cast<size_t>(n * width)), v(q.size());
      int contacts = 0, band = 0, corners = 0;
      for (int round = 0; round < 40; ++round) {
        std::vector<VectorXd> qs, vs;
        for (int l = 0; l < width; ++l) {
          VectorXd ql = pedalwave::model::testing::random_q(m, rng);
          ql(m.i_theta_N()) = 0.3 * u(rng);
          ql(m.i_px()) = 0.1 * u(rng);
          ql(m.i_pz()) = 0.02 * u(rng) + (l % 3 == 0 ? 0.05 : 0.0);  // some up at the box's top
          if (l == 1 && round % 2 == 1) {  // nearly flat, 2 mm under the box's top: across its edges
            for (int j = 0; j < J; ++j) ql(m.i_alpha(j)) = ql(m.i_beta(j)) = 0.01 * u(rng);
            ql(m.i_theta_N()) = 0.02 * u(rng);
            ql(m.i_px()) = 0.05 * u(rng);
            ql(m.i_pz()) = 0.058;
          }
          const VectorXd vl = pedalwave::model::testing::random_v(m, rng, (round + l) % 3 == 0 ? 1e-3 : 0.3);
          for (int i = 0; i < n; ++i) {
            q[static_cast<size_t>(i * width + l)] = ql(i);
            v[static_cast<size_t>(i * width + l)] = vl(i);
          }
          for (int j = 0; j < J; ++j) {
            const size_t x = static_cast<size_t>(j * width + l);
            in.tau[x] = 0.1 * u(rng);
            in.kp[x] = l == width - 1 ? 0.0 : 30.0 + u(rng);  // the last member's torque off
            in.beta_ref[x] = 0.5 * u(rng);
            in.kd[x] = l == width - 1 ? 0.0 : 15.0;
            in.beta_dot_ref[x] = u(rng);
            if (l == width - 1) in.tau[x] = in.beta_ref[x] = in.beta_dot_ref[x] = 0.0;
          }
          qs.push_back(ql);
          vs.push_back(vl);
        }
        const bool with_mass = round % 2 == 0;
        // The Jacobian ∂F/∂v + a ∂F/∂q in every other round, half of them for a Newton iterate
        // whose step started at v0 (ImplicitTerms::v_start): v0 with some points' velocities
        // reversed or in the stick band.
        const bool with_jacobian = round % 4 >= 2;
        std::vector<double> v0(v.size());
        std::vector<VectorXd> v0s;
        for (int l = 0; l < width; ++l) {
          VectorXd x(n);
          for (int i = 0; i < n; ++i) x(i) = v[static_cast<size_t>(i * width + l)] * (i % 2 == 0 ? -1.0 : 1e-3);
          for (int i = 0; i < n; ++i) v0[static_cast<size_t>(i * width + l)] = x(i);
          v0s.push_back(x);
        }
        const bool from_start = round % 4 == 3;
        lanes.evaluate(q.data(), v.data(), in, with_mass, out, with_jacobian ? a : 0.0, from_start ? v0.data() : nullptr);
        ref.with_jacobian = with_jacobian;
        for (int l = 0; l < width; ++l) {
          for (int j = 0; j < J; ++j) {
            const size_t x = static_cast<size_t>(j * width + l);
            plant.input().tau(j) = in.tau[x];
            plant.input().kp(j) = in.kp[x];
            plant.input().beta_ref(j) = in.beta_ref[x];
            plant.input().kd(j) = in.kd[x];
            plant.input().beta_dot_ref(j) = in.beta_dot_ref[x];
          }
          ref.v_start = from_start ? &v0s[static_cast<size_t>(l)] : nullptr;
          ASSERT_TRUE(plant.implicit_terms(0.0, qs[static_cast<size_t>(l)], vs[static_cast<size_t>(l)], ref));
          ref.v_start = nullptr;
          if (with_jacobian) {
            MatrixXd D(n, n);
            for (int c = 0; c < n; ++c)
              for (int r = 0; r < n; ++r) D(r, c) = out.D[static_cast<size_t>((c * n + r) * width + l)];
            EXPECT_LE((D - ref.dFdv).lpNorm<Eigen::Infinity>(), 1e-12 * (1.0 + ref.dFdv.lpNorm<Eigen::Infinity>()))
                << "round " << round << ", member " << l << "\nD lanes\n" << D << "\nD plant\n" << ref.dFdv;
          }
          VectorXd F(n), dqv(n);
          for (int i = 0; i < n; ++i) {
            F(i) = out.F[static_cast<size_t>(i * width + l)];
            dqv(i) = out.dFdq_v[static_cast<size_t>(i * width + l)];
          }
          EXPECT_LE(rel_diff(F, ref.F), 1e-12) << "round " << round << ", member " << l << "\nF lanes " << F.transpose()
                                               << "\nF plant " << ref.F.transpose();
          if (with_mass) {
            EXPECT_LE(rel_diff(dqv, ref.dFdq_v), 1e-12) << "round " << round << ", member " << l;
          }
          EXPECT_EQ(out.signature[static_cast<size_t>(l)], ref.signature) << "round " << round << ", member " << l;
          if (with_mass) {
            MatrixXd M = m.M_spin();
            for (int c = 0; c < n1; ++c)
              for (int r = 0; r < n1; ++r) M(r, c) = out.Mb[static_cast<size_t>((c * n1 + r) * width + l)];
            EXPECT_LE((M - ref.M).lpNorm<Eigen::Infinity>(), 1e-12 * (1.0 + ref.M.lpNorm<Eigen::Infinity>()))
                << "round " << round << ", member " << l;
          }
          ContactReport rep;
          plant.report(qs[static_cast<size_t>(l)], vs[static_cast<size_t>(l)], rep);
          contacts += rep.active;
          for (int k = 0; k < m.points(); ++k) band += rep.f_normal(k) > 0 && std::abs(rep.f_tangent(k)) < 0.8 * 0.82 * rep.f_normal(k) * 0.999;
          no_corners.input() = plant.input();
          ImplicitTerms other = ref;
          other.with_jacobian = false;
          ASSERT_TRUE(no_corners.implicit_terms(0.0, qs[static_cast<size_t>(l)], vs[static_cast<size_t>(l)], other));
          corners += other.F != ref.F;
        }
      }
      EXPECT_GT(contacts, 40 * width) << "too few contacts to test anything";
      EXPECT_GT(band, 10) << "too few contacts in the stick band";
      EXPECT_GT(corners, 10) << "too few states with the box's corners acting";
    }
  }
}

TEST(LanePlant, NamesTheScenesItCannotRun) {
  Scene s = stair_like(6);
  EXPECT_EQ(LanePlant::unsupported(s), "");
  s.robot.link_shape = LinkShape::kCapsule;
  s.robot.link_radius = 0.01;
  EXPECT_EQ(LanePlant::unsupported(s), "link_shape is not segment");
  s = stair_like(6);
  s.ground.law = FrictionLaw::kTanh;
  EXPECT_EQ(LanePlant::unsupported(s), "the ground's friction law is not regularized");
  s = stair_like(6);
  s.torque_limit_on = true;
  EXPECT_EQ(LanePlant::unsupported(s), "a torque limit is on");
  s = stair_like(6);
  s.robot.joints = JointModel::kRigid;
  EXPECT_EQ(LanePlant::unsupported(s), "the joints are not flexible");
  Plant rigid(s);
  try {
    LanePlant lanes(rigid, 4);
    ADD_FAILURE() << "a rigid scene was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("scene 'lanes': the joints are not flexible"), std::string::npos) << e.what();
  }
  if (LanePlant::machine_width() > 0) {
    Plant ok(stair_like(6));
    EXPECT_THROW(LanePlant(ok, 2), std::invalid_argument);
    EXPECT_THROW(LanePlant(ok, 16), std::invalid_argument);
  }
}

// LaneStepper: each member stepped in lockstep is the member stepped alone by its Integrator
// (implicit_contact at 1 ms, its Jacobian kept and refreshed), over 4 s of a gait on the stair
// scene with the box at the head (every contact kind, the Jacobian refreshed in ≈ 30 % of the
// steps): the same evaluation, Jacobian, step and unconverged counts member by member, and the
// states equal to 1e-9.
TEST(LaneStepper, EachMemberAsItsOwnIntegratorStepsIt) {
  if (widths().empty())
    GTEST_SKIP() << "SKIPPED LOUDLY: this machine has neither AVX-512 nor AVX2+FMA; LanePlant cannot run here";
  for (int width : widths()) {
    SCOPED_TRACE("width " + std::to_string(width));
    Scene sc = stair_like(6);
    sc.boxes[0].x_near = std::numeric_limits<double>::quiet_NaN();
    sc.boxes[0].ahead_of_head = 0.0;
    sc.ground.patches.clear();
    IntegratorOptions io;
    io.method = Method::kImplicitContact;
    io.h = 1e-3;
    Plant plant(sc);
    LanePlant lanes(plant, width);
    LaneStepper stepper(lanes, plant, io);
    const Model& m = plant.model();
    const int n = m.nq(), J = m.joints();
    std::vector<Plant> plants;
    std::vector<Integrator> integs;
    std::vector<VectorXd> qs, vs;
    plants.reserve(static_cast<size_t>(width));
    for (int l = 0; l < width; ++l) {
      plants.emplace_back(sc);
      integs.emplace_back(n, io);
      VectorXd q, v;
      plants.back().initial_state(q, v);
      qs.push_back(q);
      vs.push_back(v);
    }
    std::vector<double> q(static_cast<size_t>(n * width)), v(q.size());
    for (int l = 0; l < width; ++l)
      for (int i = 0; i < n; ++i) {
        q[static_cast<size_t>(i * width + l)] = qs[static_cast<size_t>(l)](i);
        v[static_cast<size_t>(i * width + l)] = vs[static_cast<size_t>(l)](i);
      }
    LaneInputs in = lanes.make_inputs();
    std::vector<StepStatus> status(static_cast<size_t>(width), StepStatus::kOk);
    const double h = 1e-3;
    for (int k = 0; k < 4000; ++k) {
      const double t = k * h;
      for (int l = 0; l < width; ++l) {
        ActuatorInput& u = plants[static_cast<size_t>(l)].input();
        for (int j = 0; j < J; ++j) {
          const double A = 0.6 + 0.05 * l, ph = 3.14159 * t - 1.2566 * j + 0.3 * l;
          u.kp(j) = 30.0;
          u.kd(j) = 15.0;
          u.beta_ref(j) = A * std::sin(ph);
          u.beta_dot_ref(j) = A * 3.14159 * std::cos(ph);
          const size_t x = static_cast<size_t>(j * width + l);
          in.kp[x] = u.kp(j);
          in.kd[x] = u.kd(j);
          in.beta_ref[x] = u.beta_ref(j);
          in.beta_dot_ref[x] = u.beta_dot_ref(j);
          in.tau[x] = 0.0;
        }
        ASSERT_EQ(integs[static_cast<size_t>(l)].step(plants[static_cast<size_t>(l)], t, h, qs[static_cast<size_t>(l)],
                                                       vs[static_cast<size_t>(l)]),
                  StepStatus::kOk);
      }
      stepper.step(t, h, q.data(), v.data(), in, status.data());
    }
    for (int l = 0; l < width; ++l) {
      SCOPED_TRACE("member " + std::to_string(l));
      EXPECT_EQ(status[static_cast<size_t>(l)], StepStatus::kOk);
      const IntegratorStats& a = stepper.stats(l);
      const IntegratorStats& b = integs[static_cast<size_t>(l)].stats();
      EXPECT_EQ(a.steps, b.steps);
      EXPECT_EQ(a.evaluations, b.evaluations);
      EXPECT_EQ(a.jacobians, b.jacobians);
      EXPECT_EQ(a.newton_unconverged, b.newton_unconverged);
      EXPECT_GT(b.jacobians, b.steps / 10) << "too few Jacobian refreshes to test them";
      double dq = 0.0, dv = 0.0;
      for (int i = 0; i < n; ++i) {
        dq = std::max(dq, std::abs(q[static_cast<size_t>(i * width + l)] - qs[static_cast<size_t>(l)](i)));
        dv = std::max(dv, std::abs(v[static_cast<size_t>(i * width + l)] - vs[static_cast<size_t>(l)](i)));
      }
      EXPECT_LE(dq, 1e-9);
      EXPECT_LE(dv, 1e-9);
      ContactReport rep;
      plants[static_cast<size_t>(l)].report(qs[static_cast<size_t>(l)], vs[static_cast<size_t>(l)], rep);
      std::printf("width %d member %d: %llu evaluations, %llu Jacobians, %llu unconverged, |dq| %.2g, |dv| %.2g, p_x %.4f m\n",
                  width, l, (unsigned long long)b.evaluations, (unsigned long long)b.jacobians,
                  (unsigned long long)b.newton_unconverged, dq, dv, qs[static_cast<size_t>(l)](m.i_px()));
    }
  }
}
