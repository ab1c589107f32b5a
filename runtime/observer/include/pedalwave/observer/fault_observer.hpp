// The onboard model observer: fault detection and isolation (issue 7).
//
// Every cycle it compares the motor-side measurements with the onboard model and turns
// disagreement into named, isolated, latched faults (runtime::FaultClass) with evidence.
//
// 1. Motor-side momentum residual (De Luca's generalized-momentum observer), one per joint, on the
//    last N−1 rows of model-spec.md §4:
//        J β̈_j − n I_r θ̈_j + K_j (β_j − α_j) = u_j − b_m β̇_j,     J = n² I_r
//    p_j = J β̇_j is the motor momentum. Contact forces never act on these rows, so the residual
//    is terrain-independent. The coupling n I_r θ̈_j (θ_j the stator link's absolute angle, not
//    measured) is left as a bounded disturbance: it is 1/n of the rotor spin term's size
//    (|n I_r θ̈| ≈ 1.3e-5 kg·m² · |θ̈|, ≤ 1e-3 N·m for |θ̈| ≤ 80 rad/s²; README).
//    Applied torque: the host knows the module's law (interface/io.hpp, Command) and the measured β,
//    β̇; with module-side PD the module applies u(t) = τ + k_p(β_ref − β(t)) + k_d(β̇_ref − β̇(t))
//    continuously between samples (ASSUMPTION: the module runs its law on the same β it reports,
//    much faster than the host rate, with the last command held, clamped to ±u_max when configured).
//    Discrete time, over one period [t_k, t_k+1] with the command of cycle k held (ZOH):
//        ∫u dt = T(τ + k_p β_ref + k_d β̇_ref) − k_p T (β_k + β_k+1)/2 − k_d (β_k+1 − β_k)
//    (the k_d term is exact; the k_p term trapezoidal, error k_p T³ β̈/12), ∫K(β−α) dt trapezoidal
//    on the measured deflection, ∫b_m β̇ dt = b_m (β_k+1 − β_k) exact. Unexplained impulse
//        e_k = J (β̇_k+1 − β̇_k) − ∫(u − K·deflection − b_m β̇) dt          [N·m·s]
//    and the residual is the exact ZOH discretization of ṙ = K_O (e/T − r):
//        r_k+1 = r_k + (1 − e^{−K_O T}) (e_k/T − r_k)                       [N·m]
//    i.e. r is the first-order low-pass (bandwidth K_O) of the unexplained motor torque.
//    Fault signatures (r ≈ θ·x with x = [u, K·deflection, β̇, 1] filtered the same way):
//        actuator gain g:          r = (g − 1) u
//        motor friction +Δb:       r = −Δb β̇
//        deflection scale s:       r = (1 − 1/s) K·deflection
//        spring stiffness × s_K:   r = (1 − s_K) K·deflection     (named broken when ≥ spring_broken)
//        deflection bias δ:        r = K δ
//    After |r| crosses r_threshold, a window of t_classify is least-squares fitted with all four
//    regressors; the largest contribution |θ_i|·rms(x_i) names the class (between K·deflection
//    and the constant — deflection scale / spring against bias — a fit on those two alone decides:
//    after a bias the four are dependent up to J β̈; README §1).
// 2. Sensor and data checks (per joint, before the residual; a joint failing them is not
//    integrated): non-finite or out-of-range values (kImplausible); kStatusMissing for
//    missing_cycles in a row or a whole frame frozen (kModuleSilent); stale / out-of-order flags
//    or a repeated/backward seq (kStaleData); bit-identical β (or deflection) for hold_cycles while
//    the motor is commanded to (or does) move (kEncoderStuck / kDeflectionStuck); the kinematic
//    consistency c = β_k+1 − β_k − T(β̇_k + β̇_k+1)/2: one isolated spike (kEncoderJump) or repeated
//    spikes (kEncoderNoise); the module law's demand beyond ±u_max (or the module's
//    kStatusSaturated) for a persistent fraction of the time (kSaturation).
// 3. Link side (BodyModel): α = β − deflection is measured; θ_N, p_x, p_z and rates are not. They
//    are PREDICTED by the onboard plant model driven by the measured joint angles over the nominal
//    terrain (body rows of §4 with contact, implicit step), and the external joint torques are
//    ESTIMATED from the α rows: τ_ext = M_α q̈ + c_α + G_α − K·deflection, q̈ from the filtered
//    measured α̈, β̈ and the predicted body accelerations.
//
// Faults latch (per joint, the first class found) until reset(). A joint with a latched sensor or
// data fault is no longer classified by its residual (its residual is then meaningless).
// observe() allocates nothing, locks nothing, throws nothing (sized in the constructor).
#pragma once

#include <array>
#include <cstdint>
#include <memory>

