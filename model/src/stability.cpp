#include "pedalwave/model/stability.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <vector>

#include <Eigen/Eigenvalues>

#include "pedalwave/model/dynamics.hpp"
#include "pedalwave/model/kinematics.hpp"

namespace pedalwave::model {

namespace {

using cd = std::complex<double>;

constexpr int idx(Effect e) { return static_cast<int>(e); }

// The linear model M ẍ + D ẋ + K x = 0 per effect, at the flat resting pose.
struct Linearization {
  MatrixXd M;
  std::array<MatrixXd, kEffectCount> K, D;
  std::array<bool, kEffectCount> present{};
  double normal_force = 0.0;
};

Linearization linearize(const Scene& scene, const ControlGains& gains) {
  validate(scene);
  const Model m(scene.robot);
  Data d(m);
  const int n = m.nq(), P = m.points();
  Linearization lin;
  for (auto& x : lin.K) x = MatrixXd::Zero(n, n);
  for (auto& x : lin.D) x = MatrixXd::Zero(n, n);

  // Flat pose, at rest; on the ground every point carries m g / P (uniform static penetration).
  VectorXd q = VectorXd::Zero(n), v = VectorXd::Zero(n);
  update_kinematics(m, d, q, v);
  compute_mass_matrix(m, d);
  lin.M = d.M;

  // Motor PD (and motor viscous friction) on the β rows, or on α for rigid joints.
  const double b_m = scene.joint_friction_on ? scene.joint_friction.motor_viscous : 0.0;
  for (int j = 0; j < m.joints(); ++j) {
    const int r = m.flexible() ? m.i_beta(j) : m.i_alpha(j);
    lin.K[idx(Effect::kMotorPd)](r, r) += gains.K_p;
    lin.D[idx(Effect::kMotorPd)](r, r) += gains.K_D + b_m;
  }
  lin.present[idx(Effect::kMotorPd)] = gains.K_p > 0 || gains.K_D + b_m > 0;

  // SEA springs ½ K (β − α)².
  if (m.flexible()) {
    MatrixXd& Ks = lin.K[idx(Effect::kSpring)];
    for (int j = 0; j < m.joints(); ++j) {
      const int a = m.i_alpha(j), b = m.i_beta(j);
      const double k = m.K()(j);
      Ks(a, a) += k;
      Ks(b, b) += k;
      Ks(a, b) -= k;
      Ks(b, a) -= k;
    }
    lin.present[idx(Effect::kSpring)] = true;
  }

  // Ground: every point in contact, normal +Z, tangent X.
  if (scene.ground_on) {
    const Ground& g = scene.ground;
    const double fN = m.total_mass() * scene.robot.g / P;
    lin.normal_force = fN;
    double mu = g.mu;
    for (const SurfacePatch& p : g.patches) mu = std::max(mu, p.mu);
    MatrixXd J = MatrixXd::Zero(2, n);
    for (int k = 0; k < P; ++k) {
      point_jacobian(m, d, k, J);
      const auto jn = J.row(1), jt = J.row(0);
      lin.K[idx(Effect::kContactStiffness)].noalias() += g.k * jn.transpose() * jn;
      lin.D[idx(Effect::kContactDamping)].noalias() += g.d * jn.transpose() * jn;
      const bool with_friction = !(g.friction_at_com && (k % 2) == 0);
      if (!with_friction || mu <= 0 || fN <= 0) continue;
      switch (g.law) {
        case FrictionLaw::kCoulomb: break;  // infinite slope: see notes
        case FrictionLaw::kRegularized:
        case FrictionLaw::kTanh:
          lin.D[idx(Effect::kFriction)].noalias() += (mu * fN / g.v_s) * jt.transpose() * jt;
          lin.present[idx(Effect::kFriction)] = true;
          break;
        case FrictionLaw::kStickSlip: {
          // The plant's anchor spring k_t with damping 2 √(0.1 k_t) (plant.cpp, friction()).
          lin.K[idx(Effect::kFriction)].noalias() += g.k_t * jt.transpose() * jt;
          lin.D[idx(Effect::kFriction)].noalias() +=
              (2.0 * std::sqrt(g.k_t * 0.1)) * jt.transpose() * jt;
          lin.present[idx(Effect::kFriction)] = true;
          break;
        }
      }
    }
    lin.present[idx(Effect::kContactStiffness)] = g.k > 0;
    lin.present[idx(Effect::kContactDamping)] = g.d > 0;
  }
  return lin;
}

// Largest generalized eigenvalue of (A, M), A symmetric positive semi-definite.
double max_generalized(const MatrixXd& A, const MatrixXd& M) {
  if (A.cwiseAbs().maxCoeff() == 0.0) return 0.0;
  Eigen::GeneralizedSelfAdjointEigenSolver<MatrixXd> es(A, M, Eigen::EigenvaluesOnly);
  if (es.info() != Eigen::Success) return std::numeric_limits<double>::quiet_NaN();
  return std::max(0.0, es.eigenvalues().maxCoeff());
}

// Stability polynomials of the explicit Runge–Kutta methods.
cd R_rk4(cd z) { return 1.0 + z * (1.0 + z * (0.5 + z * (1.0 / 6 + z / 24.0))); }
cd R_dopri(cd z) {
  return 1.0 + z * (1.0 + z * (0.5 + z * (1.0 / 6 + z * (1.0 / 24 + z * (1.0 / 120 + z / 600.0)))));
}

// Largest r with |R(r u)| ≤ 1 on [0, r] along the ray of unit direction u (|z| ≤ 8 scanned).
template <class F>
double ray_limit(F R, cd u) {
  constexpr double tol = 1e-12, dr = 2e-3;
  double good = 0.0;
  for (double r = dr; r <= 8.0; r += dr) {
    if (std::abs(R(r * u)) > 1.0 + tol) {
      double lo = good, hi = r;
      for (int i = 0; i < 50; ++i) {
        const double mid = 0.5 * (lo + hi);
        (std::abs(R(mid * u)) > 1.0 + tol ? hi : lo) = mid;
      }
      return lo;
    }
    good = r;
  }
  return kNoLimit;
}

// Semi-implicit Euler on one mode λ² + c λ + ω² = 0: hc < 2 and h²ω² + 2hc < 4.
double si_mode_limit(cd lambda) {
  double c, w2;
  if (std::abs(lambda.imag()) > 1e-12 * std::abs(lambda)) {
    c = -2.0 * lambda.real();
    w2 = std::norm(lambda);
  } else {
    c = -lambda.real();  // overdamped: the first-order decay of this root
    w2 = 0.0;
  }
  c = std::max(c, 0.0);
  double h = c > 0 ? 2.0 / c : kNoLimit;
  if (w2 > 0) h = std::min(h, (-c + std::sqrt(c * c + 4.0 * w2)) / w2);
  return h;
}

// Spectral radius of semi-implicit Euler's amplification matrix for M⁻¹K = Aq', M⁻¹D = Av'.
double si_radius(const MatrixXd& MiK, const MatrixXd& MiD, double h) {
  const int n = static_cast<int>(MiK.rows());
  const MatrixXd I = MatrixXd::Identity(n, n);
  const MatrixXd Vv = I - h * MiD;  // v' = −h M⁻¹K q + (I − h M⁻¹D) v;  q' = q + h v'
  MatrixXd G(2 * n, 2 * n);
  G.topLeftCorner(n, n) = I - h * h * MiK;
  G.topRightCorner(n, n) = h * Vv;
  G.bottomLeftCorner(n, n) = -h * MiK;
  G.bottomRightCorner(n, n) = Vv;
  Eigen::EigenSolver<MatrixXd> es(G, false);
  return es.eigenvalues().cwiseAbs().maxCoeff();
}

struct Modes {
  Eigen::VectorXcd lambda;  // eigenvalues of [0 I; −M⁻¹K −M⁻¹D]
  Eigen::MatrixXcd X;       // their q-parts (columns)
  double scale = 0.0;       // max |λ|
};

Modes modes(const MatrixXd& MiK, const MatrixXd& MiD) {
  const int n = static_cast<int>(MiK.rows());
  MatrixXd A = MatrixXd::Zero(2 * n, 2 * n);
  A.topRightCorner(n, n).setIdentity();
  A.bottomLeftCorner(n, n) = -MiK;
  A.bottomRightCorner(n, n) = -MiD;
  Eigen::EigenSolver<MatrixXd> es(A, true);
  Modes md;
  md.lambda = es.eigenvalues();
  md.X = es.eigenvectors().topRows(n);
  md.scale = md.lambda.cwiseAbs().maxCoeff();
  return md;
}

// A mode is a rigid-body (zero) mode when |λ| is round-off of the largest.
bool zero_mode(cd l, double scale) { return std::abs(l) <= 1e-7 * std::max(scale, 1.0); }
bool undamped(cd l) { return -l.real() <= 1e-9 * std::abs(l); }

double euler_mode_limit(cd l) { return undamped(l) ? 0.0 : -2.0 * l.real() / std::norm(l); }

struct Binding {
  double h = kNoLimit;
  int mode = -1;
};

template <class F>
Binding binding(const Modes& md, F limit_of) {
  Binding b;
  for (Eigen::Index i = 0; i < md.lambda.size(); ++i) {
    const cd l = md.lambda(i);
    if (zero_mode(l, md.scale)) continue;
    const double h = limit_of(l);
    if (h < b.h) b = {h, static_cast<int>(i)};
  }
  return b;
}

// The effect behind the binding mode, from its Rayleigh quotients on the mode shape x:
// ω_e² = x*K_e x / x*M x, c_e = x*D_e x / x*M x. An oscillatory mode (damping ratio < 0.5) is
// named after its largest stiffness (its damping only sets how fast Euler loses it), an
// overdamped one after its largest damping.
Effect attribute(const Linearization& lin, const Eigen::VectorXcd& x, double zeta) {
  const double mx = std::abs(x.dot(lin.M * x));
  Effect best = Effect::kMotorPd;
  double best_score = -1.0;
  for (int e = 0; e < kEffectCount; ++e) {
    if (!lin.present[e]) continue;
    const double score = zeta < 0.5 ? std::abs(x.dot(lin.K[e] * x)) / mx
                                    : std::abs(x.dot(lin.D[e] * x)) / mx;
    if (score > best_score) best_score = score, best = static_cast<Effect>(e);
  }
  return best;
}

MethodLimit make_limit(Method method, const Linearization& lin, const Modes& md, Binding b) {
  MethodLimit ml;
  ml.method = method;
  ml.h_max = b.h;
  if (b.mode >= 0) {
    const cd l = md.lambda(b.mode);
    ml.mode_omega = std::abs(l);
    ml.mode_damping = std::max(0.0, -l.real()) / std::abs(l);
    ml.dominant = attribute(lin, md.X.col(b.mode), ml.mode_damping);
  }
  return ml;
}

struct Analysis {
  Linearization lin;
  MatrixXd MiK, MiD;
  Modes md;
};

// without_friction: the friction slope left out (the "blow-up" limits, see MethodLimit::h_blowup).
Analysis analyse(const Scene& scene, const ControlGains& gains, bool without_friction = false) {
  Analysis a;
  a.lin = linearize(scene, gains);
  if (without_friction) {
    a.lin.K[idx(Effect::kFriction)].setZero();
    a.lin.D[idx(Effect::kFriction)].setZero();
    a.lin.present[idx(Effect::kFriction)] = false;
  }
  const int n = static_cast<int>(a.lin.M.rows());
  MatrixXd K = MatrixXd::Zero(n, n), D = MatrixXd::Zero(n, n);
  for (int e = 0; e < kEffectCount; ++e) {
    K += a.lin.K[e];
    D += a.lin.D[e];
  }
  const Eigen::LLT<MatrixXd> llt(a.lin.M);
  a.MiK = llt.solve(K);
  a.MiD = llt.solve(D);
  a.md = modes(a.MiK, a.MiD);
  return a;
}

// Semi-implicit Euler: the modal estimate, refined on the amplification matrix's spectral radius
// (exact for non-proportional damping too).
double si_limit(const Analysis& a, const Binding& est) {
  if (!std::isfinite(est.h)) return est.h;
  auto unstable = [&](double h) { return si_radius(a.MiK, a.MiD, h) > 1.0 + 1e-7; };
  double lo = 0.5 * est.h, hi = 2.0 * est.h;
  for (int i = 0; i < 8 && unstable(lo); ++i) lo *= 0.5;
  for (int i = 0; i < 8 && !unstable(hi); ++i) hi *= 2.0;
  for (int i = 0; i < 30; ++i) {
    const double mid = std::sqrt(lo * hi);
    (unstable(mid) ? hi : lo) = mid;
  }
  return lo;
}

// Compact number: "4.33e-4", "0.25", "408".
std::string fmt(double v, int sig = 3) {
  if (!std::isfinite(v)) return v > 0 ? "inf" : "nan";
  char buf[48];
  const double a = std::abs(v);
  if (a != 0.0 && (a < 1e-2 || a >= 1e4)) {
    const int ex = static_cast<int>(std::floor(std::log10(a)));
    double mant = v / std::pow(10.0, ex);
    std::snprintf(buf, sizeof buf, "%.*g", sig, mant);
    if (std::abs(std::strtod(buf, nullptr)) >= 10.0) {  // rounding carried into the exponent
      std::snprintf(buf, sizeof buf, "%.*ge%d", sig, mant / 10.0, ex + 1);
      return buf;
    }
    std::snprintf(buf, sizeof buf, "%.*ge%d", sig, mant, ex);
    return buf;
  }
  std::snprintf(buf, sizeof buf, "%.*g", sig, v);
  return buf;
}

const char* method_name(Method m) {
  switch (m) {
    case Method::kExplicitEuler: return "explicit Euler";
    case Method::kSemiImplicitEuler: return "semi-implicit Euler";
    case Method::kImplicitVelocity: return "implicit_velocity";
    case Method::kRK4: return "RK4";
    case Method::kDormandPrince45: return "dopri45";
    case Method::kImplicitContact: return "implicit_contact";
  }
  return "?";
}

std::string effect_phrase(const StabilityReport& r, Effect e) {
  const EffectScale& s = r.effects[static_cast<std::size_t>(idx(e))];
  switch (e) {
    case Effect::kMotorPd:
      return "the motor damping K_D / (n² I_r) = " + fmt(s.rate_max) + " 1/s";
    case Effect::kSpring:
      return "the SEA spring K against the link inertia (ω = " + fmt(s.omega_max) + " rad/s)";
    case Effect::kContactStiffness:
      return "the ground stiffness k against the link masses (ω = " + fmt(s.omega_max) + " rad/s)";
    case Effect::kContactDamping:
      return "the ground damping d against the link masses (d/m up to " + fmt(s.rate_max) + " 1/s)";
    case Effect::kFriction:
      return "the friction slope μ f_N / v_s against the link masses (" + fmt(s.rate_max) +
             " 1/s)";
  }
  return "?";
}

// The binding mode: an overdamped one by its effect's rate, an oscillatory one by its frequency
// and damping ratio (explicit Euler's limit on it is 2ζ/ω).
std::string mode_phrase(const StabilityReport& r, const MethodLimit& ml) {
  if (ml.mode_damping >= 0.5) return effect_phrase(r, ml.dominant);
  const char* what = "?";
  switch (ml.dominant) {
    case Effect::kMotorPd: what = "the motor PD on n² I_r"; break;
    case Effect::kSpring: what = "the SEA spring K against the link inertia"; break;
    case Effect::kContactStiffness: what = "the ground stiffness k against the link masses"; break;
    case Effect::kContactDamping: what = "the ground damping d against the link masses"; break;
    case Effect::kFriction: what = "the friction slope"; break;
  }
  return std::string(what) + " (a mode at ω = " + fmt(ml.mode_omega) + " rad/s, damping ratio " +
         fmt(ml.mode_damping, 2) + ")";
}

// A round step below the limit: 0.95 × limit floored to one significant digit (two when one
// would lose more than 30 %).
double suggest(double limit) {
  const double x = 0.95 * limit;
  const double p = std::pow(10.0, std::floor(std::log10(x)));
  double s = std::floor(x / p) * p;
  if (s < 0.7 * limit) s = std::floor(x / (p / 10)) * (p / 10);
  return s;
}

}  // namespace

const char* to_string(Effect e) {
  switch (e) {
    case Effect::kMotorPd: return "motor_pd";
    case Effect::kSpring: return "spring";
    case Effect::kContactStiffness: return "contact_stiffness";
    case Effect::kContactDamping: return "contact_damping";
    case Effect::kFriction: return "friction";
  }
  return "?";
}

const char* to_string(CheckLevel l) {
  switch (l) {
    case CheckLevel::kOk: return "ok";
    case CheckLevel::kWarning: return "warning";
    case CheckLevel::kError: return "error";
  }
  return "?";
}

MethodLimit StabilityReport::limit(Method m) const {
  switch (m) {
    case Method::kExplicitEuler: return euler;
    case Method::kSemiImplicitEuler: return semi_implicit;
    case Method::kRK4: return rk4;
    case Method::kDormandPrince45: return dopri;
    case Method::kImplicitVelocity:
    case Method::kImplicitContact: break;
  }
  MethodLimit none;
  none.method = m;
  return none;
}

StabilityReport predict_stability(const Scene& scene, const ControlGains& gains) {
  const Analysis a = analyse(scene, gains);
  const Linearization& lin = a.lin;
  StabilityReport r;
  r.nq = static_cast<int>(lin.M.rows());
  r.normal_force = lin.normal_force;
  const Params& p = scene.robot;
  if (p.joints == JointModel::kFlexible) {
    r.motor_inertia = p.n * p.n * p.I_r;
    const double b_m = scene.joint_friction_on ? scene.joint_friction.motor_viscous : 0.0;
    if (gains.K_D + b_m > 0) r.motor_time_scale = r.motor_inertia / (gains.K_D + b_m);
  }

  // All effects together.
  const int n = r.nq;
  MatrixXd K = MatrixXd::Zero(n, n), D = MatrixXd::Zero(n, n);
  for (int e = 0; e < kEffectCount; ++e) {
    K += lin.K[e];
    D += lin.D[e];
  }
  r.omega_max = std::sqrt(max_generalized(K, lin.M));
  r.rate_max = max_generalized(D, lin.M);

  const Modes& md = a.md;
  auto limits = [](const Analysis& an, StabilityReport& out) {
    const Modes& mm = an.md;
    out.euler = make_limit(Method::kExplicitEuler, an.lin, mm, binding(mm, euler_mode_limit));
    out.rk4 = make_limit(Method::kRK4, an.lin, mm, binding(mm, [](cd l) {
                           return ray_limit(R_rk4, l / std::abs(l)) / std::abs(l);
                         }));
    out.dopri = make_limit(Method::kDormandPrince45, an.lin, mm, binding(mm, [](cd l) {
                             return ray_limit(R_dopri, l / std::abs(l)) / std::abs(l);
                           }));
    const Binding si = binding(mm, si_mode_limit);
    out.semi_implicit = make_limit(Method::kSemiImplicitEuler, an.lin, mm, si);
    out.semi_implicit.h_max = si_limit(an, si);
  };
  limits(a, r);
  // Friction's slope only acts inside the stick band |v_t| < v_s; above its limit an explicit
  // scheme chatters there with bounded amplitude. The limit without it is where runs blow up.
  StabilityReport hard = r;
  if (lin.present[idx(Effect::kFriction)]) limits(analyse(scene, gains, true), hard);
  for (auto [mine, other] : {std::pair{&r.euler, &hard.euler}, {&r.semi_implicit, &hard.semi_implicit},
                             {&r.rk4, &hard.rk4}, {&r.dopri, &hard.dopri}}) {
    mine->h_blowup = std::max(mine->h_max, other->h_max);
    mine->blowup_dominant = mine->h_blowup > mine->h_max ? other->dominant : mine->dominant;
  }
  for (Eigen::Index i = 0; i < md.lambda.size(); ++i)
    if (!zero_mode(md.lambda(i), md.scale) && undamped(md.lambda(i)))
      r.euler_undamped_omega = std::max(r.euler_undamped_omega, std::abs(md.lambda(i)));

  // Each effect alone (modal limits; semi-implicit Euler from the per-mode formula).
  const Eigen::LLT<MatrixXd> llt(lin.M);
  for (int e = 0; e < kEffectCount; ++e) {
    EffectScale& s = r.effects[static_cast<std::size_t>(e)];
    s.effect = static_cast<Effect>(e);
    s.present = lin.present[e];
    if (!s.present) continue;
    s.omega_max = std::sqrt(max_generalized(lin.K[e], lin.M));
    s.rate_max = max_generalized(lin.D[e], lin.M);
    const Modes me = modes(llt.solve(lin.K[e]), llt.solve(lin.D[e]));
    s.h_euler = binding(me, euler_mode_limit).h;
    s.h_semi_implicit = binding(me, si_mode_limit).h;
    s.h_rk4 = binding(me, [](cd l) { return ray_limit(R_rk4, l / std::abs(l)) / std::abs(l); }).h;
    s.h_dopri =
        binding(me, [](cd l) { return ray_limit(R_dopri, l / std::abs(l)) / std::abs(l); }).h;
  }

  if (scene.ground_on && scene.ground.law == FrictionLaw::kCoulomb)
    r.notes += "exact Coulomb friction has an infinite slope at v_t = 0: no linear step limit; "
               "explicit schemes chatter at rest with velocity jumps of about mu g h. ";
  if (scene.torque_limit_on)
    r.notes += "torque limits ignored (saturation only lowers the effective gains). ";
  if (!scene.boxes.empty())
    r.notes += "boxes not linearized (same k, d as the ground). ";
  return r;
}

double growth_factor(const Scene& scene, const ControlGains& gains, Method method, double h,
                     double duration) {
  if (method == Method::kImplicitVelocity || method == Method::kImplicitContact || !(h > 0))
    return 1.0;
  const Analysis a = analyse(scene, gains);
  const double steps = duration / h;
  double rho = 1.0;
  if (method == Method::kSemiImplicitEuler) {
    rho = si_radius(a.MiK, a.MiD, h);
  } else {
    for (Eigen::Index i = 0; i < a.md.lambda.size(); ++i) {
      const cd z = h * a.md.lambda(i);
      if (zero_mode(a.md.lambda(i), a.md.scale)) continue;
      const double r = method == Method::kExplicitEuler ? std::abs(1.0 + z)
                       : method == Method::kRK4         ? std::abs(R_rk4(z))
                                                        : std::abs(R_dopri(z));
      rho = std::max(rho, r);
    }
  }
  if (rho <= 1.0 + 1e-7) return 1.0;
  const double lg = steps * std::log(rho);
  return lg > 700 ? std::numeric_limits<double>::infinity() : std::exp(lg);
}

std::string stability_message(const StabilityReport& r, Method method, double h) {
  std::ostringstream os;
  if (method == Method::kImplicitContact)
    return "implicit_contact (θ-trapezoid, θ = 0.55, contact and friction solved at the end of the "
           "step) is A-stable: no step limit from these effects; h = " + fmt(h) +
           " s is limited by accuracy only";
  if (method == Method::kImplicitVelocity)
    return "implicit_velocity (linearized backward Euler) has no step limit from these effects; "
           "h = " + fmt(h) + " s is limited by accuracy only";
  const MethodLimit ml = r.limit(method);
  const std::string name = method_name(method);
  if (!std::isfinite(ml.h_max))
    return name + " has no step limit from these effects at h = " + fmt(h) + " s";
  if (method == Method::kDormandPrince45) {
    os << "dopri45 adapts its step; the stiffest mode, " << mode_phrase(r, ml)
       << ", holds it near " << fmt(ml.h_max) << " s";
    return os.str();
  }
  if (ml.h_max <= 0.0) {
    os << "explicit Euler is unstable at every step: the undamped mode at ω = "
       << fmt(r.euler_undamped_omega) << " rad/s (" << effect_phrase(r, ml.dominant)
       << ") grows by √(1 + h²ω²) per step; use semi_implicit_euler, rk4 or implicit_velocity";
    return os.str();
  }
  if (h > ml.h_max && h <= ml.h_blowup) {
    os << "h = " << fmt(h) << " s is above " << name << "'s stability limit " << fmt(ml.h_max)
       << " s set by " << mode_phrase(r, ml) << ": inside the stick band |v_t| < v_s it chatters "
       << "(bounded, inaccurate); it blows up above " << fmt(ml.h_blowup) << " s (" 
       << to_string(ml.blowup_dominant) << "): use h ≤ " << fmt(suggest(ml.h_max), 2)
       << " s, or implicit_velocity";
  } else if (h > ml.h_max) {
    os << "h = " << fmt(h) << " s is above " << name << "'s stability limit " << fmt(ml.h_max)
       << " s set by " << mode_phrase(r, ml) << ": use h ≤ " << fmt(suggest(ml.h_max), 2)
       << " s, or implicit_velocity";
  } else {
    os << "h = " << fmt(h) << " s is within " << name << "'s stability limit " << fmt(ml.h_max)
       << " s (" << fmt(ml.h_max / h, 2) << "× margin) set by " << mode_phrase(r, ml);
  }
  return os.str();
}

StabilityCheck check(const Scene& scene, const ControlGains& gains) {
  return check(scene, gains, scene.integrator, scene.duration);
}

StabilityCheck check(const Scene& scene, const ControlGains& gains, const IntegratorOptions& integ,
                     double duration) {
  StabilityCheck c;
  c.report = predict_stability(scene, gains);
  const Method m = integ.method;
  c.message = stability_message(c.report, m, integ.h);
  if (m == Method::kImplicitVelocity || m == Method::kImplicitContact ||
      m == Method::kDormandPrince45)
    return c;
  c.h_limit = c.report.limit(m).h_max;
  if (integ.h <= 0.8 * c.h_limit) return c;
  c.growth = growth_factor(scene, gains, m, integ.h, duration);
  if (integ.h <= c.h_limit) {
    c.level = CheckLevel::kWarning;
    c.message += "; within 20 % of the limit: contact onset or other poses may push it over";
  } else if (integ.h <= c.report.limit(m).h_blowup) {
    // Above a friction-set limit only: bounded chatter inside the stick band.
    c.level = CheckLevel::kWarning;
    c.message += "; above it the friction chatters inside |v_t| < v_s (bounded, but it adds error); "
                 "runs blow up above " + fmt(c.report.limit(m).h_blowup) + " s";
  } else {
    c.level = c.growth >= 10.0 ? CheckLevel::kError : CheckLevel::kWarning;
    c.message += "; the worst mode grows ×" + fmt(c.growth, 2) + " over " + fmt(duration) + " s";
  }
  return c;
}

}  // namespace pedalwave::model
