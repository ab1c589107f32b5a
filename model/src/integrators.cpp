#include "pedalwave/model/integrators.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace pedalwave::model {

std::string_view to_string(Method m) {
  switch (m) {
    case Method::kExplicitEuler: return "euler";
    case Method::kSemiImplicitEuler: return "semi_implicit_euler";
    case Method::kImplicitVelocity: return "implicit_velocity";
    case Method::kRK4: return "rk4";
    case Method::kDormandPrince45: return "dopri45";
    case Method::kImplicitContact: return "implicit_contact";
  }
  return "?";
}

Method parse_method(std::string_view name) {
  for (Method m : {Method::kExplicitEuler, Method::kSemiImplicitEuler, Method::kImplicitVelocity,
                   Method::kRK4, Method::kDormandPrince45, Method::kImplicitContact})
    if (name == to_string(m)) return m;
  throw std::invalid_argument("integrator '" + std::string(name) +
                              "' is unknown: expected one of euler, semi_implicit_euler, "
                              "implicit_velocity, rk4, dopri45, implicit_contact");
}

bool is_adaptive(Method m) { return m == Method::kDormandPrince45; }

std::string_view to_string(StepStatus s) {
  switch (s) {
    case StepStatus::kOk: return "ok";
    case StepStatus::kEvalFailed: return "evaluation failed (mass matrix not positive definite)";
    case StepStatus::kNonFinite: return "state became NaN/Inf (unstable step?)";
    case StepStatus::kStepTooSmall: return "adaptive step fell below h_min (stiff or discontinuous)";
  }
  return "?";
}

void validate(const IntegratorOptions& o) {
  auto bad = [](const char* what, double v, const char* expected) {
    std::ostringstream os;
    os << "integrator option " << what << " = " << v << ": " << expected;
    throw std::invalid_argument(os.str());
  };
  if (!(o.h > 0) || !std::isfinite(o.h)) bad("h", o.h, "step must be finite and > 0 [s]");
  if (!(o.newton_tol >= 0) || !std::isfinite(o.newton_tol)) bad("newton_tol", o.newton_tol, "must be finite and >= 0");
  if (o.newton_iterations < 0 || o.newton_iterations > 50)
    bad("newton_iterations", o.newton_iterations, "must be 0 … 50");
  if (!(o.theta >= 0.5 && o.theta <= 1.0)) bad("theta", o.theta, "must be in [0.5, 1]");
  if (o.jacobian_age < 0 || o.jacobian_age > 1000)
    bad("jacobian_age", o.jacobian_age, "must be 0 … 1000 (steps)");
  if (is_adaptive(o.method)) {
    if (!(o.rtol > 0)) bad("rtol", o.rtol, "must be > 0");
    if (!(o.atol > 0)) bad("atol", o.atol, "must be > 0");
    if (!(o.h_min > 0) || o.h_min > o.h_max) bad("h_min", o.h_min, "must be > 0 and <= h_max");
  }
}

StructuredLU::StructuredLU(int n)
    : A_(MatrixXd::Zero(n, n)), d_inv_(VectorXd::Zero(n)), u_inv_(VectorXd::Zero(n)), piv_(Eigen::VectorXi::Zero(n)), n_(n) {}

// Column-major with raw column pointers (restrict: the columns a loop reads and the one it writes
// never overlap), so the inner loops over rows vectorize.
bool StructuredLU::factor(int nd) {
  nd_ = nd;
  const int n = n_, n1 = n - nd;
  double* A = A_.data();
  auto col = [&](int c) { return A + static_cast<std::ptrdiff_t>(c) * n; };
  bool ok = true;
  // The diagonal block: C = A12 A22⁻¹ in place of A12.
  for (int j = 0; j < nd; ++j) {
    double* __restrict cj = col(n1 + j);
    const double d = cj[n1 + j];
    ok = ok && d != 0.0 && std::isfinite(d);
    const double inv = 1.0 / d;
    d_inv_(j) = inv;
    for (int r = 0; r < n1; ++r) cj[r] *= inv;
  }
  // The Schur complement S = A11 − C A21 (column by column; A21's zeros skipped).
  for (int c = 0; c < n1; ++c) {
    double* __restrict ac = col(c);
    for (int j = 0; j < nd; ++j) {
      const double t = ac[n1 + j];
      if (t == 0.0) continue;
      const double* __restrict cj = col(n1 + j);
      for (int r = 0; r < n1; ++r) ac[r] -= cj[r] * t;
    }
  }
  // LU of S with partial pivoting, in place (unit lower L below the diagonal, U on and above).
  for (int k = 0; k < n1; ++k) {
    double* __restrict ak = col(k);
    int p = k;
    double big = std::abs(ak[k]);
    for (int i = k + 1; i < n1; ++i)
      if (std::abs(ak[i]) > big) big = std::abs(ak[i]), p = i;
    piv_(k) = p;
    if (!(big > 0.0) || !std::isfinite(big)) ok = false;
    if (p != k)
      for (int c = 0; c < n1; ++c) std::swap(col(c)[k], col(c)[p]);
    const double inv = 1.0 / ak[k];
    u_inv_(k) = inv;  // the back substitution multiplies (a division there stalled the solve)
    for (int i = k + 1; i < n1; ++i) ak[i] *= inv;
    for (int c = k + 1; c < n1; ++c) {
      double* __restrict ac = col(c);
      const double t = ac[k];
      if (t == 0.0) continue;
      for (int i = k + 1; i < n1; ++i) ac[i] -= ak[i] * t;
    }
  }
  return ok;
}