#include "pedalwave/interface/io.hpp"
#include "pedalwave/model/plant.hpp"
#include "pedalwave/interface/sample.hpp"

namespace pedalwave::observer {

using drivers::kMaxJoints;
using runtime::FaultClass;
using runtime::Severity;

inline constexpr std::size_t kFaultClasses = static_cast<std::size_t>(FaultClass::kCount);

struct ObserverParams {
  // ---- Robot and module (onboard model) ----
  model::Params robot = model::paper_params();  // K, n, I_r, link parameters [SI]
  double period = 1e-3;         // nominal cycle period T [s]
  double motor_viscous = 0.0;   // known nominal motor friction b_m [N·m·s/rad]
  double u_max = 0.0;           // module torque limit |u| ≤ u_max [N·m]; 0 = none
  // ---- Momentum residual ----
  double settle = 0.25;         // after reset, checks on motion start this late [s] (the module
                                // PD's start-up transient); NaN/missing/stale are checked at once
  double command_step = 0.2;    // a β̇_ref change larger than this between commands [rad/s] …
  int command_settle = 5;       // … pauses the consistency check this many cycles (hold/resume)
  double K_O = 10.0;            // observer gain (residual bandwidth) [1/s]
  double r_threshold = 0.03;    // detection threshold on |r| [N·m] (README: 2× the nominal max)
  double t_classify = 2.0;      // least-squares window after the first crossing [s] (one gait
                                // period: the regressors need a full cycle to separate)
  double nominal_tau = 10.0;    // memory of the healthy-past least squares [s]
  double t_transient = 0.3;     // after the crossing, skip this long before fitting [s] (3/K_O:
                                // the filter's onset transient is not a step in φ)
  double persist_fraction = 0.3;  // fraction of the window with |r| > r_threshold/2 to confirm [-]
  double spring_broken = 0.5;   // θ_s ≥ this: stiffness lost ≥ 50 % → kSpringBroken [-]
  // ---- Sensor and data checks ----
  double beta_max = 6.3;        // |β| plausible range [rad] (≈ 2π: links would overlap)
  double beta_dot_max = 60.0;   // |β̇| plausible range [rad/s]
  double deflection_max = 1.0;  // |deflection| plausible range (spring travel) [rad]
  int missing_cycles = 3;       // consecutive kStatusMissing (or frozen frames) → silent [-]
  double missing_time = 0.0;    // > 0: missing replies in a row for this long, and at least
                                // missing_cycles of them → silent [s] (a bus: periods skipped
                                // after an overrun count by their time, but one request left
                                // unanswered across a host stall is not a silent module); 0: cycles
  int stale_count = 3;          // stale/out-of-order/repeated cycles within stale_window → fault [-]
  int stale_window = 50;        // [cycles]
  int hold_cycles = 60;         // bit-identical β samples → encoder stuck [-]
  int hold_cycles_deflection = 150;  // bit-identical deflection samples → stuck (a quantized
                                     // sensor can sit on one code for a while) [-]
  double hold_motion = 5e-3;    // … while β_ref (encoder) or β (deflection) moved this much [rad]
  double consistency_threshold = 5e-4;  // |c| spike threshold [rad]
  int jump_window = 20;         // cycles after a spike to tell a jump from noise [cycles]
  int noise_spikes = 2;         // further spikes within jump_window → noise burst [-]
  double saturation_fraction = 0.8;  // low-passed saturated indicator above this → fault [-]
  double saturation_tau = 0.1;       // its time constant [s]
  // ---- Sensor resolution (README §1.3): declared by the driver (drivers::FeedbackSpec) ----
  // Each threshold is at least what the declared quantization can produce in a healthy run: the
  // consistency check's |c| ≤ LSB_β + dt·LSB_β̇/2 and the hold rule's apparent motion
  // ≤ LSB_β + hold_cycles·T·LSB_β̇/2 are hard bounds (× quantization_margin); the residual's
  // floor is quantization_sigmas × its σ from β, β̇ through J and k_d plus its bounded share
  // (torque LSB/2, k_p·LSB_β/2, K·LSB_def/2). Not declared (0): the configured thresholds alone.
  drivers::FeedbackSpec feedback{};
  double quantization_margin = 2.0;  // [-]
  double quantization_sigmas = 5.0;  // [-]
  // ---- Link side / body prediction ----
  bool body_model = true;       // run the onboard body model (predicted θ_N, p, τ_ext)
  model::Ground ground;         // nominal terrain of the body model (no obstacles)
  double accel_filter_hz = 10.0;  // bandwidth of the α̈/β̈ estimate [Hz]
  double speed_tau = 2.0;       // forward-speed averaging time constant [s] (a gait period)
  // ---- Reactions: severity per class (the runtime maps severities to reactions) ----
  std::array<Severity, kFaultClasses> severity = default_severities();

