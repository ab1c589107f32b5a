// Time integration of second-order systems q̈ = a(t, q, v), v = q̇ (model-spec.md §10).
// Integrators own their workspace (sized once); advance() allocates nothing and reports, never
// throws: a NaN/Inf or a singular mass matrix ends the advance with a status, not garbage.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include <Eigen/Core>
#include <Eigen/LU>

namespace pedalwave::model {

using Eigen::MatrixXd;
using Eigen::VectorXd;

// What a velocity-implicit step needs: M a = F(q, v) with the Jacobians of F.
struct ImplicitTerms {
  MatrixXd M;    // mass matrix at q, nq×nq
  VectorXd F;    // generalized force F(q, v) = B u + Q − bias, (nq)
  MatrixXd dFdq; // ∂F/∂q of the stiff terms (springs, contact stiffness), nq×nq
  MatrixXd dFdv; // ∂F/∂v of the stiff terms (contact/joint damping, friction), nq×nq
  // The velocity at the start of the step when (q, v) is a Newton iterate (implicit_contact), else
  // null. A contact sliding at the iterate that started the step inside the stick band or sliding
  // the other way crossed the band within the step: its friction slope in dFdv is then the stick
  // band's (the slip branch's slope 0 lets Newton jump from one slip direction to the other and
  // back, never entering the band). Only the Jacobian changes, never F.
  const VectorXd* v_start = nullptr;
  // The number of trailing coordinates whose block of M, dFdq and dFdv is diagonal (the plant's
  // motor angles β, N−1 of them when the joints are flexible; 0: no structure known). The implicit
  // integrators then factor only the leading block's Schur complement (StructuredLU).
  int n_diag = 0;
  // What the caller asks for (set by the caller, kept by implicit_terms): with_mass false leaves
  // M untouched (implicit_contact's corrections use M at the step's start); dq_in_dv = s > 0 leaves
  // dFdq untouched and writes ∂F/∂v + s ∂F/∂q into dFdv (all a caller needs that only forms
  // M − θh (∂F/∂v + θh ∂F/∂q)).
  // With dq_in_dv > 0 and dFdq_v sized nq, also dFdq_v = ∂F/∂q · v at the evaluated v (what the
  // predictor's right-hand side needs of ∂F/∂q); left empty, it is not computed.
  // with_jacobian false leaves dFdq and dFdv untouched (F, M and dFdq_v as asked): what
  // implicit_contact's evaluations need while they reuse a factored Jacobian (jacobian_age).
  // check_mass false assembles M without its Cholesky factorization (mass_valid not checked: the
  // caller's own factorization reports a singular matrix).
  bool with_mass = true;
  bool with_jacobian = true;
  bool check_mass = true;
  // Written by the plant: a hash of the contacts carrying force and each one's friction branch
  // (stick band or sliding either way); equal signatures, the same branches of the force law.
  std::uint64_t signature = 0;
  double dq_in_dv = 0.0;
  VectorXd dFdq_v = VectorXd();
};

// LU solve of A x = b for an n×n A whose trailing nd×nd block A22 is diagonal (the motor block,
// ImplicitTerms::n_diag): with A = [A11, A12; A21, A22],
//   S = A11 − A12 A22⁻¹ A21  (n1×n1, n1 = n − nd), factored by LU with partial pivoting,
//   x1 = S⁻¹ (b1 − A12 A22⁻¹ b2),  x2 = A22⁻¹ (b2 − A21 x1).
// The same x as a dense LU of A to rounding (tests/model/structured_solve_test.cpp); at N = 6
// (n = 13, nd = 5) an 8×8 factorization instead of a 13×13 one. nd = 0: a plain dense LU. Plain
// loops (Eigen's blocked LU costs more than the arithmetic at these sizes); sized once, allocates
// nothing. No pivoting within A22: its diagonal must be nonzero (M's motor inertias n² I_r plus
// the positive PD/spring terms make it so for the plant).
class StructuredLU {
 public:
  explicit StructuredLU(int n);
  // The matrix to factor (n×n): fill it, then factor(). factor() overwrites it.
  MatrixXd& matrix() { return A_; }
  // Factors matrix() with its trailing nd×nd block taken as diagonal (its off-diagonal entries
  // are not read); false on a zero or non-finite pivot (solve() then gives non-finite x).
  bool factor(int nd);
  // b ← A⁻¹ b, (n).
  void solve(Eigen::Ref<VectorXd> b) const;