void StructuredLU::solve(Eigen::Ref<VectorXd> b) const {
  const int n = n_, n1 = n - nd_;
  const double* A = A_.data();
  auto col = [&](int c) { return A + static_cast<std::ptrdiff_t>(c) * n; };
  double* __restrict x = b.data();
  // b1 − A12 A22⁻¹ b2
  for (int j = 0; j < nd_; ++j) {
    const double t = x[n1 + j];
    if (t == 0.0) continue;
    const double* __restrict cj = col(n1 + j);
    for (int r = 0; r < n1; ++r) x[r] -= cj[r] * t;
  }
  // x1 = S⁻¹ (…): the row swaps, then L y = …, U x1 = y (column-oriented).
  for (int k = 0; k < n1; ++k)
    if (piv_(k) != k) std::swap(x[k], x[piv_(k)]);
  for (int k = 0; k < n1; ++k) {
    const double t = x[k];
    if (t == 0.0) continue;
    const double* __restrict ak = col(k);
    for (int i = k + 1; i < n1; ++i) x[i] -= ak[i] * t;
  }
  for (int k = n1 - 1; k >= 0; --k) {
    const double* __restrict ak = col(k);
    const double t = x[k] * u_inv_(k);
    x[k] = t;
    if (t == 0.0) continue;
    for (int i = 0; i < k; ++i) x[i] -= ak[i] * t;
  }
  // x2 = A22⁻¹ (b2 − A21 x1): A21 is the rows n1 … of the first n1 columns.
  for (int j = 0; j < nd_; ++j) {
    double s = x[n1 + j];
    for (int c = 0; c < n1; ++c) s -= col(c)[n1 + j] * x[c];
    x[n1 + j] = d_inv_(j) * s;
  }
}

Integrator::Integrator(int nq, const IntegratorOptions& o)
    : o_(o), nq_(nq), h_adapt_(o.h), lu_(nq), slu_(nq) {
  validate(o_);
  const int n = 2 * nq;
  for (auto* v : {&y_, &y_new_, &tmp_}) *v = VectorXd::Zero(n);
  for (auto& k : k_) k = VectorXd::Zero(n);
  for (auto* v : {&a_, &qtmp_, &vtmp_, &dv_}) *v = VectorXd::Zero(nq);
  imp_.M = MatrixXd::Zero(nq, nq);
  imp_.F = VectorXd::Zero(nq);
  imp_.dFdq = MatrixXd::Zero(nq, nq);
  imp_.dFdv = MatrixXd::Zero(nq, nq);
  A_ = MatrixXd::Zero(nq, nq);
  imp1_ = imp_;
  ick_ = imp_;
  ick_.dFdq_v = VectorXd::Zero(nq);
  v1_ = VectorXd::Zero(nq);
  q1_ = VectorXd::Zero(nq);
}

bool Integrator::eval(System& sys, double t, const VectorXd& y, VectorXd& f) {
  ++stats_.evaluations;
  qtmp_ = y.head(nq_);
  vtmp_ = y.tail(nq_);
  if (!sys.acceleration(t, qtmp_, vtmp_, a_)) return false;
  f.head(nq_) = vtmp_;
  f.tail(nq_) = a_;
  return true;
}

namespace {
bool finite(const VectorXd& x) { return x.allFinite(); }
}  // namespace

