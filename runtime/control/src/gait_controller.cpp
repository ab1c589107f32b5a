#include "pedalwave/control/gait_controller.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <tuple>

#include "validate.hpp"

namespace pedalwave::control {
namespace {

constexpr double kMinPeriod = 5e-5;  // 20 kHz [s]
constexpr double kMaxPeriod = 1e-2;  // 100 Hz [s]

// Checks that must pass before any member is built (joints and period size everything else).
const GaitControllerParams& validated(const GaitControllerParams& p) {
  detail::require_joints(p.joints);
  if (!(std::isfinite(p.period) && p.period >= kMinPeriod && p.period <= kMaxPeriod)) {
    detail::fail("period", detail::format_value(p.period),
                 "a control period in [5e-05, 0.01] s, i.e. a rate of 100 Hz … 20 kHz");
  }
  validate(p.gait);
  if (p.pd.placement != PdPlacement::kHost && p.pd.placement != PdPlacement::kModule) {
    detail::fail("pd.placement", std::to_string(static_cast<int>(p.pd.placement)),
                 "host (0) or module (1)");
  }
  return p;
}

JointArray per_joint_checked(std::string_view name, const std::vector<double>& v, int joints,
                             bool allow_zero, bool allow_inf, std::string_view unit) {
  JointArray a = detail::per_joint(name, v, joints);
  for (int j = 0; j < joints; ++j) {
    const double x = a[static_cast<std::size_t>(j)];
    const bool ok = !std::isnan(x) && (allow_inf || std::isfinite(x)) && (allow_zero ? x >= 0.0 : x > 0.0);
    if (!ok) {
      std::string expected = allow_zero ? "a value >= 0 " : "a value > 0 ";
      expected += allow_inf ? "(+inf = no limit) " : "(finite) ";
      expected += unit;
      detail::fail(detail::indexed(name, j), detail::format_value(x), expected);
    }
  }
  return a;
}

}  // namespace

Measurement measurement_from(const drivers::Feedback& fb) noexcept {
  const auto n = static_cast<std::size_t>(std::clamp(fb.joints, 0, drivers::kMaxJoints));
  return Measurement{std::span<const double>(fb.beta.data(), n),
                     std::span<const double>(fb.beta_dot.data(), n),
                     std::span<const double>(fb.deflection.data(), n)};
}

GaitController::GaitController(const GaitControllerParams& params)
    : params_(validated(params)),
      joints_(params.joints),
      admittance_(params.admittance, params.joints, params.period) {
  const int n = joints_;
  K_ = per_joint_checked("actuator.K", params.actuator.K, n, false, false, "[N·m/rad]");
  J_ = per_joint_checked("actuator.reflected_inertia", params.actuator.reflected_inertia, n, false,
                         false, "[kg·m²] (n²·I_r)");
  K_p_ = per_joint_checked("pd.K_p", params.pd.K_p, n, true, false, "[N·m/rad]");
  K_D_ = per_joint_checked("pd.K_D", params.pd.K_D, n, true, false, "[N·m·s/rad]");
  tau_max_ = per_joint_checked("limits.tau_max", params.limits.tau_max, n, false, true, "[N·m]");
  tau_rate_max_ = per_joint_checked("limits.tau_rate_max", params.limits.tau_rate_max, n, false,
                                    true, "[N·m/s]");

  // Discrete stability of a host-side PD at the nominal period, for every joint: with the spring
  // to a fixed link and with K = 0 (the light-link limit); keep the worst. Identical joints are
  // checked once.
  const double T = params.period;
  std::map<std::tuple<double, double, double, double>, HostPdStability> seen;
  int worst_joint = -1;
  for (int j = 0; j < n; ++j) {
    const auto i = static_cast<std::size_t>(j);
    const auto key = std::make_tuple(J_[i], K_[i], K_p_[i], K_D_[i]);
    auto it = seen.find(key);
    if (it == seen.end()) {
      HostPdStability fixed = check_host_pd_stability(J_[i], K_[i], K_p_[i], K_D_[i], T);
      const HostPdStability light = check_host_pd_stability(J_[i], 0.0, K_p_[i], K_D_[i], T);
      if (light.spectral_radius > fixed.spectral_radius) fixed.spectral_radius = light.spectral_radius;
      fixed.stable = fixed.stable && light.stable;
      if (light.critical_period < fixed.critical_period) {
        fixed.critical_period = light.critical_period;
        fixed.min_rate = light.min_rate;
      }
      it = seen.emplace(key, fixed).first;
    }
    if (worst_joint < 0 || it->second.spectral_radius > host_pd_.spectral_radius) {
      host_pd_ = it->second;
      worst_joint = j;
    }
  }

  if (params.pd.placement == PdPlacement::kHost && !host_pd_.stable) {
    const auto i = static_cast<std::size_t>(worst_joint);
    std::string msg = "control: pd.placement = host is discretely unstable at period = " +
                      detail::format_value(T) + " s for joint " + std::to_string(worst_joint + 1) +
                      ": " + describe(host_pd_, J_[i], K_[i], K_p_[i], K_D_[i], T) +
                      ". Fix: set pd.placement = module (the module applies the PD at its own "
                      "internal rate), or run the control loop at a rate of at least " +
                      std::to_string(static_cast<long long>(std::ceil(1.2 * host_pd_.min_rate))) +
                      " Hz (20 % margin), or lower K_D below " +
                      detail::format_value(2.0 * J_[i] / T) + " N·m·s/rad (= 2J/T)";
    throw std::invalid_argument(msg);
  }
}

GaitControllerState GaitController::make_state() const noexcept {
  GaitControllerState s;
  reset(s, 0.0);
  return s;
}

void GaitController::reset(GaitControllerState& state, double t0) const noexcept {
  state.joints = joints_;
  state.t_offset = t0;
  state.tau_last = 0.0;
  state.frozen = false;
  admittance_.reset(state.admittance);
  state.u_prev.fill(0.0);
  // What a freeze before the first update holds: the gait at τ = 0 with Π = Π_n.
  for (int j = 0; j < joints_; ++j) {
    const auto i = static_cast<std::size_t>(j);
    state.eta_held[i] = admittance_.eta(state.admittance, j);
    state.alpha_d_held[i] = gait_joint(params_.gait, 0.0, j + 1, state.eta_held[i], 0.0, 0.0).alpha_d;
  }
}

std::uint32_t GaitController::update(double t, double dt, const Measurement& m,
                                     GaitControllerState& state, ControlOutput& out,
                                     std::span<const double> tau_ff) const noexcept {
  const int n = joints_;
  const auto nz = static_cast<std::size_t>(n);
  out.joints = n;
  out.status = kControlOk;
  std::fill_n(out.flags.begin(), nz, std::uint8_t{0});

  const bool t_ok = std::isfinite(t);
  const bool dt_ok = t_ok && std::isfinite(dt) && dt > 0.0;
  if (!dt_ok) out.status |= kControlBadDt;
  const bool sizes_ok = m.beta.size() >= nz && m.beta_dot.size() >= nz && m.deflection.size() >= nz;
  const bool have_ff = tau_ff.size() >= nz;

  // Gait time: runs with t, or stays at the held phase while frozen (t_offset absorbs the pause).
  const bool frozen = state.frozen;
  double tau = t - state.t_offset;
  if (!t_ok) {
    tau = state.tau_last;  // a non-finite time never reaches the phase
  } else if (frozen) {
    tau = state.tau_last;
    state.t_offset = t - tau;
  }
  if (frozen) out.status |= kControlFrozen;
  out.tau = tau;

  for (int j = 0; j < n; ++j) {
    const auto i = static_cast<std::size_t>(j);
    const double beta = sizes_ok ? m.beta[i] : 0.0;
    const double beta_dot = sizes_ok ? m.beta_dot[i] : 0.0;
    const double deflection = sizes_ok ? m.deflection[i] : 0.0;

    // 1. Measured SEA torque Q_e = K (α − β) = −K · (β − α).
    out.Q_e[i] = generalized_spring_force(K_[i], deflection);

    if (frozen) {
      // 2–3 (frozen). Hold the last running update's Π and α^d exactly, with zero rates.
      out.eta[i] = state.eta_held[i];
      out.eta_dot[i] = 0.0;
      out.eta_ddot[i] = 0.0;
      out.alpha_d[i] = state.alpha_d_held[i];
      out.alpha_d_dot[i] = 0.0;
      out.alpha_d_ddot[i] = 0.0;
    } else {
      // 2. Spatial frequency and its rates from the admittance state.
      out.eta[i] = admittance_.eta(state.admittance, j);
      out.eta_dot[i] = admittance_.eta_dot(state.admittance, j);
      out.eta_ddot[i] = admittance_.eta_ddot(state.admittance, j, out.Q_e[i]);
      if (!std::isfinite(out.eta_ddot[i])) out.eta_ddot[i] = 0.0;  // non-finite Q_e: η held below

      // 3. Gait reference (P-34), 1-based joint number j+1.
      const GaitPoint g =
          gait_joint(params_.gait, tau, j + 1, out.eta[i], out.eta_dot[i], out.eta_ddot[i]);
      out.alpha_d[i] = g.alpha_d;
      out.alpha_d_dot[i] = g.alpha_d_dot;
      out.alpha_d_ddot[i] = g.alpha_d_ddot;
      state.eta_held[i] = out.eta[i];
      state.alpha_d_held[i] = out.alpha_d[i];
    }

    // 4. PD (P-33) + feed-forward, then limits last.
    double ff = have_ff ? tau_ff[i] : 0.0;
    if (!std::isfinite(ff)) ff = 0.0;
    out.tau_ff[i] = std::clamp(ff, -tau_max_[i], tau_max_[i]);
    if (!sizes_ok || !std::isfinite(beta) || !std::isfinite(beta_dot)) {
      out.flags[i] |= kJointBadMotor;
      out.u_raw[i] = 0.0;
      out.u[i] = 0.0;  // no torque from a joint we cannot see
      out.status |= kControlBadMeasurement;
    } else {
      out.u_raw[i] = pd_torque(K_p_[i], K_D_[i], beta, beta_dot, out.alpha_d[i], out.alpha_d_dot[i]) + ff;
      const LimitedTorque lim =
          limit_torque(out.u_raw[i], state.u_prev[i], tau_max_[i], tau_rate_max_[i], dt);
      out.u[i] = lim.u;
      out.flags[i] |= lim.flags;
      if (lim.flags != 0) out.status |= kControlSaturated;
    }
    if (!std::isfinite(deflection)) {
      out.flags[i] |= kJointBadTorque;  // η_j is not advanced with it (Admittance::step)
      out.status |= kControlBadMeasurement;
    }
    if (!sizes_ok) out.status |= kControlBadMeasurement;
    state.u_prev[i] = out.u[i];
  }

  // 5. Advance the admittance from t to t + dt with Q_e(t) held (exact ZOH), unless frozen.
  if (!frozen && dt_ok && sizes_ok) {
    admittance_.step(state.admittance, std::span<const double>(out.Q_e.data(), nz), dt,
                     std::span<std::uint8_t>(out.flags.data(), nz));
    for (int j = 0; j < n; ++j) {
      const std::uint8_t f = out.flags[static_cast<std::size_t>(j)];
      if (f & kJointPiBound) out.status |= kControlPiBound;
      if (f & kJointBadTorque) out.status |= kControlBadMeasurement;
    }
  }
  state.tau_last = tau;
  return out.status;
}

void GaitController::fill_command(const ControlOutput& out, drivers::Command& cmd) const noexcept {
  const auto nz = static_cast<std::size_t>(joints_);
  control::fill_command(params_.pd.placement, joints_, std::span<const double>(K_p_.data(), nz),
                        std::span<const double>(K_D_.data(), nz),
                        std::span<const double>(out.u.data(), nz),
                        std::span<const double>(out.tau_ff.data(), nz),
                        std::span<const double>(out.alpha_d.data(), nz),
                        std::span<const double>(out.alpha_d_dot.data(), nz), cmd);
}

}  // namespace pedalwave::control
