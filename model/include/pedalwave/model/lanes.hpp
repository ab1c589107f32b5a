// Several members of one scene's plant evaluated at once, one SIMD lane per member: what a sweep
// whose members differ only in their commands (the k_c sweep) needs of the plant, each quantity a
// vector across the members (README "Point 4", the lockstep route). The same terms as
// Plant::implicit_terms without the Jacobian — F, the body block of M, D_q v, the contact
// signature — equal to it to rounding (tests/model/lanes_test.cpp), for the scenes it supports
// (LanePlant::unsupported: segment links, flexible joints, regularized ground friction, boxes,
// healthy actuators without limits or joint friction).
//
// Lane layout: coordinate i of member l at x[i · width + l]. The width is the machine's: 8 with
// AVX-512, 4 with AVX2 (the kernels are compiled for both and chosen at run time); 0 means the
// machine has neither and the caller keeps the scalar Plant.
//
// Sized once at construction; evaluate() allocates nothing.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "pedalwave/model/plant.hpp"

namespace pedalwave::model {

// What LanePlant::evaluate writes, each in lane layout.
struct LaneTerms {
  std::vector<double> F;          // F(q, v) = B u + Q − bias, nq × width
  std::vector<double> Mb;         // the body block of M (nq1 × nq1, column-major) × width, the
                                  // rotors' spin in it; M's other entries are Model::M_spin()'s
  std::vector<double> dFdq_v;     // D_q v with ∂F/∂q's stiff terms (ImplicitTerms::dFdq_v), nq × width
  std::vector<double> D;          // with a Jacobian asked for: ∂F/∂v + a ∂F/∂q (ImplicitTerms::dFdv
                                  // with dq_in_dv = a), nq × nq (column-major) × width; its structural
                                  // zeros are written by make_terms() only
  std::vector<std::uint64_t> signature;  // ImplicitTerms::signature per member, width
};

// The module commands of each member (ActuatorInput; a member with its torque off has all five
// zero), each (N−1) × width in lane layout.
struct LaneInputs {
  std::vector<double> tau, kp, beta_ref, kd, beta_dot_ref;
};

// Members' StructuredLU factors in lane layout (LanePlant::factor, LanePlant::solve).
struct LaneLU {
  int n = 0, nd = 0, width = 0;
  std::vector<double> A;       // StructuredLU::factors(), n × n (column-major) × width
  std::vector<double> d_inv;   // nd × width
  std::vector<double> u_inv;   // (n − nd) × width
  std::vector<int> perm;       // the row swaps as one permutation, (n − nd) × width: row k ← perm[k]
  bool identity = true;        // every lane's perm is the identity (no row swapped)
  // The motor block's part as it was last computed (LanePlant::factor): Z = C A21, (n − nd)² ×
  // width; the entries of D it came from (D(β_j, β_j), D(α_j, β_j), D(β_j, α_j)), 3 nd × width, and
  // a; whether A22's pivots were good (1/0), width.
  std::vector<double> Z, key, motor_ok;
  double key_a = std::numeric_limits<double>::quiet_NaN();
  LaneLU(int n_, int nd_, int width_);
};

class LanePlant {
 public:
  // Why `scene` cannot be evaluated in lanes, or "" when it can.
  static std::string unsupported(const Scene& scene);
  // The lane width this machine runs: 8 (AVX-512 F and DQ), 4 (AVX2 and FMA) or 0 (neither).
  static int machine_width();

  // The constants of `plant` (its boxes already placed). Throws std::invalid_argument when the
  // scene is unsupported or `width` is not one the machine runs (8 or 4, at most machine_width()).
  explicit LanePlant(const Plant& plant, int width = machine_width());
  ~LanePlant();
  LanePlant(const LanePlant&) = delete;
  LanePlant& operator=(const LanePlant&) = delete;

  int width() const { return width_; }
  int nq() const { return nq_; }
  int nq1() const { return nq1_; }
  int joints() const { return joints_; }