  static constexpr std::array<Severity, kFaultClasses> default_severities() {
    std::array<Severity, kFaultClasses> s{};
    auto set = [&s](FaultClass c, Severity v) { s[static_cast<std::size_t>(c)] = v; };
    set(FaultClass::kActuatorTorque, Severity::kDegrade);   // hold
    set(FaultClass::kMotorFriction, Severity::kWarning);    // keep walking, published
    set(FaultClass::kEncoderStuck, Severity::kStop);        // PD blind: torque off
    set(FaultClass::kEncoderJump, Severity::kStop);
    set(FaultClass::kEncoderNoise, Severity::kDegrade);
    set(FaultClass::kDeflectionStuck, Severity::kDegrade);
    set(FaultClass::kDeflectionBias, Severity::kWarning);
    set(FaultClass::kDeflectionScale, Severity::kWarning);
    set(FaultClass::kSpringBroken, Severity::kStop);
    set(FaultClass::kModuleSilent, Severity::kStop);
    set(FaultClass::kStaleData, Severity::kDegrade);
    set(FaultClass::kImplausible, Severity::kStop);
    set(FaultClass::kSaturation, Severity::kWarning);
    set(FaultClass::kOverrun, Severity::kDegrade);
    set(FaultClass::kException, Severity::kStop);
    set(FaultClass::kStaleFeedback, Severity::kStop);      // the host's PD is blind: torque off
    return s;
  }
};

// Observer parameters matching a scene (robot, nominal ground without patches or obstacles, known
// joint friction, module torque limit) at a cycle period [s].
ObserverParams observer_params(const model::Scene& scene, double period);

// Throws std::invalid_argument naming the parameter, the value and what was expected.
void validate(const ObserverParams& p);

// One latched fault with its evidence.
struct FaultRecord {
  FaultClass fault = FaultClass::kNone;
  Severity severity = Severity::kInfo;
  std::int16_t joint = -1;  // 0-based, −1 = not a joint (whole frame)
  double t = 0.0;           // time of the verdict [s] (observe's t)
  double value = 0.0;       // evidence [unit of the test: N·m for residuals, rad, cycles, -]
  double threshold = 0.0;   // threshold crossed [same unit]
  double estimate = 0.0;    // fitted fault parameter (gain g, Δb, s, bias [rad]) or 0 [-]
  const char* text = "";    // static description
};

class BodyModel;

class FaultObserver {
 public:
  // Validates (throws std::invalid_argument) and sizes everything for robot.N − 1 joints.
  explicit FaultObserver(const ObserverParams& p);
  ~FaultObserver();
  FaultObserver(const FaultObserver&) = delete;
  FaultObserver& operator=(const FaultObserver&) = delete;

  const ObserverParams& params() const { return p_; }
  int joints() const { return joints_; }

  // Forget everything (latched faults included); the next observe() starts the residuals.
  void reset();

  // One cycle: fb = this cycle's measurements, cmds = the commands written recently (a single
  // Command converts: the one applied since the previous cycle), t = controller time [s], dt =
  // time since the previous cycle's deadline [s]. With fb.timing == kNominal the residual and the
  // consistency check integrate over dt with cmds.last() acting throughout (the in-process
  // plant); with kModule over each joint's measured sample interval with the command(s) the
  // module applied in it, split at its application time (file comment). Returns the number of
  // latched faults (faults() holds them, oldest first). Never allocates, locks or throws.
  int observe(const drivers::Feedback& fb, const drivers::CommandHistory& cmds, double t, double dt);

  // ---- Results of the last observe() ----
  const std::array<double, kMaxJoints>& residual() const { return r_; }   // r [N·m]
  const std::array<double, kMaxJoints>& tau_ext() const { return tau_ext_; }  // [N·m]
  const std::array<double, kMaxJoints>& consistency() const { return c_; }  // c [rad]
  const std::array<double, kMaxJoints>& saturation() const { return sat_lp_; }  // [-]
  // Predicted θ_N, p_x, p_z [rad, m, m] and rates [rad/s, m/s] (zeros without the body model).
  const std::array<double, 6>& body() const { return body_; }
  double forward_speed() const { return speed_; }  // averaged predicted ṗ_x [m/s]
  // Sample intervals not integrated (timing record missing, command not kept, two commands
  // applied in one interval) since reset() [-].
  std::uint64_t intervals_skipped() const { return intervals_skipped_; }
  // Of the intervals checked, those the momentum residual skipped because a command's application
  // time inside them was only estimated, too coarsely for the residual (Interval::estimate_bound)
  // since reset() [-].
  std::uint64_t intervals_estimated() const { return intervals_estimated_; }
  // The thresholds in use with the declared resolution (ObserverParams::feedback; README §1.3):
  // the consistency threshold over one nominal period [rad], the hold rule's motion [rad], the
  // residual's threshold with k_d = 0 (a torque command) [N·m]. Without a declaration: the
  // configured ones.
  double consistency_threshold_used(double beta_dot = 0.0) const {
    return consistency_limit(p_.period, false, beta_dot);
  }
  double hold_motion_used() const { return hold_motion_; }
  double r_threshold_used(double kd = 0.0, double kp = 0.0) const {
    return residual_limit(p_.period, kd, kp);
  }
  const FaultRecord* faults() const { return latched_.data(); }
  int fault_count() const { return n_latched_; }
  // The most severe latched fault (ties: the earliest), or nullptr.
  const FaultRecord* primary() const { return primary_; }
  std::uint32_t flags() const { return flags_; }  // bit (1 << FaultClass) of every latched class