StepStatus Integrator::step(System& sys, double t, double h, VectorXd& q, VectorXd& v) {
  switch (o_.method) {
    case Method::kExplicitEuler: {
      ++stats_.evaluations;
      if (!sys.acceleration(t, q, v, a_)) return StepStatus::kEvalFailed;
      q += h * v;
      v += h * a_;
      break;
    }
    case Method::kSemiImplicitEuler: {
      ++stats_.evaluations;
      if (!sys.acceleration(t, q, v, a_)) return StepStatus::kEvalFailed;
      v += h * a_;
      q += h * v;
      break;
    }
    case Method::kImplicitVelocity: {
      ++stats_.evaluations;
      if (!sys.implicit_terms(t, q, v, imp_)) return StepStatus::kEvalFailed;
      // Linearized backward Euler in v: (M − h D_v − h² D_q) Δv = h (F + h D_q v).
      A_ = imp_.M - h * imp_.dFdv - (h * h) * imp_.dFdq;
      dv_.noalias() = imp_.dFdq * v;
      dv_ = h * (imp_.F + h * dv_);
      lu_.compute(A_);
      vtmp_ = lu_.solve(dv_);
      v += vtmp_;
      q += h * v;
      break;
    }
    case Method::kImplicitContact: {
      const StepStatus s = step_implicit_contact(sys, t, h, q, v);
      if (s != StepStatus::kOk) return s;
      break;
    }
    case Method::kRK4: {
      y_.head(nq_) = q;
      y_.tail(nq_) = v;
      if (!eval(sys, t, y_, k_[0])) return StepStatus::kEvalFailed;
      tmp_ = y_ + 0.5 * h * k_[0];
      if (!eval(sys, t + 0.5 * h, tmp_, k_[1])) return StepStatus::kEvalFailed;
      tmp_ = y_ + 0.5 * h * k_[1];
      if (!eval(sys, t + 0.5 * h, tmp_, k_[2])) return StepStatus::kEvalFailed;
      tmp_ = y_ + h * k_[2];
      if (!eval(sys, t + h, tmp_, k_[3])) return StepStatus::kEvalFailed;
      y_ += (h / 6.0) * (k_[0] + 2.0 * k_[1] + 2.0 * k_[2] + k_[3]);
      q = y_.head(nq_);
      v = y_.tail(nq_);
      break;
    }
    case Method::kDormandPrince45: {
      y_.head(nq_) = q;
      y_.tail(nq_) = v;
      fsal_valid_ = false;
      double err = 0.0;
      const StepStatus s = step_dopri(sys, t, h, err);
      if (s != StepStatus::kOk) return s;
      q = y_new_.head(nq_);
      v = y_new_.tail(nq_);
      break;
    }
  }
  ++stats_.steps;
  stats_.h_last = h;
  return (finite(q) && finite(v)) ? StepStatus::kOk : StepStatus::kNonFinite;
}