  // Buffers of the right sizes (zero).
  LaneTerms make_terms() const;
  LaneInputs make_inputs() const;

  // The terms at (q, v) (nq × width each, lane layout) with the members' commands; Mb and dFdq_v
  // only when with_mass (what a step's start needs; its Newton iterates need neither); D only when
  // jacobian = a > 0, then with v_start (nq × width, or null) the step's
  // start of a Newton iterate (ImplicitTerms::v_start).
  void evaluate(const double* q, const double* v, const LaneInputs& in, bool with_mass, LaneTerms& out,
                double jacobian = 0.0, const double* v_start = nullptr);

  // Each member's M − a D (M: its body block Mb, the rest Model::M_spin(); Mb, D from LaneTerms) factored
  // as StructuredLU::factor would (the same operations, each member's own pivots), into `out` for
  // the members with need[l] (the others' factors stay); ok[l] false where StructuredLU::factor
  // would return false (a zero or non-finite pivot).
  void factor(const std::vector<double>& Mb, const std::vector<double>& D, double a, const char* need,
              LaneLU& out, char* ok);
  // x ← A⁻¹ x for every member at once (x nq × width, lane layout), A each member's factors in lu
  // (StructuredLU::solve's operations in its order, lane by lane).
  void solve(const LaneLU& lu, double* x) const;
  // r = M x − (b F0 + a F1) for every member (M: its body block Mb from a LaneTerms, the rest
  // Model::M_spin()), x, F0, F1, r nq × width: implicit_contact's Newton residual.
  void residual(const std::vector<double>& Mb, const double* x, const double* F0, const double* F1, double b,
                double a, double* r) const;

  struct Constants;  // the plant's constants in the kernels' flat form (lanes.cpp)
  struct Workspace;  // the kernels' per-evaluation arrays (lanes.cpp)

 private:
  int width_ = 0, nq_ = 0, nq1_ = 0, joints_ = 0;
  std::unique_ptr<Constants> c_;
  std::unique_ptr<Workspace> w_;
};

}  // namespace pedalwave::model

namespace pedalwave::model {

// implicit_contact (Integrator::step_implicit_contact: the θ-trapezoid with Newton corrections and
// a kept, factored Jacobian) for every member of a LanePlant at once: the evaluations in lanes,
// each member's Jacobian kept, refreshed and factored as its own Integrator would (its own age,
// contact signature and Newton iteration count), so that a member's step is the scalar one to
// rounding and its IntegratorStats are the scalar ones (tests/model/lanes_test.cpp).
// Sized once at construction; step() allocates nothing.
class LaneStepper {
 public:
  // o.method must be implicit_contact (throws std::invalid_argument otherwise).
  LaneStepper(LanePlant& plant, const Plant& scalar, const IntegratorOptions& o);

  // One step of h from t of every member whose status is kOk (a member that failed stays frozen
  // with its status), q and v in lane layout (nq × width), with the members' commands.
  void step(double t, double h, double* q, double* v, const LaneInputs& in, StepStatus* status);

  const IntegratorStats& stats(int member) const { return stats_[static_cast<size_t>(member)]; }

 private:
  struct Member {
    bool valid = false;
    std::uint64_t sig = 0;
    double h = 0.0;
    int age = 0;
  };
  // The members with need_[l] refactored at `at` (M₀ from the step's start): their Jacobian count,
  // signature, h and age; a failed factorization fails the member.
  void factor(const LaneTerms& at, double a, double h, StepStatus* status);

  LanePlant& plant_;
  IntegratorOptions o_;
  int W_, nq_;
  std::vector<Member> m_;
  LaneLU lu_;  // every member's factors, for the solves in lanes
  std::vector<IntegratorStats> stats_;
  LaneTerms t0_, t1_;  // at the step's start, at the Newton iterate
  std::vector<double> v1_, q1_, r_, tmp_;  // lane layout, nq × width
  std::vector<char> newton_, need_, ok_, converged_;  // per member
};

}  // namespace pedalwave::model
