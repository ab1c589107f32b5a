#include "pedalwave/control/host_pd_stability.hpp"

#include <cmath>
#include <limits>
#include <sstream>

#include <Eigen/Eigenvalues>
#include <unsupported/Eigen/MatrixFunctions>

#include "validate.hpp"

namespace pedalwave::control {
namespace {

constexpr double kScanStart = 1e-6;   // shortest period examined [s] (1 MHz)
constexpr double kScanEnd = 10.0;     // longest period examined [s]
constexpr double kScanFactor = 1.05;  // geometric scan step [-]
constexpr double kStableMargin = 1e-12;  // ρ < 1 − margin counts as stable (rounding of eig)

void validate_loop(double J, double K_spring, double K_p, double K_D, double T,
                   const HostPdLoopOptions& o) {
  detail::require_positive("host PD check: J (reflected inertia n²·I_r)", J, "[kg·m²]");
  detail::require_non_negative("host PD check: K_spring", K_spring, "[N·m/rad]");
  detail::require_non_negative("host PD check: K_p", K_p, "[N·m/rad]");
  detail::require_non_negative("host PD check: K_D", K_D, "[N·m·s/rad]");
  detail::require_positive("host PD check: T (control period)", T, "[s]");
  detail::require_non_negative("host PD check: link_inertia", o.link_inertia, "[kg·m²] (0 = fixed link)");
  if (o.delay_steps < 0 || o.delay_steps > 8) {
    detail::fail("host PD check: delay_steps", std::to_string(o.delay_steps), "an integer in 0…8");
  }
}

double max_abs_eigenvalue(const Eigen::MatrixXd& M) {
  Eigen::EigenSolver<Eigen::MatrixXd> es(M, /*computeEigenvectors=*/false);
  return es.eigenvalues().cwiseAbs().maxCoeff();
}

}  // namespace

Eigen::MatrixXd host_pd_closed_loop(double J, double K_spring, double K_p, double K_D, double T,
                                    const HostPdLoopOptions& options) {
  validate_loop(J, K_spring, K_p, K_D, T, options);

  // Continuous plant: fixed link x = [β, β̇]; free link x = [β, β̇, α, α̇].
  const bool free_link = options.link_inertia > 0.0;
  const Eigen::Index n = free_link ? 4 : 2;
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n, n);
  Eigen::VectorXd B = Eigen::VectorXd::Zero(n);
  A(0, 1) = 1.0;
  A(1, 0) = -K_spring / J;
  B(1) = 1.0 / J;
  if (free_link) {
    A(1, 2) = K_spring / J;
    A(2, 3) = 1.0;
    A(3, 0) = K_spring / options.link_inertia;
    A(3, 2) = -K_spring / options.link_inertia;
  }

  // Exact ZOH: exp([A B; 0 0] T) = [Φ Γ; 0 1].
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(n + 1, n + 1);
  M.topLeftCorner(n, n) = A * T;
  M.topRightCorner(n, 1) = B * T;
  const Eigen::MatrixXd E = M.exp();
  const Eigen::MatrixXd Phi = E.topLeftCorner(n, n);
  const Eigen::VectorXd Gamma = E.topRightCorner(n, 1);

  // Feedback u = −F x (reference 0: the loop's stability does not depend on α^d).
  Eigen::RowVectorXd F = Eigen::RowVectorXd::Zero(n);
  F(0) = K_p;
  F(1) = K_D;

  const int d = options.delay_steps;
  if (d == 0) return Phi - Gamma * F;

  // Delay: z = [x; w_1 … w_d], w_i = u_{k−i}; x' = Φ x + Γ w_d, w_1' = −F x, w_i' = w_{i−1}.
  Eigen::MatrixXd Z = Eigen::MatrixXd::Zero(n + d, n + d);
  Z.topLeftCorner(n, n) = Phi;
  Z.block(0, n + d - 1, n, 1) = Gamma;
  Z.block(n, 0, 1, n) = -F;
  for (int i = 1; i < d; ++i) Z(n + i, n + i - 1) = 1.0;
  return Z;
}

double host_pd_spectral_radius(double J, double K_spring, double K_p, double K_D, double T,
                               const HostPdLoopOptions& options) {
  return max_abs_eigenvalue(host_pd_closed_loop(J, K_spring, K_p, K_D, T, options));
}

HostPdStability check_host_pd_stability(double J, double K_spring, double K_p, double K_D, double T,
                                        const HostPdLoopOptions& options) {
  HostPdStability s;
  s.spectral_radius = host_pd_spectral_radius(J, K_spring, K_p, K_D, T, options);
  s.stable = s.spectral_radius < 1.0 - kStableMargin;
  s.velocity_bound = K_D > 0.0 ? 2.0 * J / K_D : std::numeric_limits<double>::infinity();

  // First period at which the loop stops being stable: geometric scan, then bisection.
  auto unstable = [&](double t) {
    return !(host_pd_spectral_radius(J, K_spring, K_p, K_D, t, options) < 1.0 - kStableMargin);
  };
  s.critical_period = std::numeric_limits<double>::infinity();
  double lo = 0.0;
  for (double t = kScanStart; t <= kScanEnd; t *= kScanFactor) {
    if (unstable(t)) {
      double hi = t;
      if (lo > 0.0) {
        while ((hi - lo) > 1e-9 * hi) {
          const double mid = 0.5 * (lo + hi);
          (unstable(mid) ? hi : lo) = mid;
        }
      }
      s.critical_period = hi;
      break;
    }
    lo = t;
  }
  s.min_rate = std::isfinite(s.critical_period) ? 1.0 / s.critical_period : 0.0;
  return s;
}

std::string describe(const HostPdStability& s, double J, double K_spring, double K_p, double K_D,
                     double T) {
  std::ostringstream o;
  o.precision(4);
  o << "host-side PD at T = " << T << " s (" << 1.0 / T << " Hz) with J = " << J
    << " kg·m², K = " << K_spring << " N·m/rad, K_p = " << K_p << " N·m/rad, K_D = " << K_D
    << " N·m·s/rad: spectral radius " << s.spectral_radius << (s.stable ? " < 1 (stable)" : " >= 1 (UNSTABLE)")
    << "; stable only for T < " << s.critical_period << " s (control rate > " << s.min_rate
    << " Hz); velocity-feedback bound 2J/K_D = " << s.velocity_bound << " s";
  return o.str();
}

}  // namespace pedalwave::control