// The θ-trapezoid with Newton corrections (integrators.hpp). Buffers: ick_ at (q₀, v₀) — its M,
// F are needed by every correction —, imp1_ at the iterate, v1_ the iterate, q1_ its position,
// dv_ the residual / correction; slu_ the factored Jacobian M − θh (D_v + θh D_q), kept across
// steps (jacobian_age) with the contact signature sig_slu_ it was made with. No allocation.
StepStatus Integrator::step_implicit_contact(System& sys, double t, double h, VectorXd& q,
                                             VectorXd& v) {
  const double th = o_.theta, a = th * h;  // and θ²h² = a · θh
  const bool always = o_.jacobian_age == 0;  // a fresh Jacobian at every evaluation
  // The kept factorization expires after jacobian_age steps, or when h changed — by more than
  // rounding: a caller stepping to t + period gets h = (t + period) − t, which differs from the
  // period in its last bits from one step to the next; that must not refresh the Jacobian (it
  // did, at random steps: the same run then took another path within the Newton tolerance
  // depending on how the caller spelled its times).
  if (always || std::abs(h - h_slu_) > 1e-9 * h || ++jac_age_ > o_.jacobian_age) slu_valid_ = false;
  // Every evaluation wants only M − θh (D_v + θh D_q) (ImplicitTerms::dq_in_dv); the start's also
  // D_q v for the predictor and M(q₀) for every correction.
  ick_.dq_in_dv = imp1_.dq_in_dv = a;
  imp1_.with_mass = false;
  ick_.check_mass = imp1_.check_mass = false;  // a singular M shows as a zero pivot of slu_
  // Evaluates (q, v) into `out`, with the Jacobian when asked or when the contacts' branches
  // differ from those of the kept factorization (then twice: the first without it).
  auto evaluate = [&](double te, const VectorXd& qe, const VectorXd& ve, ImplicitTerms& out, bool fresh) {
    ++stats_.evaluations;
    out.with_jacobian = fresh;
    if (!sys.implicit_terms(te, qe, ve, out)) return false;
    if (fresh || out.signature == sig_slu_) return true;
    ++stats_.evaluations;
    out.with_jacobian = true;
    return sys.implicit_terms(te, qe, ve, out);
  };
  auto factor = [&](const ImplicitTerms& at) {
    ++stats_.jacobians;
    slu_.matrix() = ick_.M - a * at.dFdv;  // dFdv holds ∂F/∂v + θh ∂F/∂q (dq_in_dv)
    slu_valid_ = slu_.factor(at.n_diag);
    sig_slu_ = at.signature;
    h_slu_ = h;
    jac_age_ = 0;
    return slu_valid_;
  };
  if (!evaluate(t, q, v, ick_, !slu_valid_)) return StepStatus::kEvalFailed;
  if (ick_.with_jacobian && !factor(ick_)) return StepStatus::kNonFinite;
  // Predictor: linearized at the start of the step, (M − θh D_v − θ²h² D_q) Δv = h (F + θh D_q v)
  // (with a kept Jacobian: from a recent step, the same contact branches).
  dv_ = h * (ick_.F + a * ick_.dFdq_v);
  slu_.solve(dv_);
  v1_ = v + dv_;
  const double tol = o_.newton_tol;
  imp1_.v_start = &v;
  bool converged = o_.newton_iterations == 0;
  StepStatus status = StepStatus::kOk;
  for (int it = 0; it < o_.newton_iterations; ++it) {
    q1_ = q + ((1 - th) * h) * v + a * v1_;
    if (!evaluate(t + h, q1_, v1_, imp1_, always)) {
      status = StepStatus::kEvalFailed;
      break;
    }
    // Residual G(v₁) = M₀ (v₁ − v₀) − h [(1−θ) F₀ + θ F₁]; Jacobian M₀ − θh D_v − θ²h² D_q, fresh
    // at (q₁, v₁) when evaluated there, else the kept one (same contact branches).
    vtmp_ = v1_ - v;
    dv_.noalias() = ick_.M * vtmp_;
    dv_ -= ((1 - th) * h) * ick_.F + a * imp1_.F;
    if (imp1_.with_jacobian && !factor(imp1_)) {
      status = StepStatus::kNonFinite;
      break;
    }
    slu_.solve(dv_);
    v1_ -= dv_;
    if (!v1_.allFinite()) break;
    if (dv_.lpNorm<Eigen::Infinity>() <= tol * (1.0 + v1_.lpNorm<Eigen::Infinity>())) {
      converged = true;
      break;
    }
  }
  imp1_.v_start = nullptr;
  if (status != StepStatus::kOk) return status;
  if (!converged) ++stats_.newton_unconverged;
  q += ((1 - th) * h) * v + a * v1_;
  v = v1_;
  return StepStatus::kOk;
}

