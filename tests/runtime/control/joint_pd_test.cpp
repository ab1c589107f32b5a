// Joint PD (P-33), torque limits and the Command hand-off for both placements.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <limits>

#include "pedalwave/control/joint_pd.hpp"

namespace pc = pedalwave::control;
constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(JointPd, HandComputedTorque) {
  // u = −30 (0.12 − 0.10) − 15 (−0.4 − 0.6) = −0.6 + 15 = 14.4
  EXPECT_NEAR(pc::pd_torque(30.0, 15.0, 0.12, -0.4, 0.10, 0.6), 14.4, 1e-12);
  // On the reference: zero torque.
  EXPECT_EQ(pc::pd_torque(30.0, 15.0, 0.3, 0.2, 0.3, 0.2), 0.0);
  // Sign: motor ahead of the reference is pushed back.
  EXPECT_LT(pc::pd_torque(30.0, 15.0, 0.5, 0.0, 0.0, 0.0), 0.0);
}

TEST(JointPd, MagnitudeLimitAndFlag) {
  auto r = pc::limit_torque(2.5, 0.0, 1.2, kInf, 1e-3);
  EXPECT_EQ(r.u, 1.2);
  EXPECT_EQ(r.flags, pc::kJointSatMagnitude);
  r = pc::limit_torque(-7.0, 0.0, 1.2, kInf, 1e-3);
  EXPECT_EQ(r.u, -1.2);
  EXPECT_EQ(r.flags, pc::kJointSatMagnitude);
  r = pc::limit_torque(1.1999, 0.0, 1.2, kInf, 1e-3);
  EXPECT_EQ(r.u, 1.1999);
  EXPECT_EQ(r.flags, 0);
  r = pc::limit_torque(1e300, 0.0, kInf, kInf, 1e-3);  // no limits configured
  EXPECT_EQ(r.u, 1e300);
  EXPECT_EQ(r.flags, 0);
}

TEST(JointPd, RateLimitAppliedAfterMagnitude) {
  // 100 N·m/s over 1 ms allows 0.1 N·m of change.
  auto r = pc::limit_torque(0.5, 0.2, 10.0, 100.0, 1e-3);
  EXPECT_NEAR(r.u, 0.3, 1e-15);
  EXPECT_EQ(r.flags, pc::kJointSatRate);
  r = pc::limit_torque(-0.5, 0.2, 10.0, 100.0, 1e-3);
  EXPECT_NEAR(r.u, 0.1, 1e-15);
  EXPECT_EQ(r.flags, pc::kJointSatRate);
  // Both limits active: clamp to 1.0, then rate from 0.95 allows up to 1.05 → 1.0 (only magnitude).
  r = pc::limit_torque(3.0, 0.95, 1.0, 100.0, 1e-3);
  EXPECT_EQ(r.u, 1.0);
  EXPECT_EQ(r.flags, pc::kJointSatMagnitude);
  // From 0.5: magnitude clamps 3 → 1, rate clamps 1 → 0.6: both flags, still within ±tau_max.
  r = pc::limit_torque(3.0, 0.5, 1.0, 100.0, 1e-3);
  EXPECT_NEAR(r.u, 0.6, 1e-15);
  EXPECT_EQ(r.flags, pc::kJointSatMagnitude | pc::kJointSatRate);
  // A bad dt disables the rate limit (never produces NaN).
  r = pc::limit_torque(0.5, 0.2, 10.0, 100.0, std::nan(""));
  EXPECT_EQ(r.u, 0.5);
  EXPECT_EQ(r.flags, 0);
}

TEST(JointPd, FillCommandForBothPlacements) {
  const std::array<double, 3> Kp{30, 31, 32}, KD{15, 16, 17}, u{0.1, -0.2, 0.3},
      ff{0.01, 0.02, 0.03}, ad{0.4, 0.5, 0.6}, add{-1.0, -2.0, -3.0};
  pedalwave::drivers::Command host, module;
  host.kp.fill(99.0);
  pc::fill_command(pc::PdPlacement::kHost, 3, Kp, KD, u, ff, ad, add, host);
  pc::fill_command(pc::PdPlacement::kModule, 3, Kp, KD, u, ff, ad, add, module);
  EXPECT_EQ(host.joints, 3);
  EXPECT_EQ(module.joints, 3);
  for (std::size_t i = 0; i < 3; ++i) {
    EXPECT_EQ(host.tau[i], u[i]);
    EXPECT_EQ(host.kp[i], 0.0);
    EXPECT_EQ(host.kd[i], 0.0);
    EXPECT_EQ(host.beta_ref[i], ad[i]);
    EXPECT_EQ(module.tau[i], ff[i]);
    EXPECT_EQ(module.kp[i], Kp[i]);
    EXPECT_EQ(module.kd[i], KD[i]);
    EXPECT_EQ(module.beta_ref[i], ad[i]);
    EXPECT_EQ(module.beta_dot_ref[i], add[i]);
  }
  EXPECT_FALSE(module.torque_off);
}

// The module's law (interface/io.hpp) with the module-side fields is P-33 plus the feed-forward:
// both placements give the same torque at the sampling instant.
TEST(JointPd, ModuleLawEqualsHostLawAtTheSample) {
  const double Kp = 30.0, KD = 15.0, beta = 0.21, beta_dot = -0.7, ad = 0.15, add = 0.33, ff = 0.05;
  const std::array<double, 1> kp{Kp}, kd{KD}, u{0.0}, f{ff}, a{ad}, ad_dot{add};
  pedalwave::drivers::Command c;
  pc::fill_command(pc::PdPlacement::kModule, 1, kp, kd, u, f, a, ad_dot, c);
  const double module_u = c.tau[0] + c.kp[0] * (c.beta_ref[0] - beta) + c.kd[0] * (c.beta_dot_ref[0] - beta_dot);
  EXPECT_NEAR(module_u, pc::pd_torque(Kp, KD, beta, beta_dot, ad, add) + ff, 1e-14);
}
