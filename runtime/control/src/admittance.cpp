#include "pedalwave/control/admittance.hpp"

#include <algorithm>
#include <cmath>
#include <complex>

#include "validate.hpp"

namespace pedalwave::control {

AdmittanceZoh discretize_admittance(double M_d, double D_d, double K_d, double dt) noexcept {
  // A = [0 1; −k −c]; Cayley–Hamilton: e^{A t} = e^{σ t} [C(t) I + S(t) (A − σ I)],
  // σ = tr(A)/2 = −c/2, δ = σ² − det(A) = c²/4 − k;
  // δ > 0: C = cosh(q t), S = sinh(q t)/q;  δ < 0: C = cos(q t), S = sin(q t)/q  (q = √|δ|);
  // δ = 0: C = 1, S = t.
  const double k = K_d / M_d;  // [1/s²]
  const double c = D_d / M_d;  // [1/s]
  const double sigma = -0.5 * c;
  const double delta = sigma * sigma - k;
  double C = 1.0;
  double S = dt;
  if (delta > 0.0) {
    const double q = std::sqrt(delta);
    C = std::cosh(q * dt);
    S = std::sinh(q * dt) / q;
  } else if (delta < 0.0) {
    const double q = std::sqrt(-delta);
    C = std::cos(q * dt);
    S = std::sin(q * dt) / q;
  }
  const double e = std::exp(sigma * dt);

  AdmittanceZoh z;
  z.dt = dt;
  // A − σI = [c/2 1; −k −c/2]
  z.Phi(0, 0) = e * (C + 0.5 * c * S);
  z.Phi(0, 1) = e * S;
  z.Phi(1, 0) = -e * S * k;
  z.Phi(1, 1) = e * (C - 0.5 * c * S);
  // Γ = A⁻¹ (Φ − I) [0; 1], A⁻¹ = (1/k) [−c −1; k 0]  (A invertible since k > 0);
  // the second row is Φ12 because d/dt Φ12 = Φ22.
  z.Gamma(0) = (1.0 - z.Phi(1, 1) - c * z.Phi(0, 1)) / k;
  z.Gamma(1) = z.Phi(0, 1);
  return z;
}

double spectral_radius(const AdmittanceZoh& zoh) noexcept {
  // Eigenvalues of a real 2×2: (tr ± √(tr² − 4 det)) / 2.
  const double tr = zoh.Phi.trace();
  const double det = zoh.Phi(0, 0) * zoh.Phi(1, 1) - zoh.Phi(0, 1) * zoh.Phi(1, 0);
  const std::complex<double> disc = std::sqrt(std::complex<double>(tr * tr - 4.0 * det, 0.0));
  const double r1 = std::abs(0.5 * (tr + disc));
  const double r2 = std::abs(0.5 * (tr - disc));
  return std::max(r1, r2);
}

Admittance::Admittance(const AdmittanceParams& params, int joints, double period)
    : params_(params), joints_(joints) {
  detail::require_joints(joints);
  detail::require_positive("admittance.M_d", params.M_d, "[N·m·s²/rad]");
  detail::require_positive("admittance.D_d", params.D_d, "[N·m·s/rad] (the admittance must be damped)");
  detail::require_positive("admittance.K_d", params.K_d, "[N·m/rad] (the admittance must return to Π_n)");
  detail::require_finite("admittance.k_c", params.k_c, "[-]");
  detail::require_positive("period", period, "[s]");
  if (std::isnan(params.eta_min) || params.eta_min == std::numeric_limits<double>::infinity()) {
    detail::fail("admittance.eta_min", detail::format_value(params.eta_min),
                 "a number < eta_max or -inf (no bound) [rad]");
  }
  if (std::isnan(params.eta_max) || params.eta_max == -std::numeric_limits<double>::infinity()) {
    detail::fail("admittance.eta_max", detail::format_value(params.eta_max),
                 "a number > eta_min or +inf (no bound) [rad]");
  }
  if (!(params.eta_min < params.eta_max)) {
    detail::fail("admittance.eta_max", detail::format_value(params.eta_max),
                 "> admittance.eta_min = " + detail::format_value(params.eta_min) + " [rad]");
  }
  Pi_n_ = detail::per_joint("admittance.eta_n", params.eta_n, joints);
  for (int j = 0; j < joints; ++j) {
    const double eta = Pi_n_[static_cast<std::size_t>(j)];
    detail::require_finite(detail::indexed("admittance.eta_n", j), eta, "[rad]");
    if (eta < params.eta_min || eta > params.eta_max) {
      detail::fail(detail::indexed("admittance.eta_n", j), detail::format_value(eta),
                   "within [eta_min, eta_max] = [" + detail::format_value(params.eta_min) + ", " +
                       detail::format_value(params.eta_max) + "] [rad]");
    }
  }
  nominal_ = discretize_admittance(params.M_d, params.D_d, params.K_d, period);
}

void Admittance::reset(AdmittanceState& s) const noexcept {
  s.joints = joints_;
  s.x.fill(0.0);
  s.v.fill(0.0);
  s.zoh = nominal_;
}

double Admittance::eta_ddot(const AdmittanceState& s, int i, double Q_e) const noexcept {
  const auto u = static_cast<std::size_t>(i);
  const double f = params_.k_c == 0.0 ? 0.0 : params_.k_c * Q_e;  // k_c Q_e [N·m]
  return (f - params_.D_d * s.v[u] - params_.K_d * s.x[u]) / params_.M_d;
}

void Admittance::step(AdmittanceState& s, std::span<const double> Q_e, double dt,
                      std::span<std::uint8_t> flags) const noexcept {
  // Refresh the cached ZOH matrices only when the period changed (exact ZOH for any dt).
  if (dt != s.zoh.dt) s.zoh = discretize_admittance(params_.M_d, params_.D_d, params_.K_d, dt);
  const Eigen::Matrix2d& Phi = s.zoh.Phi;
  const Eigen::Vector2d& Gamma = s.zoh.Gamma;
  const bool open_loop = params_.k_c == 0.0;

  for (int j = 0; j < joints_; ++j) {
    const auto u = static_cast<std::size_t>(j);
    // Forcing f = k_c Q_e / M_d; exactly 0 in open loop so that Π stays at Π_n bit-for-bit.
    double f = 0.0;
    if (!open_loop) {
      if (!std::isfinite(Q_e[u])) {
        flags[u] |= kJointBadTorque;  // hold this joint's η: never integrate a NaN
        continue;
      }
      f = params_.k_c * Q_e[u] / params_.M_d;
    }
    const double x = s.x[u];
    const double v = s.v[u];
    double x_next = Phi(0, 0) * x + Phi(0, 1) * v + Gamma(0) * f;
    double v_next = Phi(1, 0) * x + Phi(1, 1) * v + Gamma(1) * f;

    // Optional bounds on η = Π_n + x: clamp, and stop the rate pushing outwards.
    const double eta = Pi_n_[u] + x_next;
    if (eta > params_.eta_max) {
      x_next = params_.eta_max - Pi_n_[u];
      v_next = std::min(v_next, 0.0);
      flags[u] |= kJointPiBound;
    } else if (eta < params_.eta_min) {
      x_next = params_.eta_min - Pi_n_[u];
      v_next = std::max(v_next, 0.0);
      flags[u] |= kJointPiBound;
    }
    s.x[u] = x_next;
    s.v[u] = v_next;
  }
}

}  // namespace pedalwave::control