 private:
  MatrixXd A_;            // S's LU in the leading n1×n1 block, A12 A22⁻¹ beside it, A21 below
  VectorXd d_inv_;        // A22⁻¹'s diagonal, (nd)
  VectorXd u_inv_;        // 1 / U's diagonal, (n1)
  Eigen::VectorXi piv_;   // row k swapped with row piv_(k) at step k, (n1)
  int n_ = 0, nd_ = 0;
};

class System {
 public:
  virtual ~System() = default;
  virtual int nq() const = 0;
  // a = q̈ at (t, q, v); false if it cannot be evaluated (singular mass matrix).
  virtual bool acceleration(double t, const VectorXd& q, const VectorXd& v, VectorXd& a) = 0;
  // Fills out (already sized nq) for velocity-implicit schemes; false if unsupported/failed.
  // Honours out's requests (with_mass, dq_in_dv, dFdq_v): implicit_contact relies on them.
  virtual bool implicit_terms(double t, const VectorXd& q, const VectorXd& v, ImplicitTerms& out) {
    (void)t, (void)q, (void)v, (void)out;
    return false;
  }
};

enum class Method : std::uint8_t {
  kExplicitEuler,      // q += h v; v += h a(q, v)                       order 1, explicit
  kSemiImplicitEuler,  // v += h a(q, v); q += h v_new                   order 1, symplectic
  kImplicitVelocity,   // (M − h ∂F/∂v − h² ∂F/∂q) Δv = h (F + h ∂F/∂q v) order 1, linearly implicit
  kRK4,                // classic Runge–Kutta                             order 4
  kDormandPrince45,    // embedded RK 5(4), adaptive step, error control  order 5
  kImplicitContact,    // θ-trapezoid, Newton on contact/friction   order 2 at θ = ½, else 1; A-stable
};
// implicit_contact: the trapezoidal family in velocity form, its one implicit stage solved for
// the contact normal forces and the regularized friction at the END of the step (not linearized
// once at its start, as implicit_velocity does):
//   G(v₁) = M(q₀)(v₁ − v₀) − h [(1−θ) F(q₀, v₀) + θ F(q₁, v₁)] = 0,  q₁ = q₀ + h((1−θ) v₀ + θ v₁),
// predictor = the linearization at the start, (M − θh D_v − θ²h² D_q) Δv = h (F + θh D_q v), then
// up to IntegratorOptions::newton_iterations corrections with the Jacobian
// M − θh ∂F/∂v − θ²h² ∂F/∂q re-evaluated at (q₁, v₁): each correction re-detects the contacts
// and re-selects the friction branch (stick band |v_t| < v_s or saturated), so the kink of the
// regularized law and the clamp f_N ≥ 0 are resolved, not extrapolated through. θ = 0.55 (the
// default, IntegratorOptions::theta) damps the stiffest modes (|R(∞)| = (1−θ)/θ = 0.82) at a
// first-order error term of size (θ − ½) h (θ = ½: order 2, stiff modes undamped). ∂F/∂q, ∂F/∂v
// are the System's stiff terms (the plant: springs, PD, contact k and d, friction slope; what they
// neglect is listed at Plant::implicit_terms). M is frozen at q₀.
// The corrections stop as soon as one moves v₁ by at most newton_tol (1 + |v₁|∞) in the max norm
// (default 1e-2, at most 3 corrections): on the shipped walking scenes at 1 ms most steps stop
// after one correction (2.02–2.06 evaluations per step), the few where a contact or a friction
// branch changes take two or three; two corrections on every step (the earlier default) are both
// costlier and less accurate on the stairs (README "An accurate step at 1 ms"). The linear solves
// eliminate the diagonal motor block first (StructuredLU, ImplicitTerms::n_diag).
// The Jacobian is kept (IntegratorOptions::jacobian_age, default 5): a factored
// M − θh (D_v + θh D_q) serves the predictors and corrections of the next steps as long as the
// contacts carrying force and their friction branches (ImplicitTerms::signature) are those it was
// made with, for at most jacobian_age steps and the same h; the evaluations in between skip the
// contact Jacobians (ImplicitTerms::with_jacobian). An evaluation whose branches differ is repeated
// with the Jacobian, which is factored and kept from then on — so every kink of the force law is
// crossed by a Newton correction with a fresh Jacobian, as before. jacobian_age = 0: a fresh
// Jacobian at every evaluation (the scheme before; the same results bit for bit).
std::string_view to_string(Method m);
// Parses "euler", "semi_implicit_euler", "implicit_velocity", "rk4", "dopri45",
// "implicit_contact"; throws
// std::invalid_argument listing the accepted names.
Method parse_method(std::string_view name);
bool is_adaptive(Method m);

struct IntegratorOptions {
  Method method = Method::kRK4;
  double h = 1e-4;       // fixed step, or initial step for adaptive methods [s]
  double rtol = 1e-6;    // adaptive: relative tolerance [-]
  double atol = 1e-8;    // adaptive: absolute tolerance [SI of each state]
  double h_min = 1e-10;  // adaptive: smallest step before giving up [s]
  double h_max = 1e-2;   // adaptive: largest step [s]
  int newton_iterations = 3;  // implicit_contact: most Newton corrections per step (0 = linearized) [-]
  double theta = 0.55;        // implicit_contact: implicitness θ ∈ [0.5, 1] (0.5: trapezoid,
                              // order 2, undamped stiff modes; 1: backward Euler) [-]
  double newton_tol = 1e-2;  // implicit_contact: the corrections stop once |Δv|∞ ≤ newton_tol (1 + |v₁|∞) [-]
  int jacobian_age = 5;  // implicit_contact: a factored Jacobian serves the evaluations of at most this
                         // many later steps while the contact branches stay (0: fresh at every one) [-]
};
// Throws std::invalid_argument naming the option and the value.
void validate(const IntegratorOptions& o);

struct IntegratorStats {
  std::uint64_t steps = 0;        // accepted steps
  std::uint64_t rejected = 0;     // rejected (adaptive) steps
  std::uint64_t evaluations = 0;  // acceleration / implicit-term evaluations
  std::uint64_t newton_unconverged = 0;  // implicit_contact steps that used every correction
                                         // without reaching |Δv|∞ ≤ newton_tol (1 + |v|∞)
  std::uint64_t jacobians = 0;  // implicit_contact: Jacobians evaluated and factored
  double h_last = 0.0;            // last step size [s]
};

enum class StepStatus : std::uint8_t { kOk = 0, kEvalFailed, kNonFinite, kStepTooSmall };
std::string_view to_string(StepStatus s);

class Integrator {
 public:
  Integrator(int nq, const IntegratorOptions& o);

