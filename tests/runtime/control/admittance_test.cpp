// Adaptive admittance (P-35): closed-form ZOH against Eigen's matrix exponential, discrete
// stability over 100 Hz … 20 kHz, step response against the continuous solution (steady state,
// overshoot, decay rate from ζ and ω_n), k_c = 0 exactness, bounds, validation.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <unsupported/Eigen/MatrixFunctions>

#include "pedalwave/control/admittance.hpp"

namespace pc = pedalwave::control;

namespace {

// Reference ZOH by the augmented matrix exponential exp([A B; 0 0] T) = [Φ Γ; 0 1].
void reference_zoh(double M, double D, double K, double T, Eigen::Matrix2d& Phi, Eigen::Vector2d& Gamma) {
  Eigen::Matrix3d Maug = Eigen::Matrix3d::Zero();
  Maug(0, 1) = T;
  Maug(1, 0) = -K / M * T;
  Maug(1, 1) = -D / M * T;
  Maug(1, 2) = T;
  const Eigen::Matrix3d E = Maug.exp();
  Phi = E.topLeftCorner<2, 2>();
  Gamma = E.topRightCorner<2, 1>();
}

// Continuous step response of M x'' + D x' + K x = F from rest (textbook closed forms).
double continuous_step(double M, double D, double K, double F, double t) {
  const double wn = std::sqrt(K / M);
  const double zeta = D / (2.0 * std::sqrt(K * M));
  const double xs = F / K;
  if (zeta > 1.0) {
    const double r = wn * std::sqrt(zeta * zeta - 1.0);
    const double l1 = -zeta * wn + r, l2 = -zeta * wn - r;
    return xs * (1.0 - (l2 * std::exp(l1 * t) - l1 * std::exp(l2 * t)) / (l2 - l1));
  }
  const double wd = wn * std::sqrt(1.0 - zeta * zeta);
  return xs * (1.0 - std::exp(-zeta * wn * t) *
                         (std::cos(wd * t) + zeta * wn / wd * std::sin(wd * t)));
}

pc::AdmittanceParams params_with(double k_c, double D_d = 10.0) {
  pc::AdmittanceParams p;
  p.k_c = k_c;
  p.D_d = D_d;
  return p;
}

}  // namespace

TEST(Admittance, ClosedFormZohMatchesMatrixExponential) {
  // Over-, under- and critically damped, over the whole rate range and beyond.
  struct Case { double M, D, K; };
  for (const Case c : {Case{1.0, 10.0, 17.5}, Case{1.0, 2.0, 17.5}, Case{2.0, 2.0 * std::sqrt(2.0 * 8.0), 8.0},
                       Case{0.5, 0.1, 100.0}}) {
    for (double T : {5e-5, 1e-4, 1e-3, 4e-3, 1e-2, 0.3}) {
      const pc::AdmittanceZoh z = pc::discretize_admittance(c.M, c.D, c.K, T);
      Eigen::Matrix2d Phi;
      Eigen::Vector2d Gamma;
      reference_zoh(c.M, c.D, c.K, T, Phi, Gamma);
      EXPECT_EQ(z.dt, T);
      EXPECT_LT((z.Phi - Phi).cwiseAbs().maxCoeff(), 1e-13) << "D=" << c.D << " T=" << T;
      EXPECT_LT((z.Gamma - Gamma).cwiseAbs().maxCoeff(), 1e-12 * std::max(1.0, Gamma.norm()) + 1e-17)
          << "D=" << c.D << " T=" << T;
      // Γ ≈ [T²/2; T] for small T: a relative check where the cancellation in Γ(0) is worst.
      if (T <= 1e-4) {
        EXPECT_NEAR(z.Gamma(0) / (0.5 * T * T), 1.0, 1e-2);
      }
    }
  }
}

TEST(Admittance, DiscreteEigenvaluesInsideUnitCircleFrom100HzTo20kHz) {
  const pc::AdmittanceParams p;
  // Continuous poles of s² + (D/M) s + K/M: −5 ± √7.5 for the defaults.
  const double l_slow = -5.0 + std::sqrt(7.5);
  for (double rate = 100.0; rate <= 20000.0 * 1.0001; rate *= 1.1) {
    const double T = 1.0 / rate;
    const pc::AdmittanceZoh z = pc::discretize_admittance(p.M_d, p.D_d, p.K_d, T);
    Eigen::EigenSolver<Eigen::Matrix2d> es(z.Phi);
    const double rho = es.eigenvalues().cwiseAbs().maxCoeff();
    EXPECT_LT(rho, 1.0) << "rate " << rate;
    // Exact ZOH maps the continuous pole λ to e^{λT}.
    EXPECT_NEAR(rho, std::exp(l_slow * T), 1e-12) << "rate " << rate;
    EXPECT_NEAR(pc::spectral_radius(z), rho, 1e-12);
  }
}