// Dormand–Prince 5(4) with FSAL: y_ holds the start state; y_new_ the 5th-order result; err the
// scaled RMS error estimate (accept when <= 1).
StepStatus Integrator::step_dopri(System& sys, double t, double h, double& err) {
  static constexpr double c2 = 1.0 / 5, c3 = 3.0 / 10, c4 = 4.0 / 5, c5 = 8.0 / 9;
  static constexpr double a21 = 1.0 / 5;
  static constexpr double a31 = 3.0 / 40, a32 = 9.0 / 40;
  static constexpr double a41 = 44.0 / 45, a42 = -56.0 / 15, a43 = 32.0 / 9;
  static constexpr double a51 = 19372.0 / 6561, a52 = -25360.0 / 2187, a53 = 64448.0 / 6561,
                          a54 = -212.0 / 729;
  static constexpr double a61 = 9017.0 / 3168, a62 = -355.0 / 33, a63 = 46732.0 / 5247,
                          a64 = 49.0 / 176, a65 = -5103.0 / 18656;
  static constexpr double b1 = 35.0 / 384, b3 = 500.0 / 1113, b4 = 125.0 / 192,
                          b5 = -2187.0 / 6784, b6 = 11.0 / 84;
  static constexpr double e1 = 71.0 / 57600, e3 = -71.0 / 16695, e4 = 71.0 / 1920,
                          e5 = -17253.0 / 339200, e6 = 22.0 / 525, e7 = -1.0 / 40;
  if (!fsal_valid_) {
    if (!eval(sys, t, y_, k_[0])) return StepStatus::kEvalFailed;
  }
  tmp_ = y_ + h * a21 * k_[0];
  if (!eval(sys, t + c2 * h, tmp_, k_[1])) return StepStatus::kEvalFailed;
  tmp_ = y_ + h * (a31 * k_[0] + a32 * k_[1]);
  if (!eval(sys, t + c3 * h, tmp_, k_[2])) return StepStatus::kEvalFailed;
  tmp_ = y_ + h * (a41 * k_[0] + a42 * k_[1] + a43 * k_[2]);
  if (!eval(sys, t + c4 * h, tmp_, k_[3])) return StepStatus::kEvalFailed;
  tmp_ = y_ + h * (a51 * k_[0] + a52 * k_[1] + a53 * k_[2] + a54 * k_[3]);
  if (!eval(sys, t + c5 * h, tmp_, k_[4])) return StepStatus::kEvalFailed;
  tmp_ = y_ + h * (a61 * k_[0] + a62 * k_[1] + a63 * k_[2] + a64 * k_[3] + a65 * k_[4]);
  if (!eval(sys, t + h, tmp_, k_[5])) return StepStatus::kEvalFailed;
  y_new_ = y_ + h * (b1 * k_[0] + b3 * k_[2] + b4 * k_[3] + b5 * k_[4] + b6 * k_[5]);
  if (!eval(sys, t + h, y_new_, k_[6])) return StepStatus::kEvalFailed;
  tmp_ = h * (e1 * k_[0] + e3 * k_[2] + e4 * k_[3] + e5 * k_[4] + e6 * k_[5] + e7 * k_[6]);
  double sum = 0.0;
  const Eigen::Index n = y_.size();
  for (Eigen::Index i = 0; i < n; ++i) {
    const double sc = o_.atol + o_.rtol * std::max(std::abs(y_(i)), std::abs(y_new_(i)));
    const double r = tmp_(i) / sc;
    sum += r * r;
  }
  err = std::sqrt(sum / static_cast<double>(n));
  if (!std::isfinite(err)) err = 1e10;
  return StepStatus::kOk;
}

StepStatus Integrator::advance(System& sys, double& t, double t_end, VectorXd& q, VectorXd& v) {
  if (!is_adaptive(o_.method)) {
    while (t_end - t > 1e-12 * std::max(1.0, std::abs(t_end))) {
      const double h = std::min(o_.h, t_end - t);
      const StepStatus s = step(sys, t, h, q, v);
      if (s != StepStatus::kOk) return s;
      t += h;
    }
    t = t_end;
    return StepStatus::kOk;
  }
  // Adaptive: standard controller h_new = h · clamp(0.9 err^(−1/5), 0.2, 5).
  y_.head(nq_) = q;
  y_.tail(nq_) = v;
  fsal_valid_ = false;
  while (t_end - t > 1e-12 * std::max(1.0, std::abs(t_end))) {
    double h = std::min({h_adapt_, o_.h_max, t_end - t});
    const bool clipped = h < h_adapt_;
    double err = 0.0;
    const StepStatus s = step_dopri(sys, t, h, err);
    if (s != StepStatus::kOk) return s;
    const double fac = std::clamp(0.9 * std::pow(std::max(err, 1e-10), -0.2), 0.2, 5.0);
    if (err <= 1.0) {
      t += h;
      y_ = y_new_;
      k_[0] = k_[6];  // FSAL
      fsal_valid_ = true;
      ++stats_.steps;
      stats_.h_last = h;
      if (!y_.allFinite()) return StepStatus::kNonFinite;
      if (!clipped) h_adapt_ = std::min(h * fac, o_.h_max);
    } else {
      ++stats_.rejected;
      fsal_valid_ = true;  // k_[0] still belongs to y_
      h_adapt_ = h * std::min(fac, 1.0);
      if (h_adapt_ < o_.h_min) {
        q = y_.head(nq_);
        v = y_.tail(nq_);
        return StepStatus::kStepTooSmall;
      }
    }
  }
  t = t_end;
  q = y_.head(nq_);
  v = y_.tail(nq_);
  return StepStatus::kOk;
}

}  // namespace pedalwave::model
