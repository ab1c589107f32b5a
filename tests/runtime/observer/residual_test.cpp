// The motor-side momentum residual and the link-side estimates against the plant's truth.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <vector>

#include <Eigen/Dense>

#include "harness.hpp"
#include "pedalwave/model/kinematics.hpp"

namespace pw = pedalwave;

namespace {

double max_residual(const char* scene, double h, double seconds) {
  pw::faultbench::LoopOptions o;
  o.noise = false;
  o.plant_h = h;
  pw::faultbench::FaultLoop loop(pw::faultbench::shipped_scene(scene), o);
  double m = 0.0;
  for (int i = 0; i < static_cast<int>(seconds / o.period); ++i) {
    EXPECT_EQ(loop.step(), pw::model::StepStatus::kOk);
    if (loop.t() < 0.5) continue;
    for (int j = 0; j < 5; ++j)
      m = std::max(m, std::abs(loop.observer().core().residual()[static_cast<std::size_t>(j)]));
  }
  return m;
}

// Noise-free, healthy: the residual is what the plant's integrator does differently from the
// continuous model (implicit velocity evaluates the module PD at the step's end: an apparent
// viscous term ≈ k_p h/2 · β̇). It shrinks in proportion to the plant step h.
TEST(Residual, HealthyResidualIsThePlantsIntegrationErrorAndShrinksWithH) {
  const double r_coarse = max_residual("flat_high_friction", 2.5e-4, 4.0);
  const double r_fine = max_residual("flat_high_friction", 1.0e-4, 4.0);
  // k_p h/2 · max|β̇| (A_p ω ≈ 2.5 rad/s) with margin
  EXPECT_LT(r_coarse, 30.0 * 2.5e-4 / 2 * 2.5 * 1.5);
  EXPECT_LT(r_fine, 0.55 * r_coarse);  // ∝ h (0.4 expected)
  EXPECT_GT(r_coarse, 0.0);
}

// Contact forces act on the body rows only: the stair's (and the ground's) forces do not change
// the motor residual, while the link-side external torque estimate sees them.
TEST(Residual, TerrainIndependent) {
  const double flat = max_residual("flat_high_friction", 2.5e-4, 15.0);
  const double stair = max_residual("stair", 2.5e-4, 15.0);
  EXPECT_LT(stair, 1.3 * flat);
  EXPECT_LT(stair, 0.5 * pw::faultbench::campaign_params(pw::faultbench::shipped_scene("stair")).r_threshold);
}

// The residual of a torque-gain fault is (g − 1)·u (its signature): least squares of r on the
// equally filtered u and β̇ (β̇ carries the plant's integration error, see above) gives g − 1 and
// explains r; the other joints' residuals stay quiet.
TEST(Residual, GainFaultSignatureOnItsJointOnly) {
  pw::faultbench::LoopOptions o;
  o.noise = false;
  pw::faultbench::FaultLoop loop(pw::faultbench::shipped_scene("flat_high_friction"), o);
  pw::model::FaultSpec f;
  f.type = pw::model::FaultType::kTorqueGain;
  f.joint = 1;
  f.t_start = 3.0;
  f.value = 0.5;
  loop.injector().add(f);
  double u_f = 0.0, bd_f = 0.0;  // u and β̇ low-passed like the residual (K_O)
  const double a = 1.0 - std::exp(-loop.observer().core().params().K_O * o.period);
  Eigen::Matrix2d G = Eigen::Matrix2d::Zero();
  Eigen::Vector2d g = Eigen::Vector2d::Zero();
  double rr = 0.0, other = 0.0;
  std::vector<std::array<double, 3>> rows;
  pw::drivers::Command cmd_prev{};
  double beta_prev = 0.0;
  for (int i = 0; i < 6000; ++i) {
    if (i > 0) cmd_prev = loop.command();
    ASSERT_EQ(loop.step(), pw::model::StepStatus::kOk);
    // The module law averaged over the period just applied (ZOH command, continuous PD):
    // ū = τ + k_p (β_ref − mean β) + k_d (β̇_ref − Δβ/T).
    const double b1 = loop.feedback().beta[1];
    const double u_avg = i == 0 ? 0.0
                                : cmd_prev.tau[1] + cmd_prev.kp[1] * (cmd_prev.beta_ref[1] - 0.5 * (beta_prev + b1)) +
                                      cmd_prev.kd[1] * (cmd_prev.beta_dot_ref[1] - (b1 - beta_prev) / o.period);
    beta_prev = b1;
    u_f += a * (u_avg - u_f);
    bd_f += a * (loop.feedback().beta_dot[1] - bd_f);
    const auto& r = loop.observer().core().residual();
    if (loop.t() >= 3.5) {  // after the onset transient (5/K_O)
      const Eigen::Vector2d x(u_f, bd_f);
      G += x * x.transpose();
      g += x * r[1];
      rr += r[1] * r[1];
      rows.push_back({u_f, bd_f, r[1]});
      other = std::max({other, std::abs(r[0]), std::abs(r[2]), std::abs(r[3]), std::abs(r[4])});
    }
  }
  const Eigen::Vector2d th = G.ldlt().solve(g);
  double e2 = 0.0;
  for (const auto& row : rows) e2 += std::pow(row[2] - th(0) * row[0] - th(1) * row[1], 2);
  const double n = static_cast<double>(rows.size());
  EXPECT_GT(std::sqrt(rr / n), 1.5 * loop.observer().core().params().r_threshold);
  EXPECT_NEAR(th(0), f.value - 1.0, 0.05) << "u coefficient = g - 1";
  EXPECT_LT(std::sqrt(e2 / rr), 0.1) << "relative rms of what the signature leaves unexplained";
  EXPECT_LT(other, 0.6 * loop.observer().core().params().r_threshold);
}

// Link side on flat ground: the external joint-torque estimate follows the true generalized
// contact force on the α rows; the predicted body states follow the true ones.
TEST(LinkSide, ExternalTorqueAndBodyPredictionOnFlatGround) {
  pw::faultbench::LoopOptions o;
  pw::faultbench::FaultLoop loop(pw::faultbench::shipped_scene("flat_high_friction"), o);
  auto& sim = loop.sim().sim();
  auto& plant = sim.plant();
  const auto& m = plant.model();
  Eigen::VectorXd Q = Eigen::VectorXd::Zero(m.nq());
  double sxy = 0, sxx = 0, syy = 0, sx = 0, sy = 0;
  int n = 0;
  const double px0 = sim.q()(m.i_px());
  double th_err = 0.0, pz_err = 0.0;
  for (int i = 0; i < 20000; ++i) {
    ASSERT_EQ(loop.step(), pw::model::StepStatus::kOk);
    if (loop.t() < 1.0) continue;
    // Truth at the state the observer just measured (before this cycle's write advanced it is not
    // available; the sample is one period old: compare against the state at the next read).
    Q.setZero();
    pw::model::update_kinematics(m, plant.data(), sim.q(), sim.v());
    plant.contact_forces(sim.q(), sim.v(), Q, nullptr, nullptr);
    const auto& body = loop.observer().core().body();
    th_err = std::max(th_err, std::abs(body[0] - sim.q()(m.i_theta_N())));
    pz_err = std::max(pz_err, std::abs(body[2] - sim.q()(m.i_pz())));
    for (int j = 0; j < 5; ++j) {
      const double x = loop.observer().core().tau_ext()[static_cast<std::size_t>(j)], y = Q(m.i_alpha(j));
      sxy += x * y, sxx += x * x, syy += y * y, sx += x, sy += y, ++n;
    }
  }
  const double cov = sxy / n - sx / n * sy / n;
  const double corr = cov / std::sqrt((sxx / n - sx / n * sx / n) * (syy / n - sy / n * sy / n));
  EXPECT_GT(corr, 0.9) << "tau_ext vs true contact torque on the alpha rows";
  const double dx_true = sim.q()(m.i_px()) - px0;
  const double dx_pred = loop.observer().core().body()[1];
  EXPECT_GT(dx_true, 0.1);  // the robot walked (20 s)
  EXPECT_NEAR(dx_pred, dx_true, 0.3 * dx_true) << "predicted p_x (odometry-like)";
  EXPECT_LT(th_err, 0.2);
  EXPECT_LT(pz_err, 0.01);
  EXPECT_NEAR(loop.observer().core().forward_speed(), dx_true / 20.0, 0.5 * dx_true / 20.0);
  RecordProperty("tau_ext_corr", std::to_string(corr));
  RecordProperty("px_true", std::to_string(dx_true));
  RecordProperty("px_pred", std::to_string(dx_pred));
  RecordProperty("theta_N_err_max", std::to_string(th_err));
  RecordProperty("p_z_err_max", std::to_string(pz_err));
  RecordProperty("speed_pred", std::to_string(loop.observer().core().forward_speed()));
}

}  // namespace
