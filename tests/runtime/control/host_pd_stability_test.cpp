// Host-side PD discrete stability: the analytic bounds, the recursion itself, and an independent
// fine-step simulation of the continuous motor with a zero-order-held PD.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>

#include <Eigen/Core>
#include <Eigen/Eigenvalues>

#include "pedalwave/control/host_pd_stability.hpp"

namespace pc = pedalwave::control;

namespace {
constexpr double kJ = 255.0 * 255.0 * 5e-8;  // n² I_r = 3.25125e-3 kg·m²

// Continuous motor J β̈ = u − K β (link fixed at 0) with u = −K_p β_k − K_D β̇_k held over each
// period, integrated by RK4 with `sub` substeps per period. Returns [β, β̇] after `steps` periods.
Eigen::Vector2d simulate_zoh(double K, double Kp, double KD, double T, int steps, Eigen::Vector2d x,
                             int sub = 200) {
  const double h = T / sub;
  for (int k = 0; k < steps; ++k) {
    const double u = -Kp * x(0) - KD * x(1);
    auto f = [&](const Eigen::Vector2d& y) { return Eigen::Vector2d(y(1), (u - K * y(0)) / kJ); };
    for (int s = 0; s < sub; ++s) {
      const Eigen::Vector2d k1 = f(x), k2 = f(x + 0.5 * h * k1), k3 = f(x + 0.5 * h * k2),
                            k4 = f(x + h * k3);
      x += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4);
    }
  }
  return x;
}
}  // namespace

TEST(HostPdStability, VelocityFeedbackAloneHasFactorOneMinusKdTOverJ) {
  for (double T : {1e-4, 4e-4, 1e-3}) {
    const Eigen::MatrixXd M = pc::host_pd_closed_loop(kJ, 0.0, 0.0, 15.0, T);
    ASSERT_EQ(M.rows(), 2);
    // [1, T − K_D T²/(2J); 0, 1 − K_D T/J]
    EXPECT_NEAR(M(0, 0), 1.0, 1e-12);
    EXPECT_NEAR(M(1, 0), 0.0, 1e-12);
    EXPECT_NEAR(M(0, 1), T - 15.0 * T * T / (2.0 * kJ), 1e-12);
    EXPECT_NEAR(M(1, 1), 1.0 - 15.0 * T / kJ, 1e-10);
  }
  // The per-step factor 1 − K_D T/J leaves the unit circle at T = 2J/K_D.
  EXPECT_NEAR(2.0 * kJ / 15.0, 4.335e-4, 1e-7);
}

TEST(HostPdStability, ExactBoundWithoutSpringIsTwoJOverKd) {
  // Jury test with K = 0: stable iff T < 2J/K_D (and T < 2 K_D/K_p, irrelevant here).
  const pc::HostPdStability s = pc::check_host_pd_stability(kJ, 0.0, 30.0, 15.0, 1e-3);
  EXPECT_NEAR(s.critical_period, 2.0 * kJ / 15.0, 1e-9);
  EXPECT_NEAR(s.velocity_bound, 2.0 * kJ / 15.0, 1e-15);
  EXPECT_NEAR(s.min_rate, 2306.8, 0.1);
  EXPECT_FALSE(s.stable);
  EXPECT_TRUE(pc::check_host_pd_stability(kJ, 0.0, 30.0, 15.0, 0.99 * 2.0 * kJ / 15.0).stable);
  EXPECT_FALSE(pc::check_host_pd_stability(kJ, 0.0, 30.0, 15.0, 1.01 * 2.0 * kJ / 15.0).stable);
  // The other Jury condition binds when K_p is large: T < 2 K_D / K_p.
  const double Kp = 3e5, KD = 15.0;  // 2K_D/K_p = 1e-4 s < 2J/K_D
  const pc::HostPdStability s2 = pc::check_host_pd_stability(kJ, 0.0, Kp, KD, 1e-3);
  EXPECT_NEAR(s2.critical_period, 2.0 * KD / Kp, 1e-9);
}

