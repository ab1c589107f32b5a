// Gait generator (P-1, P-34): hand values, derivatives against finite differences with a
// time-varying η, and bit-exactness of the plain gait.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <stdexcept>

#include "pedalwave/control/gait.hpp"

namespace pc = pedalwave::control;
using std::numbers::pi;

TEST(Gait, HandComputedValuesAtDefaults) {
  const pc::GaitParams p;  // A_p = π/4, ω = π
  const double eta = -2.0 * pi / 5.0;
  // t = 0.25 s, joint 3: φ = π/4 + 2η = π/4 − 4π/5 = −11π/20.
  const pc::GaitPoint g = pc::gait_joint(p, 0.25, 3, eta, 0.0, 0.0);
  const double phi = -11.0 * pi / 20.0;
  EXPECT_NEAR(g.alpha_d, (pi / 4.0) * std::sin(phi), 1e-15);
  EXPECT_NEAR(g.alpha_d, -0.7757, 1e-4);  // (π/4)·sin(−99°) = 0.785398·(−0.987688)
  EXPECT_NEAR(g.alpha_d_dot, (pi / 4.0) * std::cos(phi) * pi, 1e-15);
  EXPECT_NEAR(g.alpha_d_dot, -0.3860, 1e-4);  // (π²/4)·cos(−99°) = 2.4674·(−0.156434)
  EXPECT_NEAR(g.alpha_d_ddot, -(pi / 4.0) * std::sin(phi) * pi * pi, 1e-14);
  // Joint 1 has no spatial phase: α^d_1 = A_p sin(ω t) whatever η is.
  const pc::GaitPoint g1 = pc::gait_joint(p, 0.5, 1, 123.0, 7.0, 9.0);
  EXPECT_DOUBLE_EQ(g1.alpha_d, pi / 4.0);
  EXPECT_NEAR(g1.alpha_d_dot, 0.0, 1e-15);
}

TEST(Gait, PlainGaitIsBitExact) {
  const pc::GaitParams p;
  const double eta = -2.0 * pi / 5.0;
  for (int k = 0; k < 1000; ++k) {
    const double t = 1e-3 * k;
    for (int j = 1; j <= 5; ++j) {
      EXPECT_EQ(pc::gait_joint(p, t, j, eta, 0.0, 0.0).alpha_d,
                p.A_p * std::sin(p.omega * t + eta * static_cast<double>(j - 1)));
    }
  }
}

// η(t) = η0 + a sin(w t): the η̇ term of α̇^d (and the η̈ term of α̈^d) must be there for the
// derivative to be exact.
TEST(Gait, DerivativesMatchFiniteDifferencesWithTimeVaryingEta) {
  const pc::GaitParams p{0.7, 2.5};
  const double eta0 = -1.2, a = 0.4, w = 3.0;
  auto eta = [&](double t) { return eta0 + a * std::sin(w * t); };
  auto eta_dot = [&](double t) { return a * w * std::cos(w * t); };
  auto eta_ddot = [&](double t) { return -a * w * w * std::sin(w * t); };
  auto alpha = [&](double t, int j) { return pc::gait_joint(p, t, j, eta(t), 0.0, 0.0).alpha_d; };
  const double h = 1e-5;
  double worst_without_eta_dot = 0.0;
  for (double t : {0.0, 0.37, 1.1, 2.9, 5.3}) {
    for (int j = 1; j <= 8; ++j) {
      const pc::GaitPoint g = pc::gait_joint(p, t, j, eta(t), eta_dot(t), eta_ddot(t));
      const double fd1 = (alpha(t + h, j) - alpha(t - h, j)) / (2.0 * h);
      const double fd2 = (alpha(t + h, j) - 2.0 * alpha(t, j) + alpha(t - h, j)) / (h * h);
      EXPECT_NEAR(g.alpha_d_dot, fd1, 1e-7) << "t=" << t << " j=" << j;
      EXPECT_NEAR(g.alpha_d_ddot, fd2, 2e-4) << "t=" << t << " j=" << j;
      const double without = pc::gait_joint(p, t, j, eta(t), 0.0, 0.0).alpha_d_dot;
      worst_without_eta_dot = std::max(worst_without_eta_dot, std::abs(without - fd1));
    }
  }
  // The test can fail: dropping η̇ (P-1's formula) is wrong by far more than the tolerance.
  EXPECT_GT(worst_without_eta_dot, 1.0);
}

TEST(Gait, ValidationNamesTheField) {
  pc::GaitParams p;
  p.A_p = -0.1;
  try {
    pc::validate(p);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("gait.A_p = -0.1"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(">= 0"), std::string::npos) << e.what();
  }
  p = {};
  p.omega = std::nan("");
  EXPECT_THROW(pc::validate(p), std::invalid_argument);
  EXPECT_NO_THROW(pc::validate(pc::GaitParams{}));
}
