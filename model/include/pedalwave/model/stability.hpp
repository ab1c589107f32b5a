// Stability limits of the fixed-step integrators for a scene, predicted before a run
// (model-spec.md §10): which effect sets the largest stable step of each explicit method, and a
// message that names it and suggests the fix.
//
// Method. The plant is linearized at a flat pose resting on the ground (static penetration
// δ = m g / (k P) at each of the P = 2N+1 body points; in the air when the scene has no ground):
//   M ẍ + D ẋ + K x = 0,   K = Σ_e K_e,  D = Σ_e D_e   over the effects e below.
// Time scales: ω_max² = the largest eigenvalue of the generalized problem K x = ω² M x, and the
// largest damping rate c_max of D x = c M x (Eigen's GeneralizedSelfAdjointEigenSolver), for all
// effects together and for each alone. Stable steps: the eigenvalues λ of the first-order matrix
// [0 I; −M⁻¹K −M⁻¹D] must lie in the method's stability region after scaling by h:
//   explicit Euler  |1 + hλ| ≤ 1 → h ≤ −2 Re λ / |λ|²  (an undamped mode is unstable at every h;
//                                  an overdamped one, λ ≈ −c, gives h < 2/c: 2 n² I_r / K_D)
//   RK4             |R₄(hλ)| ≤ 1 (real-axis limit hc < 2.785, imaginary-axis limit ωh < 2√2)
//   Dormand–Prince  |R₅(hλ)| ≤ 1 with R₅ = Σ_{k≤5} z^k/k! + z⁶/600 (real-axis limit ≈ 3.31);
//                   adaptive: this is the step its error control ends up near when stiff
//   semi-implicit Euler: spectral radius of its amplification matrix ≤ 1 (per mode with damping
//                   rate c and frequency ω: hc < 2 and h²ω² + 2hc < 4; ωh < 2 when undamped)
//   implicit_velocity: linearized backward Euler, A-stable: no step limit from these effects.
//   implicit_contact: θ-trapezoid (θ ≥ ½) with Newton corrections, A-stable: none either.
// The binding mode is attributed to the effect with the largest share of its stability budget
// (h²ω_e²/4 + h c_e/2 with ω_e², c_e the effect's Rayleigh quotients on the mode shape).
//
// What it does not cover: Coriolis and gravity terms (small at rest), the stair's box (same k, d
// as the ground), torque limits (they only lower the effective gains), exact Coulomb friction
// (infinite slope at v_t = 0: no linear limit, it chatters with velocity jumps ≈ μ g h and is
// reported as a note). Contact onset, larger penetrations and other poses change the numbers
// somewhat: check() warns within 20 % of a limit.
#pragma once

#include <array>
#include <cstdint>
#include <limits>
#include <string>

#include "pedalwave/model/integrators.hpp"
#include "pedalwave/model/scene.hpp"