TEST(HostPdStability, PaperGainsAt1kHzAreUnstableAndTheSpringBarelyMovesTheLimit) {
  const pc::HostPdStability s = pc::check_host_pd_stability(kJ, 3.0, 30.0, 15.0, 1e-3);
  EXPECT_FALSE(s.stable);
  EXPECT_NEAR(s.spectral_radius, 3.616, 1e-3);
  // Necessary bound holds; the spring shifts the exact limit by < 0.1 %.
  EXPECT_LE(s.critical_period, s.velocity_bound);
  EXPECT_NEAR(s.critical_period / s.velocity_bound, 1.0, 1e-3);
  EXPECT_TRUE(pc::check_host_pd_stability(kJ, 3.0, 30.0, 15.0, 1.0 / 5000.0).stable);
  // A free light link or a heavy one: same limit to < 0.1 %; one period of delay halves it.
  for (double I : {1e-5, 1e-3, 1e-1}) {
    pc::HostPdLoopOptions o;
    o.link_inertia = I;
    EXPECT_NEAR(pc::check_host_pd_stability(kJ, 3.0, 30.0, 15.0, 1e-3, o).critical_period /
                    s.velocity_bound, 1.0, 1e-3) << "I_link " << I;
  }
  pc::HostPdLoopOptions d1;
  d1.delay_steps = 1;
  EXPECT_NEAR(pc::check_host_pd_stability(kJ, 3.0, 30.0, 15.0, 1e-3, d1).critical_period /
                  s.velocity_bound, 0.5, 0.01);
}

TEST(HostPdStability, RecursionGrowsOrDecaysAtTheSpectralRadius) {
  for (double T : {2e-4, 4.2e-4, 4.5e-4, 1e-3}) {
    const Eigen::MatrixXd M = pc::host_pd_closed_loop(kJ, 3.0, 30.0, 15.0, T);
    const double rho = pc::host_pd_spectral_radius(kJ, 3.0, 30.0, 15.0, T);
    // Iterate x_{k+1} = (Φ − ΓF) x_k, renormalizing every step; after a burn-in (other mode
    // gone) the mean growth per step is ρ.
    Eigen::VectorXd x(2);
    x << 0.01, 0.0;
    const int n = 400;
    for (int k = 0; k < n; ++k) {
      x = M * x;
      x /= x.norm();
    }
    double log_growth = 0.0;
    for (int k = 0; k < n; ++k) {
      x = M * x;
      log_growth += std::log(x.norm());
      x /= x.norm();
    }
    const double growth = std::exp(log_growth / n);
    EXPECT_NEAR(growth, rho, 1e-3 * rho) << "T=" << T;
    EXPECT_EQ(growth < 1.0, rho < 1.0) << "T=" << T;
  }
}

TEST(HostPdStability, ClosedLoopMatrixMatchesFineSimulationOfTheContinuousMotor) {
  // Independent of the matrix exponential: RK4 with 200 substeps per period.
  for (double T : {2e-4, 1e-3}) {
    const Eigen::MatrixXd M = pc::host_pd_closed_loop(kJ, 3.0, 30.0, 15.0, T);
    Eigen::Vector2d x0(0.02, -0.3);
    Eigen::Vector2d xm = x0;
    for (int k = 0; k < 5; ++k) xm = (M * xm).eval();
    const Eigen::Vector2d xs = simulate_zoh(3.0, 30.0, 15.0, T, 5, x0);
    EXPECT_LT((xm - xs).norm(), 1e-9 * std::max(1.0, xs.norm())) << "T=" << T;
  }
  // Across the limit: a continuous simulation diverges just above it and converges just below.
  const double Tc = pc::check_host_pd_stability(kJ, 3.0, 30.0, 15.0, 1e-3).critical_period;
  const Eigen::Vector2d x0(0.01, 0.0);
  EXPECT_GT(simulate_zoh(3.0, 30.0, 15.0, 1.03 * Tc, 3000, x0, 20).norm(), 1.0);
  EXPECT_LT(simulate_zoh(3.0, 30.0, 15.0, 0.97 * Tc, 3000, x0, 20).norm(), 0.01);
}

TEST(HostPdStability, DescribeAndValidation) {
  const pc::HostPdStability s = pc::check_host_pd_stability(kJ, 3.0, 30.0, 15.0, 1e-3);
  const std::string d = pc::describe(s, kJ, 3.0, 30.0, 15.0, 1e-3);
  EXPECT_NE(d.find("UNSTABLE"), std::string::npos) << d;
  EXPECT_NE(d.find("3.616"), std::string::npos) << d;
  EXPECT_NE(d.find("2307"), std::string::npos) << d;
  EXPECT_THROW(pc::check_host_pd_stability(0.0, 3.0, 30.0, 15.0, 1e-3), std::invalid_argument);
  EXPECT_THROW(pc::check_host_pd_stability(kJ, 3.0, -1.0, 15.0, 1e-3), std::invalid_argument);
  EXPECT_THROW(pc::check_host_pd_stability(kJ, 3.0, 30.0, 15.0, 0.0), std::invalid_argument);
  pc::HostPdLoopOptions o;
  o.delay_steps = 9;
  EXPECT_THROW(pc::check_host_pd_stability(kJ, 3.0, 30.0, 15.0, 1e-3, o), std::invalid_argument);
}