TEST(Admittance, StepResponseMatchesContinuousSolutionAt1kHz) {
  const double k_c = 10.1, Q = 0.8;  // constant measured torque [N·m]
  const pc::Admittance adm(params_with(k_c), 5, 1e-3);
  pc::AdmittanceState s;
  adm.reset(s);
  std::array<double, 5> Q_e{};
  Q_e.fill(Q);
  std::array<std::uint8_t, 5> flags{};
  const double M = 1.0, D = 10.0, K = 17.5, F = k_c * Q;
  double worst = 0.0, peak = -1e9;
  std::vector<double> err;  // x_ss − x at each step
  const double xs = F / K;
  for (int k = 0; k <= 12000; ++k) {
    const double t = 1e-3 * k;
    const double x = adm.eta(s, 2) - adm.eta_n(2);
    worst = std::max(worst, std::abs(x - continuous_step(M, D, K, F, t)));
    peak = std::max(peak, x);
    err.push_back(xs - x);
    adm.step(s, Q_e, 1e-3, flags);
  }
  EXPECT_LT(worst, 1e-12 * xs);  // ZOH of a constant input is exact
  // Steady state Π − Π_n = k_c Q_e / K_d (after 12 s the slow mode is down to e^{−27}).
  EXPECT_NEAR(adm.eta(s, 0) - adm.eta_n(0), k_c * Q / K, 1e-11);
  // ζ = D/(2√(KM)) = 1.195 > 1: no overshoot.
  EXPECT_LE(peak, xs * (1.0 + 1e-12));
  // Tail decays with the slow pole −ζω_n + ω_n√(ζ²−1) = −2.2614 s⁻¹ (between 4 s and 5 s the
  // fast pole's share is e^{−5.48·4} ≈ 3e-10).
  const double wn = std::sqrt(K / M), zeta = D / (2.0 * std::sqrt(K * M));
  const double slow = -zeta * wn + wn * std::sqrt(zeta * zeta - 1.0);
  const double rate = std::log(err[5000] / err[4000]) / 1.0;
  EXPECT_NEAR(rate, slow, 1e-6);
  EXPECT_NEAR(slow, -2.2614, 1e-4);
  for (auto f : flags) EXPECT_EQ(f, 0);
}

TEST(Admittance, UnderdampedOvershootAndPeakTimeMatchZetaAndOmegaN) {
  const double k_c = 2.0, Q = 1.5, D = 2.0;
  const pc::Admittance adm(params_with(k_c, D), 1, 1e-3);
  pc::AdmittanceState s;
  adm.reset(s);
  std::array<double, 1> Q_e{Q};
  std::array<std::uint8_t, 1> flags{};
  double peak = -1e9, t_peak = 0.0, worst = 0.0;
  const double xs = k_c * Q / 17.5;
  for (int k = 0; k <= 8000; ++k) {
    const double t = 1e-3 * k;
    const double x = adm.eta(s, 0) - adm.eta_n(0);
    worst = std::max(worst, std::abs(x - continuous_step(1.0, D, 17.5, k_c * Q, t)));
    if (x > peak) { peak = x; t_peak = t; }
    adm.step(s, Q_e, 1e-3, flags);
  }
  const double wn = std::sqrt(17.5), zeta = D / (2.0 * std::sqrt(17.5));  // ζ = 0.239
  const double overshoot = std::exp(-std::numbers::pi * zeta / std::sqrt(1.0 - zeta * zeta));
  const double tp = std::numbers::pi / (wn * std::sqrt(1.0 - zeta * zeta));
  EXPECT_LT(worst, 1e-12 * xs);
  EXPECT_NEAR(peak / xs - 1.0, overshoot, 1e-5);  // sampled peak within 1 ms of the true one
  EXPECT_NEAR(t_peak, tp, 1e-3);
  EXPECT_NEAR(overshoot, 0.4614, 1e-4);  // 46 % for ζ = 0.239
}

TEST(Admittance, ZeroGainKeepsNominalBitForBitEvenWithNonFiniteTorque) {
  pc::AdmittanceParams p;
  p.k_c = 0.0;
  p.eta_n = {-1.0, -1.1, -1.2, 0.3};
  const pc::Admittance adm(p, 4, 1e-3);
  pc::AdmittanceState s;
  adm.reset(s);
  std::array<double, 4> Q_e{5.0, -3.0, std::numeric_limits<double>::quiet_NaN(),
                            std::numeric_limits<double>::infinity()};
  std::array<std::uint8_t, 4> flags{};
  for (int k = 0; k < 2000; ++k) adm.step(s, Q_e, k % 2 ? 1e-3 : 7e-4, flags);
  for (int j = 0; j < 4; ++j) {
    EXPECT_EQ(adm.eta(s, j), p.eta_n[static_cast<std::size_t>(j)]);
    EXPECT_EQ(adm.eta_dot(s, j), 0.0);
    EXPECT_EQ(adm.eta_ddot(s, j, Q_e[static_cast<std::size_t>(j)]), 0.0);
    EXPECT_EQ(flags[static_cast<std::size_t>(j)], 0);
  }
}

