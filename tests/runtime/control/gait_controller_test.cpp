// GaitController: composition of admittance → gait → PD → limits, its configuration checks
// (including refusing an unstable host-side PD), freeze/hold, k_c = 0 exactness, non-finite
// inputs, the Command hand-off, and no allocation per update.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <stdexcept>
#include <string>

#include "alloc_counter.hpp"
#include "pedalwave/control/gait_controller.hpp"

namespace pc = pedalwave::control;
using std::numbers::pi;

namespace {

std::string config_error(const pc::GaitControllerParams& p) {
  try {
    pc::GaitController c(p);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

struct Meas {
  std::array<double, 63> beta{}, beta_dot{}, deflection{};
  pc::Measurement view(int n) const {
    const auto u = static_cast<std::size_t>(n);
    return {std::span<const double>(beta.data(), u), std::span<const double>(beta_dot.data(), u),
            std::span<const double>(deflection.data(), u)};
  }
};

}  // namespace

TEST(GaitController, DefaultsConstructModuleSideAndReportHostInstability) {
  const pc::GaitController c{pc::GaitControllerParams{}};
  EXPECT_EQ(c.joints(), 5);
  EXPECT_EQ(c.placement(), pc::PdPlacement::kModule);
  EXPECT_FALSE(c.host_pd_stability().stable);  // for information: host-side would diverge
  EXPECT_NEAR(c.host_pd_stability().spectral_radius, 3.616, 1e-3);
}

TEST(GaitController, RefusesUnstableHostPdWithNumbersAndFix) {
  pc::GaitControllerParams p;
  p.pd.placement = pc::PdPlacement::kHost;
  p.period = 1e-3;
  const std::string m = config_error(p);
  ASSERT_FALSE(m.empty());
  EXPECT_NE(m.find("pd.placement = host"), std::string::npos) << m;
  EXPECT_NE(m.find("spectral radius 3.616"), std::string::npos) << m;
  EXPECT_NE(m.find("pd.placement = module"), std::string::npos) << m;
  EXPECT_NE(m.find("at least 2769 Hz"), std::string::npos) << m;  // 1.2 × 2306.8
  // Fast enough: accepted.
  p.period = 1.0 / 4000.0;
  EXPECT_EQ(config_error(p), "");
  // A lower K_D makes 1 kHz possible (2J/T = 6.5 N·m·s/rad); host-side at 1 kHz with K_D = 5 is fine.
  p.period = 1e-3;
  p.pd.K_D = {5.0};
  EXPECT_EQ(config_error(p), "");
}

TEST(GaitController, ValidationMessages) {
  pc::GaitControllerParams p;
  p.period = 1.0;
  std::string m = config_error(p);
  EXPECT_NE(m.find("period = 1 "), std::string::npos) << m;
  EXPECT_NE(m.find("100 Hz"), std::string::npos) << m;
  p = {};
  p.joints = 64;
  EXPECT_NE(config_error(p).find("joints = 64"), std::string::npos);
  p = {};
  p.pd.K_p = {30, 30, 30};
  m = config_error(p);
  EXPECT_NE(m.find("pd.K_p.size() = 3"), std::string::npos) << m;
  p = {};
  p.pd.K_D = {15, 15, -1, 15, 15};
  m = config_error(p);
  EXPECT_NE(m.find("pd.K_D[2] = -1"), std::string::npos) << m;
  EXPECT_NE(m.find(">= 0"), std::string::npos) << m;
  p = {};
  p.limits.tau_max = {0.0};
  EXPECT_NE(config_error(p).find("limits.tau_max[0] = 0"), std::string::npos);
  p = {};
  p.actuator.K = {std::numeric_limits<double>::infinity()};
  EXPECT_NE(config_error(p).find("actuator.K[0] = inf"), std::string::npos);
  p = {};
  p.gait.A_p = -1.0;
  EXPECT_NE(config_error(p).find("gait.A_p = -1"), std::string::npos);
  p = {};
  p.admittance.M_d = 0.0;
  EXPECT_NE(config_error(p).find("admittance.M_d = 0"), std::string::npos);
}

TEST(GaitController, OpenLoopGaitIsExactAndPiStaysNominalBitForBit) {
  pc::GaitControllerParams p;
  p.admittance.k_c = 0.0;
  const pc::GaitController c(p);
  pc::GaitControllerState s = c.make_state();
  pc::ControlOutput out;
  Meas m;
  const double eta = -2.0 * pi / 5.0;
  for (int k = 0; k < 3000; ++k) {
    const double t = 1e-3 * k;
    for (int j = 0; j < 5; ++j) {  // large, varying spring torques: must not matter with k_c = 0
      m.deflection[static_cast<std::size_t>(j)] = 0.3 * std::sin(7.0 * t + j);
      m.beta[static_cast<std::size_t>(j)] = 0.1 * j;
    }
    c.update(t, 1e-3, m.view(5), s, out);
    for (int j = 0; j < 5; ++j) {
      const auto i = static_cast<std::size_t>(j);
      ASSERT_EQ(out.eta[i], eta);
      ASSERT_EQ(out.eta_dot[i], 0.0);
      ASSERT_EQ(out.alpha_d[i], (pi / 4.0) * std::sin(pi * t + eta * static_cast<double>(j)));
      ASSERT_EQ(out.alpha_d_dot[i], (pi / 4.0) * std::cos(pi * t + eta * static_cast<double>(j)) * pi);
    }
  }
}

TEST(GaitController, HandComputedUpdate) {
  pc::GaitControllerParams p;
  p.joints = 2;
  p.admittance.k_c = 2.0;
  const pc::GaitController c(p);
  pc::GaitControllerState s = c.make_state();
  pc::ControlOutput out;
  Meas m;
  m.beta = {0.1, -0.2};
  m.beta_dot = {0.5, 0.0};
  m.deflection = {0.02, -0.01};
  const double t = 0.1;
  c.update(t, 1e-3, m.view(2), s, out);
  const double eta = -2.0 * pi / 5.0;
  // Q_e = −K · deflection = −3 · [0.02, −0.01]
  EXPECT_NEAR(out.Q_e[0], -0.06, 1e-15);
  EXPECT_NEAR(out.Q_e[1], 0.03, 1e-15);
  // At the first update Π = Π_n, Π̇ = 0, Π̈ = k_c Q_e / M_d.
  EXPECT_EQ(out.eta[1], eta);
  EXPECT_NEAR(out.eta_ddot[1], 2.0 * 0.03, 1e-15);
  // Joint 1: α^d = (π/4) sin(0.1π), α̇^d = (π/4) cos(0.1π) π
  const double ad0 = (pi / 4.0) * std::sin(0.1 * pi), add0 = (pi / 4.0) * std::cos(0.1 * pi) * pi;
  EXPECT_NEAR(out.alpha_d[0], 0.24270, 1e-5);
  EXPECT_NEAR(out.u[0], -30.0 * (0.1 - ad0) - 15.0 * (0.5 - add0), 1e-12);
  // Joint 2: phase 0.1π + η
  const double ad1 = (pi / 4.0) * std::sin(0.1 * pi + eta), add1 = (pi / 4.0) * std::cos(0.1 * pi + eta) * pi;
  EXPECT_NEAR(out.u[1], -30.0 * (-0.2 - ad1) - 15.0 * (0.0 - add1), 1e-12);
  EXPECT_EQ(out.u_raw[1], out.u[1]);
  EXPECT_EQ(out.status, pc::kControlOk);
  // After the step, Π moved in the direction of k_c Q_e: joint 2 up, joint 1 down.
  c.update(t + 1e-3, 1e-3, m.view(2), s, out);
  EXPECT_GT(out.eta[1], eta);
  EXPECT_LT(out.eta[0], eta);
  EXPECT_NEAR(out.eta[1] - eta, 2.0 * 0.03 * 0.5e-6, 1e-9);  // ≈ f T²/2
}

TEST(GaitController, StepResponseThroughControllerReachesKcQeOverKd) {
  pc::GaitControllerParams p;
  p.admittance.k_c = 10.1;
  p.period = 1e-3;
  const pc::GaitController c(p);
  pc::GaitControllerState s = c.make_state();
  pc::ControlOutput out;
  Meas m;
  m.deflection.fill(-0.05);  // Q_e = +0.15 N·m
  for (int k = 0; k < 8000; ++k) c.update(1e-3 * k, 1e-3, m.view(5), s, out);
  for (int j = 0; j < 5; ++j) {
    EXPECT_NEAR(out.eta[static_cast<std::size_t>(j)] - c.admittance().eta_n(j), 10.1 * 0.15 / 17.5, 1e-7);
  }
}

TEST(GaitController, TorqueLimitsAndSaturationFlags) {
  pc::GaitControllerParams p;
  p.joints = 3;
  p.limits.tau_max = {0.5, 100.0, 100.0};
  p.limits.tau_rate_max = {1e9, 1e9, 10.0};  // joint 3: 0.01 N·m per 1 ms
  const pc::GaitController c(p);
  pc::GaitControllerState s = c.make_state();
  pc::ControlOutput out;
  Meas m;
  m.beta = {3.0, 0.0, -3.0};  // large errors: u_raw ≈ −53, ·, +46 N·m at t = 0
  c.update(0.0, 1e-3, m.view(3), s, out);
  EXPECT_EQ(out.u[0], -0.5);
  EXPECT_EQ(out.flags[0], pc::kJointSatMagnitude);
  EXPECT_TRUE(out.saturated(0));
  EXPECT_FALSE(out.saturated(1));
  EXPECT_NEAR(out.u[2], 0.01, 1e-15);  // ramps from 0
  EXPECT_EQ(out.flags[2], pc::kJointSatRate);
  EXPECT_TRUE(out.status & pc::kControlSaturated);
  c.update(1e-3, 1e-3, m.view(3), s, out);
  EXPECT_NEAR(out.u[2], 0.02, 1e-15);
}

TEST(GaitController, FreezeHoldsAlphaDAndResumeContinuesThePhase) {
  pc::GaitControllerParams p;
  p.admittance.k_c = 5.0;
  const pc::GaitController c(p);
  pc::GaitControllerState s = c.make_state();
  pc::ControlOutput out;
  Meas m;
  m.deflection.fill(0.02);
  const double T = 1e-3;
  int k = 0;
  for (; k < 500; ++k) c.update(k * T, T, m.view(5), s, out);
  const pc::ControlOutput before = out;

  c.freeze(s);
  for (int i = 0; i < 300; ++i, ++k) {
    c.update(k * T, T, m.view(5), s, out);
    EXPECT_TRUE(out.status & pc::kControlFrozen);
    for (int j = 0; j < 5; ++j) {
      const auto u = static_cast<std::size_t>(j);
      ASSERT_EQ(out.alpha_d[u], before.alpha_d[u]);  // the last α^d, held exactly
      ASSERT_EQ(out.alpha_d_dot[u], 0.0);
      ASSERT_EQ(out.eta[u], before.eta[u]);  // the admittance is held too
    }
    ASSERT_EQ(out.tau, before.tau);
  }
  // Hold: the PD pulls β to the held α^d with zero rate reference.
  m.beta[0] = before.alpha_d[0] + 0.01;
  c.update(k * T, T, m.view(5), s, out);
  EXPECT_NEAR(out.u[0], -30.0 * 0.01, 1e-12);
  ++k;

  c.resume(s);
  c.update(k * T, T, m.view(5), s, out);
  EXPECT_FALSE(out.status & pc::kControlFrozen);
  // The gait continues from the held phase: τ advanced by one period, not by the pause.
  EXPECT_NEAR(out.tau, before.tau + T, 1e-12);
  for (int j = 0; j < 5; ++j) {
    const auto u = static_cast<std::size_t>(j);
    EXPECT_NEAR(out.alpha_d[u], before.alpha_d[u], 2.0 * T * std::abs(before.alpha_d_dot[u]) + 1e-6);
    EXPECT_NE(out.alpha_d_dot[u], 0.0);
  }
}

TEST(GaitController, ResetRestartsPhaseAtT0) {
  const pc::GaitController c{pc::GaitControllerParams{}};
  pc::GaitControllerState s = c.make_state();
  pc::ControlOutput out;
  Meas m;
  c.reset(s, 1234.5);
  c.update(1234.5, 1e-3, m.view(5), s, out);
  EXPECT_EQ(out.tau, 0.0);
  EXPECT_EQ(out.alpha_d[0], 0.0);
}

TEST(GaitController, NonFiniteInputsAreContained) {
  pc::GaitControllerParams p;
  p.admittance.k_c = 5.0;
  const pc::GaitController c(p);
  pc::GaitControllerState s = c.make_state();
  pc::ControlOutput out;
  Meas m;
  m.beta[1] = std::numeric_limits<double>::quiet_NaN();
  m.deflection[3] = std::numeric_limits<double>::infinity();
  m.deflection[0] = 0.01;
  for (int k = 0; k < 10; ++k) c.update(k * 1e-3, 1e-3, m.view(5), s, out);
  EXPECT_EQ(out.u[1], 0.0);
  EXPECT_TRUE(out.flags[1] & pc::kJointBadMotor);
  EXPECT_TRUE(out.flags[3] & pc::kJointBadTorque);
  EXPECT_EQ(out.flags[0], 0);
  EXPECT_TRUE(out.status & pc::kControlBadMeasurement);
  for (int j = 0; j < 5; ++j) {
    const auto i = static_cast<std::size_t>(j);
    EXPECT_TRUE(std::isfinite(out.u[i])) << j;
    EXPECT_TRUE(std::isfinite(out.eta[i])) << j;
    EXPECT_TRUE(std::isfinite(out.alpha_d[i])) << j;
  }
  EXPECT_EQ(out.eta[3], c.admittance().eta_n(3));  // held
  EXPECT_NE(out.eta[0], c.admittance().eta_n(0));  // others adapt
  // Bad dt: flagged, admittance held.
  c.update(0.02, std::nan(""), m.view(5), s, out);
  const double pi0 = out.eta[0];
  c.update(0.021, -1.0, m.view(5), s, out);
  EXPECT_TRUE(out.status & pc::kControlBadDt);
  c.update(std::numeric_limits<double>::quiet_NaN(), 1e-3, m.view(5), s, out);
  EXPECT_TRUE(out.status & pc::kControlBadDt);
  EXPECT_TRUE(std::isfinite(out.alpha_d[2]));
  EXPECT_TRUE(std::isfinite(out.u[2]));
  c.update(0.022, 1e-3, m.view(5), s, out);
  EXPECT_EQ(out.eta[0], pi0);
  EXPECT_NEAR(out.tau, 0.022, 1e-12);  // the phase is still the clock's
  // Spans too short: no torque, flagged, nothing propagated.
  c.update(0.023, 1e-3, m.view(3), s, out);
  EXPECT_TRUE(out.status & pc::kControlBadMeasurement);
  for (int j = 0; j < 5; ++j) EXPECT_EQ(out.u[static_cast<std::size_t>(j)], 0.0);
}

TEST(GaitController, FillCommandFollowsPlacement) {
  pc::GaitControllerParams p;
  p.joints = 3;
  p.limits.tau_max = {0.2};
  const pc::GaitController module(p);
  p.period = 2e-4;
  p.pd.placement = pc::PdPlacement::kHost;
  const pc::GaitController host(p);
  Meas m;
  m.beta = {0.3, -0.1, 0.0};
  const std::array<double, 3> ff{0.05, 0.5, -0.01};
  for (const pc::GaitController* c : {&module, &host}) {
    pc::GaitControllerState s = c->make_state();
    pc::ControlOutput out;
    c->update(0.05, 1e-3, m.view(3), s, out, ff);
    pedalwave::drivers::Command cmd;
    c->fill_command(out, cmd);
    EXPECT_EQ(cmd.joints, 3);
    for (std::size_t i = 0; i < 3; ++i) {
      EXPECT_EQ(cmd.beta_ref[i], out.alpha_d[i]);
      EXPECT_EQ(cmd.beta_dot_ref[i], out.alpha_d_dot[i]);
      if (c == &host) {
        EXPECT_EQ(cmd.tau[i], out.u[i]);
        EXPECT_EQ(cmd.kp[i], 0.0);
      } else {
        EXPECT_EQ(cmd.tau[i], out.tau_ff[i]);
        EXPECT_EQ(cmd.kp[i], 30.0);
        EXPECT_EQ(cmd.kd[i], 15.0);
      }
    }
    EXPECT_EQ(out.tau_ff[1], 0.2);  // feed-forward limited too
    EXPECT_EQ(out.u_raw[0], pc::pd_torque(30, 15, 0.3, 0.0, out.alpha_d[0], out.alpha_d_dot[0]) + 0.05);
  }
}

TEST(GaitController, MeasurementFromFeedback) {
  pedalwave::drivers::Feedback fb;
  fb.joints = 4;
  fb.beta[3] = 0.7;
  fb.deflection[2] = -0.1;
  const pc::Measurement m = pc::measurement_from(fb);
  EXPECT_EQ(m.beta.size(), 4u);
  EXPECT_EQ(m.beta[3], 0.7);
  EXPECT_EQ(m.deflection[2], -0.1);
  fb.joints = -3;
  EXPECT_EQ(pc::measurement_from(fb).beta.size(), 0u);
}

TEST(GaitController, UpdateAllocatesNothing) {
  pc::GaitControllerParams p;
  p.joints = pc::kMaxJoints;
  p.admittance.k_c = 10.1;
  p.admittance.eta_min = -2.0;
  p.admittance.eta_max = -0.5;
  p.limits.tau_max = {1.0};
  p.limits.tau_rate_max = {50.0};
  const pc::GaitController c(p);
  pc::GaitControllerState s = c.make_state();
  pc::ControlOutput out;
  pedalwave::drivers::Feedback fb;
  fb.joints = pc::kMaxJoints;
  pedalwave::drivers::Command cmd;
  std::array<double, pc::kMaxJoints> ff{};
  pedalwave::test::AllocationScope scope;
  for (int k = 0; k < 2000; ++k) {
    for (int j = 0; j < pc::kMaxJoints; ++j) {
      fb.beta[static_cast<std::size_t>(j)] = 0.1 * std::sin(0.01 * k + j);
      fb.deflection[static_cast<std::size_t>(j)] = 0.05 * std::cos(0.02 * k + j);
    }
    if (k == 700) c.freeze(s);
    if (k == 900) c.resume(s);
    const double dt = (k % 5 == 0) ? 1.1e-3 : 1e-3;  // changing dt recomputes the ZOH
    c.update(1e-3 * k, dt, pc::measurement_from(fb), s, out, ff);
    c.fill_command(out, cmd);
  }
  EXPECT_EQ(scope.count(), 0u);
  EXPECT_TRUE(std::isfinite(out.u[62]));
}
