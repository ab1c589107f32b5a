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
};

class System {
 public:
  virtual ~System() = default;
  virtual int nq() const = 0;
  // a = q̈ at (t, q, v); false if it cannot be evaluated (singular mass matrix).
  virtual bool acceleration(double t, const VectorXd& q, const VectorXd& v, VectorXd& a) = 0;
  // Fills out (already sized nq) for velocity-implicit schemes; false if unsupported/failed.
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
  int newton_iterations = 2;  // implicit_contact: Newton corrections per step (0 = linearized) [-]
  double theta = 0.55;        // implicit_contact: implicitness θ ∈ [0.5, 1] (0.5: trapezoid,
                              // order 2, undamped stiff modes; 1: backward Euler) [-]
};
// Throws std::invalid_argument naming the option and the value.
void validate(const IntegratorOptions& o);

struct IntegratorStats {
  std::uint64_t steps = 0;        // accepted steps
  std::uint64_t rejected = 0;     // rejected (adaptive) steps
  std::uint64_t evaluations = 0;  // acceleration / implicit-term evaluations
  std::uint64_t newton_unconverged = 0;  // implicit_contact steps that used every correction
                                         // without reaching |Δv|∞ ≤ 1e-10 (1 + |v|∞): with the
                                         // default 2 corrections nearly all steps (a truncated
                                         // Newton; 4 corrections converge in ~90 % of the steps)
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

  ImplicitTerms imp_, imp1_;  // implicit_contact: at (q₀, v₀) and at the iterate (q₁, v₁)
  MatrixXd A_;
  VectorXd v1_, q1_;
  Eigen::PartialPivLU<MatrixXd> lu_;
};

}  // namespace pedalwave::model