TEST(Admittance, NonFiniteTorqueHoldsOnlyThatJoint) {
  const pc::Admittance adm(params_with(5.0), 3, 1e-3);
  pc::AdmittanceState s;
  adm.reset(s);
  std::array<double, 3> Q_e{1.0, std::numeric_limits<double>::quiet_NaN(), 1.0};
  std::array<std::uint8_t, 3> flags{};
  for (int k = 0; k < 100; ++k) adm.step(s, Q_e, 1e-3, flags);
  EXPECT_GT(adm.eta(s, 0), adm.eta_n(0));
  EXPECT_EQ(adm.eta(s, 1), adm.eta_n(1));
  EXPECT_TRUE(std::isfinite(adm.eta(s, 1)));
  EXPECT_EQ(flags[1], pc::kJointBadTorque);
  EXPECT_EQ(flags[0], 0);
  EXPECT_EQ(adm.eta(s, 0), adm.eta(s, 2));
}

TEST(Admittance, BoundsClampPiAndFlag) {
  pc::AdmittanceParams p = params_with(10.0);
  p.eta_min = -1.5;
  p.eta_max = -1.0;  // Π_n = −2π/5 = −1.2566; unbounded steady state would be Π_n + 10·1/17.5 = −0.685
  const pc::Admittance adm(p, 2, 1e-3);
  pc::AdmittanceState s;
  adm.reset(s);
  std::array<double, 2> Q_e{1.0, -1.0};
  std::array<std::uint8_t, 2> flags{};
  for (int k = 0; k < 3000; ++k) adm.step(s, Q_e, 1e-3, flags);
  EXPECT_NEAR(adm.eta(s, 0), -1.0, 1e-15);
  EXPECT_EQ(adm.eta_dot(s, 0), 0.0);
  EXPECT_NEAR(adm.eta(s, 1), -1.5, 1e-15);
  EXPECT_TRUE(flags[0] & pc::kJointPiBound);
  EXPECT_TRUE(flags[1] & pc::kJointPiBound);
}

TEST(Admittance, VaryingDtStaysExact) {
  // Alternating periods: the cached ZOH is recomputed, and the response is still the exact one.
  const pc::Admittance adm(params_with(3.0), 1, 1e-3);
  pc::AdmittanceState s;
  adm.reset(s);
  std::array<double, 1> Q_e{0.5};
  std::array<std::uint8_t, 1> flags{};
  double t = 0.0;
  for (int k = 0; k < 3000; ++k) {
    const double dt = (k % 3 == 0) ? 2.5e-4 : 1.3e-3;
    adm.step(s, Q_e, dt, flags);
    t += dt;
  }
  EXPECT_NEAR(adm.eta(s, 0) - adm.eta_n(0), continuous_step(1.0, 10.0, 17.5, 1.5, t), 1e-12);
}

TEST(Admittance, ValidationMessagesNameParameterValueAndExpectation) {
  auto message = [](const pc::AdmittanceParams& p, int joints, double period) -> std::string {
    try {
      pc::Admittance a(p, joints, period);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "";
  };
  pc::AdmittanceParams p;
  p.D_d = -1.0;
  std::string m = message(p, 5, 1e-3);
  EXPECT_NE(m.find("admittance.D_d = -1"), std::string::npos) << m;
  EXPECT_NE(m.find("expected a finite value > 0"), std::string::npos) << m;
  p = {};
  p.eta_n = {1.0, 2.0, 3.0};
  m = message(p, 5, 1e-3);
  EXPECT_NE(m.find("admittance.eta_n.size() = 3"), std::string::npos) << m;
  EXPECT_NE(m.find("1 (same value for every joint) or 5"), std::string::npos) << m;
  p = {};
  p.eta_max = -2.0;  // Π_n = −1.2566 outside
  m = message(p, 5, 1e-3);
  EXPECT_NE(m.find("admittance.eta_n[0]"), std::string::npos) << m;
  p = {};
  p.eta_min = 0.0;
  p.eta_max = 0.0;
  m = message(p, 5, 1e-3);
  EXPECT_NE(m.find("admittance.eta_max = 0"), std::string::npos) << m;
  p = {};
  p.K_d = 0.0;
  EXPECT_NE(message(p, 5, 1e-3).find("admittance.K_d = 0"), std::string::npos);
  p = {};
  p.k_c = std::numeric_limits<double>::infinity();
  EXPECT_NE(message(p, 5, 1e-3).find("admittance.k_c = inf"), std::string::npos);
  EXPECT_NE(message(pc::AdmittanceParams{}, 0, 1e-3).find("joints = 0"), std::string::npos);
  EXPECT_NE(message(pc::AdmittanceParams{}, 64, 1e-3).find("1..63"), std::string::npos);
  EXPECT_EQ(message(pc::AdmittanceParams{}, 63, 1e-3), "");
}