namespace pedalwave::model {

// The joint controller's gains as the module applies them (model-spec.md §7, P-33).
struct ControlGains {
  double K_p = 30.0;  // PD stiffness on the motor angle [N·m/rad]
  double K_D = 15.0;  // PD damping on the motor rate [N·m·s/rad]
};

// The effects the linearization separates (model-spec.md §10).
enum class Effect : std::uint8_t {
  kMotorPd,           // PD (K_p, K_D) and motor viscous friction on the reflected inertia n² I_r
  kSpring,            // SEA springs K against the link inertia (flexible joints only)
  kContactStiffness,  // ground stiffness k against the link masses
  kContactDamping,    // ground damping d against the link masses
  kFriction,          // friction slope: μ f_N / v_s (regularized, tanh), k_t and its damping
                      // (stick-slip); exact Coulomb has none (see StabilityReport::notes)
};
inline constexpr int kEffectCount = 5;
// Short name: "motor_pd", "spring", "contact_stiffness", "contact_damping", "friction".
const char* to_string(Effect e);

inline constexpr double kNoLimit = std::numeric_limits<double>::infinity();

// Time scales of one effect alone (with the full mass matrix).
struct EffectScale {
  Effect effect = Effect::kMotorPd;
  bool present = false;     // the scene has this effect (with nonzero coefficients)
  double omega_max = 0.0;   // highest undamped frequency √(eig(K_e, M)) [rad/s]
  double rate_max = 0.0;    // highest damping rate eig(D_e, M) [1/s]
  double h_euler = kNoLimit;          // largest stable step with this effect alone [s]
  double h_semi_implicit = kNoLimit;  // [s]
  double h_rk4 = kNoLimit;            // [s]
  double h_dopri = kNoLimit;          // [s]
};

// The largest stable fixed step of one method with all effects together.
struct MethodLimit {
  Method method = Method::kExplicitEuler;
  double h_max = kNoLimit;   // largest stable step [s]; 0 = unstable at every step (explicit
                             // Euler with an undamped mode); kNoLimit = none (implicit_velocity)
  Effect dominant = Effect::kMotorPd;  // effect that sets h_max (meaningless when kNoLimit)
  double mode_omega = 0.0;   // |λ| of the binding mode [rad/s]
  double mode_damping = 0.0; // its damping ratio −Re λ / |λ| [-]
  // Regularized friction's slope μ f_N / v_s only exists inside the stick band |v_t| < v_s: above
  // a friction-set h_max an explicit scheme chatters there with bounded amplitude (≈ v_s) instead
  // of blowing up. h_blowup is the limit with friction left out — where runs do diverge — and
  // equals h_max when friction does not set it.
  double h_blowup = kNoLimit;            // [s]
  Effect blowup_dominant = Effect::kMotorPd;  // effect that sets h_blowup
};

struct StabilityReport {
  int nq = 0;                       // coordinates of the linearized model [-]
  double omega_max = 0.0;           // highest undamped frequency, all stiffnesses [rad/s]
  double rate_max = 0.0;            // highest damping rate, all dampings [1/s]
  double motor_inertia = 0.0;       // reflected rotor inertia n² I_r [kg·m²] (0 when rigid)
  double motor_time_scale = 0.0;    // n² I_r / (K_D + b_m) [s] (0 when rigid or K_D = 0)
  double normal_force = 0.0;        // f_N per body point at rest, m g / P [N] (0: no ground)
  std::array<EffectScale, kEffectCount> effects{};  // indexed by Effect
  MethodLimit euler{Method::kExplicitEuler};
  MethodLimit semi_implicit{Method::kSemiImplicitEuler};
  MethodLimit rk4{Method::kRK4};
  MethodLimit dopri{Method::kDormandPrince45};
  double euler_undamped_omega = 0.0;  // highest frequency of an undamped mode [rad/s]: explicit
                                      // Euler amplifies it by √(1 + h²ω²) per step at any h
  std::string notes;                // caveats (exact Coulomb friction, ...), may be empty

  // The limit of `m` (implicit_velocity: an entry with kNoLimit).
  MethodLimit limit(Method m) const;
};

// Predicts the stability limits of `scene` under module-side PD gains `gains` (use K_p = K_D = 0
// for a passive robot). Throws std::invalid_argument if the scene is invalid (model::validate).
// Cost: a few eigen-decompositions of size 2·nq (milliseconds for N = 6, ~1 s for N = 50).
StabilityReport predict_stability(const Scene& scene, const ControlGains& gains);

// Amplitude growth of the worst linear mode over `duration` [s] with step h: max |ρ|^(duration/h)
// with ρ the per-step amplification (1 when stable or for implicit_velocity). Recomputes the
// linearization.
double growth_factor(const Scene& scene, const ControlGains& gains, Method method, double h,
                     double duration);

// One line explaining a step choice against the prediction, e.g.
//   "h = 2e-3 s is above explicit Euler's stability limit 4.33e-4 s set by the motor damping
//    K_D / (n² I_r) = 4.62e3 1/s: use h ≤ 4e-4 s, or implicit_velocity"
// For a stable choice it says so and gives the margin.
std::string stability_message(const StabilityReport& report, Method method, double h);

// What a tool should do before a run.
enum class CheckLevel : std::uint8_t {
  kOk,       // fixed step below 0.8 × the limit (or an implicit/adaptive method)
  kWarning,  // within 0.8 … 1 × the limit; above a friction-set limit but below h_blowup
             // (bounded chatter); or above the limit but growing less than ×10 over the run
  kError,    // above the limit (and h_blowup), with predicted growth ≥ ×10 over the run: refuse
};
const char* to_string(CheckLevel l);

struct StabilityCheck {
  CheckLevel level = CheckLevel::kOk;
  std::string message;        // stability_message(...) plus the growth over the run if relevant
  double h_limit = kNoLimit;  // limit of the scene's method [s]
  double growth = 1.0;        // predicted amplitude growth over the run [-]
  StabilityReport report;
};

// Checks the scene's own integrator (scene.integrator) over scene.duration.
StabilityCheck check(const Scene& scene, const ControlGains& gains);
// Same for another integrator and duration [s].
StabilityCheck check(const Scene& scene, const ControlGains& gains, const IntegratorOptions& integ,
                     double duration);

}  // namespace pedalwave::model