  // Advance (q, v) from t to t_end. Fixed-step methods take steps of h (the last one shortened to
  // land on t_end); adaptive ones keep their step size between calls. On failure t, q, v hold the
  // last good state.
  StepStatus advance(System& sys, double& t, double t_end, VectorXd& q, VectorXd& v);
  // One step of size h (fixed-step methods) — the unit the stability/convergence tests use.
  StepStatus step(System& sys, double t, double h, VectorXd& q, VectorXd& v);

  const IntegratorStats& stats() const { return stats_; }
  const IntegratorOptions& options() const { return o_; }
  void reset_stats() { stats_ = {}; }

 private:
  bool eval(System& sys, double t, const VectorXd& y, VectorXd& f);  // f = [v; a]
  StepStatus step_dopri(System& sys, double t, double h, double& err);

  IntegratorOptions o_;
  int nq_;
  IntegratorStats stats_;
  double h_adapt_;
  bool fsal_valid_ = false;
  VectorXd y_, y_new_, tmp_, a_, qtmp_, vtmp_, dv_;
  VectorXd k_[7];
  StepStatus step_implicit_contact(System& sys, double t, double h, VectorXd& q, VectorXd& v);

  ImplicitTerms imp_;         // implicit_velocity
  ImplicitTerms ick_, imp1_;  // implicit_contact: at (q₀, v₀) and at the iterate (q₁, v₁)
  MatrixXd A_;
  VectorXd v1_, q1_;
  Eigen::PartialPivLU<MatrixXd> lu_;
  StructuredLU slu_;  // implicit_contact's solves
  bool slu_valid_ = false;    // slu_ holds a factored Jacobian for the step h_slu_ …
  double h_slu_ = 0.0;
  int jac_age_ = 0;           // … made jac_age_ steps ago …
  std::uint64_t sig_slu_ = 0; // … with these contact branches (ImplicitTerms::signature)
};

}  // namespace pedalwave::model