 private:
  struct Joint;
  void latch(FaultClass c, int joint, double t, double value, double threshold, double estimate);
  bool joint_latched(int j) const;
  void check_frame(const drivers::Feedback& fb, double t);
  bool check_joint(const drivers::Feedback& fb, int j, double t, double dt);
  // One sample interval of a joint: its length and the commands that acted over it.
  // Across lost replies it spans several periods and several commands (pieces).
  static constexpr int kMaxGap = 8;          // lost samples bridged [-]
  struct Interval {
    double dt = 0.0;                         // length [s]
    int pieces = 1;                          // commands acting in turn, 1 … kMaxGap + 2
    std::array<const drivers::Command*, kMaxGap + 2> cmd{};  // piece i's command
    std::array<double, kMaxGap + 2> start{};                 // piece i from this far in [s]
    std::array<double, kMaxGap + 2> unsure{};  // how far start[i] may be off: 0 reported, else a cycle [s]
    bool nominal = true;                     // FeedbackTiming::kNominal
    const drivers::Command* before = nullptr;  // kNominal: the command acting until t₀ (if known)
    bool gap = false;                        // spans lost samples
    // A bound on the residual's error from application times that were estimated, not reported
    // (commands inside a gap of lost samples, spaced back a cycle at a time) [N·m]; above
    // kEstimatedShare of the threshold the momentum residual skips the interval (the
    // consistency check and the hold checks still run over it).
    double estimate_bound = 0.0;
  };
  static constexpr double kEstimatedShare = 0.1;  // of r_threshold [-]
  bool make_interval(const drivers::Feedback& fb, const drivers::CommandHistory& cmds, int j,
                     double dt, Interval& iv);
  void residual_step(const drivers::Feedback& fb, const Interval& iv, int j, double t);
  void classify(int j, double t);
  // The consistency threshold over an interval dt [rad] (stretched: a measured interval longer
  // than a period), and the residual's over dt with the module law's gains k_d, k_p [N·m]: the
  // configured ones, or the declared quantization's floor where that is higher (README §1.3).
  // beta_dot: the larger |β̇| of the interval's ends [rad/s] (a sample time off by ε moves c by
  // ε·β̇ at each end).
  double consistency_limit(double dt, bool stretched, double beta_dot) const;
  double residual_limit(double dt, double kd, double kp) const;

  ObserverParams p_;
  int joints_ = 0;
  double J_ = 0.0;  // n² I_r [kg·m²]
  double hold_motion_ = 0.0;  // hold rule's motion with the declared β, β̇ resolution [rad]
  std::array<double, kMaxJoints> K_{};
  std::unique_ptr<Joint[]> jt_;
  std::array<double, kMaxJoints> r_{}, tau_ext_{}, c_{}, sat_lp_{};
  std::array<double, 6> body_{};
  double speed_ = 0.0;
  double elapsed_ = 0.0;  // time since reset [s]
  std::uint64_t intervals_skipped_ = 0;
  std::uint64_t intervals_estimated_ = 0;
  // Frame-level state
  bool have_prev_frame_ = false;
  std::uint64_t prev_seq_ = 0;
  bool frame_ok_ = true;               // this frame may feed the residuals
  bool link_silent_ = false;           // this cycle every joint (of ≥ 2) is missing: the link's
                                       // or the host's silence, not a module's (runtime: stale_data)
  std::uint64_t frame_stale_hist_ = 0;  // repeated/backward seq, last stale_window cycles (bits)
  // Latched faults
  std::array<FaultRecord, 2 * kMaxJoints + 2> latched_{};
  int n_latched_ = 0;
  const FaultRecord* primary_ = nullptr;
  std::uint32_t flags_ = 0;
  std::unique_ptr<BodyModel> body_model_;
};

}  // namespace pedalwave::observer
