#include "pedalwave/observer/fault_observer.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <bit>
#include <cmath>
#include <numbers>
#include <stdexcept>
#include <string>

#include "body_model.hpp"

namespace pedalwave::observer {

using drivers::Command;
using drivers::CommandHistory;
using drivers::Feedback;
using drivers::FeedbackSpec;

namespace {
constexpr std::size_t idx(FaultClass c) { return static_cast<std::size_t>(c); }
int rank(Severity s) { return static_cast<int>(s); }

// Static evidence texts (the Verdict's text must outlive the cycle).
const char* text_of(FaultClass c) {
  switch (c) {
    case FaultClass::kActuatorTorque: return "observer: motor residual ~ u: actuator torque gain/loss";
    case FaultClass::kMotorFriction: return "observer: motor residual ~ beta_dot: motor friction";
    case FaultClass::kEncoderStuck: return "observer: motor encoder stuck (beta frozen while commanded to move)";
    case FaultClass::kEncoderJump: return "observer: motor encoder offset jump (beta vs beta_dot spike)";
    case FaultClass::kEncoderNoise: return "observer: motor encoder noise burst (beta vs beta_dot spikes)";
    case FaultClass::kDeflectionStuck: return "observer: deflection sensor stuck (frozen while the motor moves)";
    case FaultClass::kDeflectionBias: return "observer: motor residual constant: deflection sensor bias";
    case FaultClass::kDeflectionScale: return "observer: motor residual ~ deflection: deflection scale error";
    case FaultClass::kSpringBroken: return "observer: motor residual ~ deflection, >50%: spring stiffness lost";
    case FaultClass::kModuleSilent: return "observer: module not answering (missing frames)";
    case FaultClass::kStaleData: return "observer: stale / out-of-order data";
    case FaultClass::kImplausible: return "observer: NaN or out-of-range measurement";
    case FaultClass::kSaturation: return "observer: persistent torque saturation";
    case FaultClass::kStaleFeedback: return "observer: host-side law on feedback older than the driver's limit";
    default: return "observer fault";
  }
}
}  // namespace

// Per-joint state (everything a cycle writes).
struct FaultObserver::Joint {
  // Previous valid sample
  bool prev_valid = false;
  double beta = 0, beta_dot = 0, defl = 0;
  std::int64_t sample_ns = 0;                      // its module sample time [ns] (kModule)
  std::uint64_t applied_seq = drivers::kNoCommandSeq;  // the command in effect from it on
  double t_prev = 0;                               // its observer time (elapsed_) [s]
  std::uint64_t nominal_seq = 0;                   // kNominal: seq of the command acting from it
  int gap = 0;                                     // lost samples since it [-]
  // Application times learnt from late answers since it (kModule) [-, ns]
  std::array<std::uint64_t, FaultObserver::kMaxGap> known_seq{};
  std::array<std::int64_t, FaultObserver::kMaxGap> known_ns{};
  int known = 0;
  std::array<double, FaultObserver::kMaxGap> gap_t{};  // their observer times [s]
  // Residual regressors filtered like r: [u, K·deflection, β̇, 1]
  std::array<double, 4> phi{};
  // Classification window
  bool classifying = false;
  double t0 = 0;
  int n = 0, above = 0;
  double peak = 0;
  double r_limit = 0;  // the residual's threshold at the crossing [N·m]
  Eigen::Matrix4d G = Eigen::Matrix4d::Zero();
  Eigen::Vector4d g = Eigen::Vector4d::Zero();
  // The same least squares over the healthy past (forgetting nominal_tau): the nominal signature
  // (model error of the plant, coupling) that a fault's signature is measured against.
  Eigen::Matrix4d G_nom = Eigen::Matrix4d::Zero();
  Eigen::Vector4d g_nom = Eigen::Vector4d::Zero();
  // Checks
  int missing_run = 0;
  double missing_s = 0;  // time of the missing run [s]
  std::uint64_t stale_hist = 0;
  int hold_beta = 0, hold_defl = 0, hold_rate = 0;
  double ref_min = 0, ref_max = 0, beta_min = 0, beta_max = 0, rate_int = 0;
  int spike_wait = 0, spikes = 0;
  double spike_value = 0, spike_limit = 0;  // the first spike's |c| and the threshold it crossed
  double prev_ref_rate = 0;  // β̇_ref of the previous command [rad/s]
  int cmd_settle = 0;        // cycles left without consistency checks after a command step
  bool r_started = false;    // the residual's filter was reset at the settle time
  // Link-side filters: α (2nd order: α_f, α̇_f, α̈_f), β̇ (1st order → β̈_f)
  bool filt_init = false;
  double af = 0, afd = 0, afdd = 0, bdf = 0, bdd = 0;
};

ObserverParams observer_params(const model::Scene& scene, double period) {
  ObserverParams p;
  p.robot = scene.robot;
  p.period = period;
  p.motor_viscous = scene.joint_friction_on ? scene.joint_friction.motor_viscous : 0.0;
  p.u_max = scene.torque_limit_on ? scene.torque_limit.u_max : 0.0;
  p.body_model = scene.ground_on;
  p.ground = scene.ground;
  p.ground.patches.clear();
  return p;
}

void validate(const ObserverParams& p) {
  auto fail = [](const char* key, double v, const char* expected) {
    throw std::invalid_argument(std::string("observer parameter ") + key + " = " +
                                std::to_string(v) + ": " + expected);
  };
  model::validate(p.robot);
  if (p.robot.joints != model::JointModel::kFlexible)
    fail("robot.joints", 0, "flexible (the observer's residuals need the SEA deflection)");
  if (p.robot.N - 1 > kMaxJoints) fail("robot.N", p.robot.N, "at most kMaxLinks");
  auto pos = [&](const char* k, double v) {
    if (!std::isfinite(v) || !(v > 0)) fail(k, v, "a finite number > 0");
  };
  auto nonneg = [&](const char* k, double v) {
    if (!std::isfinite(v) || v < 0) fail(k, v, "a finite number >= 0");
  };
  pos("period", p.period);
  nonneg("motor_viscous", p.motor_viscous);
  nonneg("u_max", p.u_max);
  nonneg("settle", p.settle);
  pos("command_step", p.command_step);
  if (p.command_settle < 0) fail("command_settle", p.command_settle, ">= 0");
  pos("K_O", p.K_O);
  pos("r_threshold", p.r_threshold);
  pos("t_classify", p.t_classify);
  pos("nominal_tau", p.nominal_tau);
  nonneg("t_transient", p.t_transient);
  if (!(p.persist_fraction >= 0 && p.persist_fraction <= 1)) fail("persist_fraction", p.persist_fraction, "in [0, 1]");
  pos("spring_broken", p.spring_broken);
  pos("beta_max", p.beta_max);
  pos("beta_dot_max", p.beta_dot_max);
  pos("deflection_max", p.deflection_max);
  if (p.missing_cycles < 1) fail("missing_cycles", p.missing_cycles, ">= 1");
  if (!(p.missing_time >= 0) || !std::isfinite(p.missing_time))
    fail("missing_time", p.missing_time, ">= 0 [s] (0: count missing_cycles)");
  if (p.stale_window < 1 || p.stale_window > 64) fail("stale_window", p.stale_window, "1 … 64 cycles");
  if (p.stale_count < 1 || p.stale_count > p.stale_window) fail("stale_count", p.stale_count, "1 … stale_window");
  if (p.hold_cycles < 2) fail("hold_cycles", p.hold_cycles, ">= 2");
  if (p.hold_cycles_deflection < 2) fail("hold_cycles_deflection", p.hold_cycles_deflection, ">= 2");
  pos("hold_motion", p.hold_motion);
  pos("consistency_threshold", p.consistency_threshold);
  if (p.jump_window < 1) fail("jump_window", p.jump_window, ">= 1");
  if (p.noise_spikes < 1) fail("noise_spikes", p.noise_spikes, ">= 1");
  if (!(p.saturation_fraction > 0 && p.saturation_fraction < 1)) fail("saturation_fraction", p.saturation_fraction, "in (0, 1)");
  pos("saturation_tau", p.saturation_tau);
  pos("accel_filter_hz", p.accel_filter_hz);
  pos("speed_tau", p.speed_tau);
  nonneg("feedback.beta_lsb", p.feedback.beta_lsb);
  nonneg("feedback.beta_dot_lsb", p.feedback.beta_dot_lsb);
  nonneg("feedback.deflection_lsb", p.feedback.deflection_lsb);
  nonneg("feedback.torque_lsb", p.feedback.torque_lsb);
  nonneg("feedback.sample_time_uncertainty", p.feedback.sample_time_uncertainty);
  if (p.feedback.stale_limit < 0) fail("feedback.stale_limit", p.feedback.stale_limit, ">= 0 cycles");
  pos("quantization_margin", p.quantization_margin);
  pos("quantization_sigmas", p.quantization_sigmas);
}

// ---- Thresholds from the declared resolution (README §1.3) ----
// A uniform quantizer of step q has error within ±q/2, σ = q/√12.
// Consistency c = Δβ − dt (β̇₀ + β̇₁)/2: the roundings give |c_q| ≤ q_β + dt·q_β̇/2 (hard bound:
// one spike is a verdict, so a bound, not a σ).
// A sample time off by at most ε (FeedbackSpec::sample_time_uncertainty) at each end moves Δβ by
// up to ε·|β̇| there: 2ε·|β̇| more.
double FaultObserver::consistency_limit(double dt, bool stretched, double beta_dot) const {
  const double stretch = stretched ? std::max(1.0, dt / p_.period) : 1.0;
  const double quant = p_.feedback.beta_lsb + 0.5 * dt * p_.feedback.beta_dot_lsb +
                       2.0 * p_.feedback.sample_time_uncertainty * std::abs(beta_dot);
  return std::max(p_.consistency_threshold * stretch * stretch, p_.quantization_margin * quant);
}

// Residual: e/dt holds (J q_β̇ + (k_d + b_m) q_β)(k+1) − (…)(k) — differenced roundings, which
// the ZOH low-pass r ← r + a (e/dt − r) passes with σ_r = (a/dt)·√(2/(2−a))·σ (≈ K_O·σ) —, and
// the undifferenced k_p (q_β₀ + q_β₁)/2, K (q_d₀ + q_d₁)/2 and the actuator's rounding of the
// command (≤ q_τ/2), which it passes at most at their bound.
double FaultObserver::residual_limit(double dt, double kd, double kp) const {
  const FeedbackSpec& f = p_.feedback;
  if (f.beta_lsb <= 0 && f.beta_dot_lsb <= 0 && f.deflection_lsb <= 0 && f.torque_lsb <= 0)
    return p_.r_threshold;
  const double a = 1.0 - std::exp(-p_.K_O * dt);
  const double gain = a / dt * std::sqrt(2.0 / (2.0 - a));
  const double s_v = J_ * f.beta_dot_lsb / std::sqrt(12.0);
  const double s_b = (std::abs(kd) + p_.motor_viscous) * f.beta_lsb / std::sqrt(12.0);
  const double sigma = gain * std::sqrt(s_v * s_v + s_b * s_b);
  double K_max = 0.0;
  for (int j = 0; j < joints_; ++j) K_max = std::max(K_max, K_[static_cast<std::size_t>(j)]);
  const double bounded =
      0.5 * (f.torque_lsb + std::abs(kp) * f.beta_lsb + K_max * f.deflection_lsb);
  return std::max(p_.r_threshold, p_.quantization_sigmas * sigma + bounded);
}

FaultObserver::FaultObserver(const ObserverParams& p) : p_(p) {
  validate(p_);
  joints_ = p_.robot.N - 1;
  J_ = p_.robot.n * p_.robot.n * p_.robot.I_r;
  for (int j = 0; j < joints_; ++j) K_[static_cast<std::size_t>(j)] = p_.robot.stiffness(j);
  // The hold rule's apparent motion while β sits on one count: the true motion ≤ q_β, and the
  // integrated β̇ adds its roundings, ≤ hold_cycles·T·q_β̇/2.
  hold_motion_ = std::max(p_.hold_motion,
                          p_.quantization_margin * (p_.feedback.beta_lsb + p_.hold_cycles * p_.period *
                                                                               0.5 * p_.feedback.beta_dot_lsb));
  jt_ = std::make_unique<Joint[]>(static_cast<std::size_t>(joints_));
  if (p_.body_model) body_model_ = std::make_unique<BodyModel>(p_.robot, p_.ground);
  reset();
}

FaultObserver::~FaultObserver() = default;

void FaultObserver::reset() {
  for (int j = 0; j < joints_; ++j) jt_[static_cast<std::size_t>(j)] = Joint{};
  r_.fill(0.0);
  tau_ext_.fill(0.0);
  c_.fill(0.0);
  sat_lp_.fill(0.0);
  body_.fill(0.0);
  speed_ = 0.0;
  elapsed_ = 0.0;
  intervals_skipped_ = 0;
  intervals_estimated_ = 0;
  have_prev_frame_ = false;
  prev_seq_ = 0;
  frame_stale_hist_ = 0;
  n_latched_ = 0;
  primary_ = nullptr;
  flags_ = 0;
  if (body_model_) body_model_->reset();
}

bool FaultObserver::joint_latched(int j) const {
  for (int i = 0; i < n_latched_; ++i)
    if (latched_[static_cast<std::size_t>(i)].joint == j) return true;
  return false;
}

void FaultObserver::latch(FaultClass c, int joint, double t, double value, double threshold,
                          double estimate) {
  // One record per (class, joint); the first one wins.
  for (int i = 0; i < n_latched_; ++i) {
    const FaultRecord& f = latched_[static_cast<std::size_t>(i)];
    if (f.fault == c && f.joint == joint) return;
  }
  if (n_latched_ >= static_cast<int>(latched_.size())) return;
  FaultRecord& f = latched_[static_cast<std::size_t>(n_latched_++)];
  f.fault = c;
  f.severity = p_.severity[idx(c)];
  f.joint = static_cast<std::int16_t>(joint);
  f.t = t;
  f.value = value;
  f.threshold = threshold;
  f.estimate = estimate;
  f.text = text_of(c);
  flags_ |= 1u << static_cast<unsigned>(c);
  if (primary_ == nullptr || rank(f.severity) > rank(primary_->severity)) primary_ = &f;
}

// Frame level: the driver's seq must increase (a repeated or backward seq is stale data).
// Returns through frame_ok_ whether this frame may feed the residuals.
void FaultObserver::check_frame(const Feedback& fb, double t) {
  frame_ok_ = true;
  if (have_prev_frame_ && fb.seq <= prev_seq_) frame_ok_ = false;
  const std::uint64_t mask = p_.stale_window >= 64 ? ~0ull : ((1ull << p_.stale_window) - 1);
  frame_stale_hist_ = ((frame_stale_hist_ << 1) | (frame_ok_ ? 0u : 1u)) & mask;
  const int n = std::popcount(frame_stale_hist_);
  if (n >= p_.stale_count)
    latch(FaultClass::kStaleData, -1, t, n, p_.stale_count, 0.0);
  if (frame_ok_ || !have_prev_frame_) prev_seq_ = fb.seq;
  have_prev_frame_ = true;
}

// Data validity of joint j this cycle: plausibility, missing, stale. false = do not integrate.
bool FaultObserver::check_joint(const Feedback& fb, int j, double t, double dt) {
  const auto k = static_cast<std::size_t>(j);
  Joint& s = jt_[k];
  const double b = fb.beta[k], bd = fb.beta_dot[k], d = fb.deflection[k];
  const std::uint16_t st = fb.status[k];
  // Missing: the module did not answer this cycle (values are the driver's stale copy).
  if (st & drivers::kStatusMissing) {
    // A host-side law (the driver's FeedbackSpec::stale_limit) acting on a sample older than the
    // driver allows: named at once (the driver gives the joint no torque meanwhile). All joints at
    // once: the link's (joint −1).
    if (st & drivers::kStatusStaleFeedback)
      latch(FaultClass::kStaleFeedback, link_silent_ ? -1 : j, t, s.missing_run + 1,
            p_.feedback.stale_limit, 0.0);
    // Every module missing at once (a stalled host, a cut link) isolates no module: the run is
    // held, neither counted nor reset, and the runtime's stale_timeout judges the link.
    if (link_silent_) return false;
    ++s.missing_run;
    s.missing_s += dt;
    // With a time window, the count must be reached too: one unanswered request that spans a host
    // stall (the loop held ≥ 0.2 s inside its read) is the host's silence, not the module's.
    if (s.missing_run >= p_.missing_cycles && (p_.missing_time <= 0 || s.missing_s >= p_.missing_time))
      latch(FaultClass::kModuleSilent, j, t, p_.missing_time > 0 ? s.missing_s : s.missing_run,
            p_.missing_time > 0 ? p_.missing_time : p_.missing_cycles, 0.0);
    return false;
  }
  s.missing_run = 0;
  s.missing_s = 0;
  // Stale / out of order, counted over a sliding window.
  const bool stale = (st & (drivers::kStatusStale | drivers::kStatusOutOfOrder)) != 0;
  const std::uint64_t mask = p_.stale_window >= 64 ? ~0ull : ((1ull << p_.stale_window) - 1);
  s.stale_hist = ((s.stale_hist << 1) | (stale ? 1u : 0u)) & mask;
  if (stale) {
    const int n = std::popcount(s.stale_hist);
    if (n >= p_.stale_count) latch(FaultClass::kStaleData, j, t, n, p_.stale_count, 0.0);
    return false;
  }
  // Plausibility: finite and within the physical ranges.
  if (!std::isfinite(b) || std::abs(b) > p_.beta_max) {
    latch(FaultClass::kImplausible, j, t, b, p_.beta_max, 0.0);
    return false;
  }
  if (!std::isfinite(bd) || std::abs(bd) > p_.beta_dot_max) {
    latch(FaultClass::kImplausible, j, t, bd, p_.beta_dot_max, 0.0);
    return false;
  }
  if (!std::isfinite(d) || std::abs(d) > p_.deflection_max) {
    latch(FaultClass::kImplausible, j, t, d, p_.deflection_max, 0.0);
    return false;
  }
  return true;
}

namespace {

// ∫u dt over a piece [0, L] of an interval during which module command c acted, from the motor
// state (β, β̇) at the piece's ends: the module law u = c0 − k_p β − k_d β̇ with
// c0 = τ + k_p β_ref + k_d β̇_ref (interface/io.hpp); the k_d term is exact, the k_p term
// trapezoidal; with a torque limit the clamped law is integrated trapezoidally.
double law_integral(const Command& c, std::size_t k, double L, double ba, double bda, double bb,
                    double bdb, double u_max) noexcept {
  if (c.torque_off || L <= 0) return 0.0;
  const double c0 = c.tau[k] + c.kp[k] * c.beta_ref[k] + c.kd[k] * c.beta_dot_ref[k];
  const double u0 = c0 - c.kp[k] * ba - c.kd[k] * bda;
  const double u1 = c0 - c.kp[k] * bb - c.kd[k] * bdb;
  if (u_max > 0 && (std::abs(u0) >= u_max || std::abs(u1) >= u_max))
    return 0.5 * L * (std::clamp(u0, -u_max, u_max) + std::clamp(u1, -u_max, u_max));
  return L * c0 - c.kp[k] * L * 0.5 * (ba + bb) - c.kd[k] * (bb - ba);
}

// The law's torque at (β, β̇) [N·m].
double law_torque(const Command& c, std::size_t k, double b, double bd, double u_max) noexcept {
  const double u = drivers::module_torque(c, k, b, bd);
  return u_max > 0 ? std::clamp(u, -u_max, u_max) : u;
}

// Whether the module's damping differs between two commands (torque off counts as k_d = 0): at
// such a switch the k_d terms of ∫u dt do not telescope.
bool damping_changes(const Command& a, const Command& b, std::size_t k) noexcept {
  const double ka = a.torque_off ? 0.0 : a.kd[k], kb = b.torque_off ? 0.0 : b.kd[k];
  return std::abs(kb - ka) > 1e-9 * std::max(std::abs(ka), std::abs(kb));
}

double law_offset(const Command& c, std::size_t k) noexcept {
  return c.torque_off ? 0.0 : c.tau[k] + c.kp[k] * c.beta_ref[k] + c.kd[k] * c.beta_dot_ref[k];
}

// The law's torque without its damping term at β: what a command switch steps [N·m].
double law_target(const Command& c, std::size_t k, double beta) noexcept {
  return c.torque_off ? 0.0 : law_offset(c, k) - c.kp[k] * beta;
}

}  // namespace

void FaultObserver::residual_step(const Feedback& fb, const Interval& iv, int j, double t) {
  const auto k = static_cast<std::size_t>(j);
  Joint& s = jt_[k];
  const double dt = iv.dt;
  const Command& cmd = *iv.cmd[static_cast<std::size_t>(iv.pieces - 1)];  // the newest command
  const double b1 = fb.beta[k], bd1 = fb.beta_dot[k], d1 = fb.deflection[k];
  const double b0 = s.beta, bd0 = s.beta_dot, d0 = s.defl;
  const double K = K_[k];
  const bool sensor_latched = joint_latched(j);

  // ---- Kinematic consistency of the encoder: c = Δβ − T (β̇_0 + β̇_1)/2 ----
  // The threshold is set for one period. Over a longer measured interval (a module that sampled
  // late, a late answer used) the trapezoid's own error grows with the interval squared (a change
  // of β̈ inside it: ≤ dt²/8 · Δβ̈), so the threshold does too; an offset jump (≥ 10× the
  // threshold) still stands out over three periods.
  // With a declared sensor resolution it is at least margin × the quantization's bound (README
  // §1.3: a stock servo's 4096 counts per revolution, 1.5e-3 rad, is three times 5e-4 rad).
  const double c_threshold = consistency_limit(dt, !iv.nominal, std::max(std::abs(bd0), std::abs(bd1)));
  double c = (b1 - b0) - 0.5 * dt * (bd0 + bd1);
  // A command that takes effect inside the interval moves β̇ by the module PD's fast response:
  // J β̈ + (k_d + b_m) β̇ = (law offset − k_p β − K·deflection), so β̇ follows its target with the
  // lag τ = J/(k_d + b_m) (0.2 ms) and the target steps by Δ = Δ(law offset − k_p β)/(k_d + b_m).
  // The trapezoid through the two samples misses that step's shape by up to dt/2 · |Δ|; with the
  // step modelled (β̇ = linear + Δ(1 − e^{−(t−t_a)/τ}) after t_a, s = t₁ − t_a, f = 1 − e^{−s/τ}),
  // ∫β̇ = dt (β̇₀ + β̇₁)/2 + Δ (s − τ f − dt f/2) exactly, and what is left is the lag's own
  // shape, ≤ |Δ|·τ (on the virtual robot also its plant step h, as long again). At 100 Hz the
  // gait moves β̇_ref by ≈ 0.08 rad/s per cycle: dt/2 · |Δ| = 3.9e-4 rad, 0.8 of the threshold
  // (measured in lockstep at 100 Hz: |c| up to 4.4e-4 rad in healthy walking; over a bus the
  // check paused for good there, and an encoder offset jump over the VM's bus then went to the
  // residual and was named deflection_bias); the modelled step leaves ≤ 2·|Δ|·τ = 3e-5 rad.
  // Modelled only for a damped module (τ < dt/10; an undamped one, a host-side PD with k_d = 0,
  // moves β̈, not β̇) and where the damping does not change (torque on/off: paused below).
  const double tau = J_ / std::max(cmd.kd[k] + p_.motor_viscous, 1e-12);
  const bool damped = tau < 0.1 * dt;
  double kink = 0.0, moved = 0.0;  // the step model's share of Δβ [rad]; Σ|Δ| [rad/s]
  double unsure = 0.0;  // Σ|Δ|·(how far its time may be off): the model's placement error [rad]
  bool off_step = false;
  const auto add_switch = [&](const Command& was, const Command& now, double ta, double ta_unsure) {
    off_step = off_step || was.torque_off != now.torque_off || damping_changes(was, now, k);
    const double sa = dt - ta, beta_a = b0 + (b1 - b0) * (ta / dt);
    const double jump = (law_target(now, k, beta_a) - law_target(was, k, beta_a)) / (cmd.kd[k] + p_.motor_viscous);
    const double f = 1.0 - std::exp(-sa / tau);
    kink += jump * (sa - tau * f - 0.5 * dt * f);
    moved += std::abs(jump);
    unsure += std::abs(jump) * ta_unsure;
  };
  // Nominal timing: this cycle's command acts from the sample t₀ on (the one before it until t₀).
  if (iv.before) add_switch(*iv.before, *iv.cmd[0], 0.0, 0.0);
  for (int i = 1; i < iv.pieces; ++i)
    add_switch(*iv.cmd[static_cast<std::size_t>(i - 1)], *iv.cmd[static_cast<std::size_t>(i)],
               iv.start[static_cast<std::size_t>(i)], iv.unsure[static_cast<std::size_t>(i)]);
  // A spike is a β that neither hypothesis explains: the module's PD answered the command (c
  // against the step model) or its output did not (torque lost: the plain trapezoid). Judged on
  // the model alone, a module whose torque was lost showed |c| = |kink| every cycle (up to 3.9e-4
  // rad at 100 Hz) and was named encoder_noise over the VM's bus before the residual named the
  // actuator; an encoder offset jump (0.02 rad) is far outside both.
  const double c_plain = c;
  if (damped && !off_step) c -= kink;
  const double c_either = std::abs(c_plain) < std::abs(c) ? c_plain : c;
  if (iv.nominal) {
    // A step in the commanded rate (start, hold, resume) moves the motor within ~J/k_d, faster
    // than the trapezoid follows: no consistency verdicts for a few cycles.
    if (std::abs(cmd.beta_dot_ref[k] - s.prev_ref_rate) > p_.command_step || cmd.torque_off)
      s.cmd_settle = p_.command_settle;
    // After an overrun the gap spans skipped periods: the trapezoid is no longer exact over it and
    // the module's set-points moved meanwhile — pause the verdicts as for a command step.
    if (dt > 1.5 * p_.period) s.cmd_settle = p_.command_settle;
  } else if (damped && !off_step) {
    // Measured timing (also across lost samples: the interval is the two samples' own times, the
    // threshold stretched with it; pausing instead after every lost sample left a few per cent of
    // loss on a loaded bus blind to an offset jump for a fifth of the time): verdicts pause only
    // while the step model's own error bound exceeds a quarter of the threshold (a start, hold or
    // resume: Δ ≈ 2.5 rad/s).
    if (2.0 * moved * tau > 0.25 * c_threshold) s.cmd_settle = p_.command_settle;
  } else {
    // A torque on/off or damping change, or an undamped module: the old bound dt/2 · |Δc₀| /
    // max(k_d, J/dt) on the trapezoid's error.
    const Command& c_first = *iv.cmd[0];
    const double dc0 = iv.pieces > 1 ? std::abs(law_offset(cmd, k) - law_offset(c_first, k)) : 0.0;
    const double stiff = std::max(cmd.kd[k], J_ / dt);
    if (off_step || 0.5 * dt * dc0 / stiff > 0.25 * c_threshold) s.cmd_settle = p_.command_settle;
  }
  c_[k] = c;
  s.prev_ref_rate = cmd.beta_dot_ref[k];
  const bool settled = elapsed_ >= p_.settle;
  // A step placed at an estimated time (inside a gap of lost samples, or beside a late answer used
  // as the sample) may sit up to a cycle off: the model then misses |Δ|·(that) of Δβ — at 100 Hz
  // up to 1.3e-3 rad, 2.6 × the threshold (the size of the VM's rare false encoder_jumps, 5.7e-4 …
  // 2.1e-3 rad, whose cause is not confirmed). The verdicts judge c against the threshold plus
  // that bound; an offset jump (0.02 rad) still stands out by far.
  const double c_limit = c_threshold + (damped && !off_step ? unsure : 0.0);
  if (s.cmd_settle > 0) {
    --s.cmd_settle;
  } else if (!settled) {
  } else if (s.spike_wait > 0) {
    if (std::abs(c_either) > c_limit) ++s.spikes;
    if (s.spikes >= p_.noise_spikes) {
      latch(FaultClass::kEncoderNoise, j, t, s.spike_value, s.spike_limit, 0.0);
      s.spike_wait = 0;
    } else if (--s.spike_wait == 0 && s.hold_beta + 2 < p_.jump_window) {
      // One isolated spike, the encoder alive afterwards: an offset jump.
      latch(FaultClass::kEncoderJump, j, t, s.spike_value, s.spike_limit, s.spike_value);
    }
  } else if (std::abs(c_either) > c_limit && !sensor_latched) {
    s.spike_wait = p_.jump_window;
    s.spikes = 0;
    s.spike_value = c;
    s.spike_limit = c_limit;
  }

  // ---- Hold (stuck) detection: bit-identical values while motion is commanded / happens ----
  const double ref = cmd.beta_ref[k];
  if (b1 == b0) {
    if (s.hold_beta++ == 0) s.ref_min = s.ref_max = ref, s.rate_int = 0.0;
    s.ref_min = std::min(s.ref_min, ref);
    s.ref_max = std::max(s.ref_max, ref);
    s.rate_int += dt * bd1;
  } else {
    s.hold_beta = 0;
  }
  if (d1 == d0) {
    if (s.hold_defl++ == 0) s.beta_min = s.beta_max = b1;
    s.beta_min = std::min(s.beta_min, b1);
    s.beta_max = std::max(s.beta_max, b1);
  } else {
    s.hold_defl = 0;
  }
  s.hold_rate = bd1 == bd0 ? s.hold_rate + 1 : 0;
  if (settled && s.hold_beta >= p_.hold_cycles) {
    const double commanded = (cmd.kp[k] > 0 ? s.ref_max - s.ref_min : 0.0);
    const double motion = std::max(commanded, std::abs(s.rate_int));
    if (motion >= hold_motion_) {
      if (s.hold_defl >= p_.hold_cycles && s.hold_rate >= p_.hold_cycles && s.hold_rate == s.hold_beta)
        latch(FaultClass::kModuleSilent, j, t, s.hold_beta, p_.hold_cycles, 0.0);
      else
        latch(FaultClass::kEncoderStuck, j, t, motion, hold_motion_, b1);
    }
  }
  if (settled && s.hold_defl >= p_.hold_cycles_deflection && s.beta_max - s.beta_min >= hold_motion_ &&
      s.hold_beta == 0)
    latch(FaultClass::kDeflectionStuck, j, t, s.beta_max - s.beta_min, hold_motion_, d1);

  // ---- Momentum residual (file comment of the header) ----
  // ∫u dt: one piece with the command in effect since the previous sample, or one piece per
  // command when the module applied new ones inside the interval; β, β̇ at each split from the
  // cubic Hermite interpolant of the two samples (the k_d terms telescope: exact whatever the
  // splits, so the interval's quantization noise cancels against its neighbours' as it must).
  // Except where the damping changes at a split (torque on or off: the start, a stop): there the
  // k_d terms do not telescope, and the module's response to the new law (within J/k_d, 0.2 ms)
  // is faster than the cubic follows — at the start from rest into the gait's rate the cubic put
  // β at the split 0.3·T·Δβ̇ off (≈ 6e-4 rad at 500 Hz, × k_d = 15: an unexplained 0.009 N·m·s,
  // the bus's start-up impulse). There β comes from the motion under the law before the split:
  // constant acceleration (u − K·deflection − b_m·β̇)/J from the piece's start.
  // Commands placed at estimated times (inside a gap of lost samples) whose misplacement could
  // move r by more than a tenth of the threshold: the residual skips the interval; the checks
  // above ran over it. At 100 Hz a command moves the law's offset by ≈ 0.75–1.5 N·m a cycle and
  // its time inside the cycle varies by a few ms: integrated, such an interval kicked r by up to
  // 0.05 N·m (a real-time walk over a socket pair with 2 % of the replies lost stopped on
  // actuator_torque), while at 1 kHz the bound is ≈ 1e-3 N·m and the gap is bridged as before.
  if (iv.estimate_bound > kEstimatedShare * p_.r_threshold) {
    ++intervals_estimated_;
    return;
  }
  double Iu = 0.0;  // ∫u dt [N·m·s]
  if (iv.pieces == 1) {
    Iu = law_integral(*iv.cmd[0], k, dt, b0, bd0, b1, bd1, p_.u_max);
  } else {
    auto hermite = [&](double ts, double& bm, double& bdm) {
      const double u = ts / dt, u2 = u * u, u3 = u2 * u;
      bm = (2 * u3 - 3 * u2 + 1) * b0 + (u3 - 2 * u2 + u) * dt * bd0 + (-2 * u3 + 3 * u2) * b1 +
           (u3 - u2) * dt * bd1;
      bdm = (6 * u2 - 6 * u) / dt * b0 + (3 * u2 - 4 * u + 1) * bd0 + (-6 * u2 + 6 * u) / dt * b1 +
            (3 * u2 - 2 * u) * bd1;
    };
    double ta = 0.0, ba = b0, bda = bd0;
    for (int i = 0; i < iv.pieces; ++i) {
      const auto iu = static_cast<std::size_t>(i);
      const double tb = i + 1 < iv.pieces ? iv.start[iu + 1] : dt;
      double bb = b1, bdb = bd1;
      if (i + 1 < iv.pieces) {
        const Command& now = *iv.cmd[iu];
        if (damping_changes(now, *iv.cmd[iu + 1], k)) {
          const double h = tb - ta;
          const double d_a = d0 + (d1 - d0) * (ta / dt);
          const double acc = (law_torque(now, k, ba, bda, p_.u_max) - K * d_a - p_.motor_viscous * bda) / J_;
          bb = ba + bda * h + 0.5 * acc * h * h;
          bdb = bda + acc * h;
        } else {
          hermite(tb, bb, bdb);
        }
      }
      Iu += law_integral(*iv.cmd[iu], k, tb - ta, ba, bda, bb, bdb, p_.u_max);
      ta = tb;
      ba = bb;
      bda = bdb;
    }
  }
  const double Is = dt * K * 0.5 * (d0 + d1);              // ∫K·deflection dt
  const double Ib = p_.motor_viscous * (b1 - b0);          // ∫b_m β̇ dt
  const double e = J_ * (bd1 - bd0) - (Iu - Is - Ib);      // unexplained impulse
  const double a = 1.0 - std::exp(-p_.K_O * dt);
  // The detection threshold: the configured one, or the declared quantization's floor (§1.3).
  const double r_limit = residual_limit(dt, cmd.torque_off ? 0.0 : cmd.kd[k], cmd.torque_off ? 0.0 : cmd.kp[k]);
  double& r = r_[k];
  // The residual restarts at the settle time: its filter holds nothing of the start-up transient
  // (the module PD's start from rest; over a bus, before the torque-on split above, the first
  // cycles left an impulse up to 0.09 N·m in r, decaying with 1/K_O, whose tail still crossed the
  // threshold at the settle time in 2 of 12 walks: the start-up false alarm ≈ 2.55 s into a run).
  if (settled && !s.r_started) {
    r = 0.0;
    s.r_started = true;
  }
  r += a * (e / dt - r);
  const double x[4] = {Iu / dt, Is / dt, (b1 - b0) / dt, 1.0};
  for (int i = 0; i < 4; ++i) s.phi[static_cast<std::size_t>(i)] += a * (x[i] - s.phi[static_cast<std::size_t>(i)]);

  // ---- Detection and isolation from the residual ----
  if (sensor_latched) {
    s.classifying = false;
    return;
  }
  const Eigen::Vector4d phi(s.phi[0], s.phi[1], s.phi[2], s.phi[3]);
  if (!s.classifying) {
    if (settled) {
      const double lam = std::exp(-dt / p_.nominal_tau);
      s.G_nom *= lam;
      s.g_nom *= lam;
      s.G_nom.noalias() += phi * phi.transpose();
      s.g_nom += phi * r;
    }
    if (settled && std::abs(r) > r_limit && s.spike_wait == 0) {
      s.classifying = true;
      s.t0 = t;
      s.r_limit = r_limit;
      s.n = s.above = 0;
      s.peak = std::abs(r);  // the evidence starts with the crossing: value ≥ threshold
      s.G.setZero();
      s.g.setZero();
    }
    return;
  }
  s.peak = std::max(s.peak, std::abs(r));
  if (t - s.t0 < p_.t_transient) return;  // r and φ still in the onset transient (3/K_O)
  s.G.noalias() += phi * phi.transpose();
  s.g += phi * r;
  ++s.n;
  if (std::abs(r) > 0.5 * s.r_limit) ++s.above;
  if (t - s.t0 >= p_.t_transient + p_.t_classify) classify(j, t);
}

// End of the window: confirm (persistent) and name the class by the dominant regressor.
void FaultObserver::classify(int j, double t) {
  Joint& s = jt_[static_cast<std::size_t>(j)];
  s.classifying = false;
  if (s.n == 0 || s.above < p_.persist_fraction * s.n) return;  // a transient: no fault
  // Least squares r ≈ θ·φ over the window and over the healthy past (regularized a little for an
  // unexcited regressor); the fault's signature is the change Δθ = θ − θ_nominal.
  // The nominal fit is ridge-regularized: directions the healthy data does not determine (u and
  // K·deflection are nearly collinear: they differ by J β̈) stay at zero instead of ±large.
  auto solve = [](const Eigen::Matrix4d& G0, const Eigen::Vector4d& g0, double ridge) {
    Eigen::Matrix4d G = G0;
    const double tr = G.trace();
    G.diagonal().array() += ridge * (tr > 0 ? tr : 1.0);
    return Eigen::Vector4d(G.ldlt().solve(g0));
  };
  const Eigen::Vector4d th_nom = solve(s.G_nom, s.g_nom, 1e-3);
  Eigen::Vector4d th = solve(s.G, s.g, 1e-9) - th_nom;
  int best = 0;
  double best_c = -1.0;
  for (int i = 0; i < 4; ++i) {
    const double contribution = std::abs(th(i)) * std::sqrt(s.G(i, i) / s.n);
    if (contribution > best_c) best_c = contribution, best = i;
  }
  // A deflection sensor class (K·deflection or the constant): decided again by the fit of the
  // window's departure Δr = r − θ_nom·φ on those two regressors alone. A deflection bias δ enters
  // the K·deflection regressor too: K·(deflection + δ) = u − J β̈ − b_m β̇ + K δ, so after the
  // bias the four regressors are nearly dependent, and θ_u = −θ_s (with θ_β̇) fits the constant
  // Δr = K δ up to J β̈. In lockstep the four-regressor fit still resolves it; over a bus the
  // residual's noise does not allow it: a bias was named deflection_scale or spring_broken in one
  // of three injections. Without u the two are separated by K·deflection's variation over the gait.
  if (best == 1 || best == 3) {
    const Eigen::Vector4d gd = s.g - s.G * th_nom;  // Σ φ Δr over the window
    Eigen::Matrix2d G2;
    G2 << s.G(1, 1), s.G(1, 3), s.G(3, 1), s.G(3, 3);
    const Eigen::Vector2d ac = G2.ldlt().solve(Eigen::Vector2d(gd(1), gd(3)));
    if (ac.allFinite()) {
      th(1) = ac(0);
      th(3) = ac(1);
      best = std::abs(ac(0)) * std::sqrt(s.G(1, 1) / s.n) > std::abs(ac(1)) ? 1 : 3;
    }
  }
  const double K = K_[static_cast<std::size_t>(j)];
  switch (best) {
    case 0:
      latch(FaultClass::kActuatorTorque, j, t, s.peak, s.r_limit, 1.0 + th(0));
      break;
    case 1:
      if (th(1) >= p_.spring_broken)
        latch(FaultClass::kSpringBroken, j, t, s.peak, s.r_limit, 1.0 - th(1));
      else
        latch(FaultClass::kDeflectionScale, j, t, s.peak, s.r_limit, 1.0 / (1.0 - th(1)));
      break;
    case 2:
      latch(FaultClass::kMotorFriction, j, t, s.peak, s.r_limit, -th(2));
      break;
    default:
      latch(FaultClass::kDeflectionBias, j, t, s.peak, s.r_limit, th(3) / K);
      break;
  }
}

// The interval from joint j's previous valid sample to this one: its length and the commands that
// acted over it, in turn. false = it cannot be integrated (timing record missing, a command no
// longer kept, more than kMaxGap + 1 commands): the residual skips it.
//   kNominal: the command written in cycle i acts over [t_i, t_i+1] (the in-process plant); over a
//     gap of lost samples the cycles' times are the observer's own (exact).
//   kModule: the command in effect at the previous sample, then each newer one from its
//     application; the module reports the last application time, earlier ones inside a gap are
//     spaced evenly back from it (their samples were lost).
bool FaultObserver::make_interval(const Feedback& fb, const CommandHistory& cmds, int j, double dt,
                                  Interval& iv) {
  const auto k = static_cast<std::size_t>(j);
  const Joint& s = jt_[k];
  iv.gap = s.gap > 0;
  if (fb.timing == drivers::FeedbackTiming::kNominal) {
    iv.nominal = true;
    if (s.gap == 0) {  // the common case, as before the timing records existed
      iv.dt = dt;
      iv.pieces = 1;
      iv.cmd[0] = &cmds.last();
      iv.start[0] = 0.0;
      iv.before = iv.cmd[0]->seq > 0 ? cmds.find(iv.cmd[0]->seq - 1) : nullptr;
      return true;
    }
    iv.dt = elapsed_ - s.t_prev;
    const std::uint64_t first = s.nominal_seq, last = cmds.last().seq;
    if (last < first || last - first > static_cast<std::uint64_t>(s.gap)) return false;
    iv.before = first > 0 ? cmds.find(first - 1) : nullptr;
    iv.pieces = static_cast<int>(last - first) + 1;
    for (int i = 0; i < iv.pieces; ++i) {
      const auto iu = static_cast<std::size_t>(i);
      iv.cmd[iu] = cmds.find(first + iu);
      if (iv.cmd[iu] == nullptr) return false;
      iv.start[iu] = i == 0 ? 0.0 : s.gap_t[iu - 1] - s.t_prev;
    }
    return iv.dt > 0;
  }
  const std::int64_t t1 = fb.sample_ns[k];
  if (t1 == 0 || s.sample_ns == 0 || t1 <= s.sample_ns) return false;
  iv.nominal = false;
  iv.dt = static_cast<double>(t1 - s.sample_ns) * 1e-9;
  // An interval longer than the bridged gaps (the host stalled: no SYNC, so no sample, for tens of
  // periods) is not integrated: the trapezoids on β and deflection over it are off by a motion the
  // samples never saw (a 0.1 s host stall left |r| ≈ 0.12 N·m, four times the threshold, decaying
  // with 1/K_O). Nothing is checked across it; the next interval is.
  if (iv.dt > (kMaxGap + 1.5) * p_.period) return false;
  iv.pieces = 1;
  iv.cmd[0] = cmds.find(s.applied_seq);
  iv.start[0] = 0.0;
  if (iv.cmd[0] == nullptr) return false;
  const std::uint64_t a = fb.applied_seq[k];
  if (a == s.applied_seq) return true;
  // A new command at an unknown time (its age saturated at 32.8 ms: at 100 Hz, an interval of
  // four periods or more across a stall) is not integrated: placed at the saturated age, it
  // left |r| ≈ 0.08–0.39 N·m after a 4–8-period stall (BusModel.AMachineStallAt100Hz…).
  if (fb.applied_ns[k] == 0) return false;
  const double t_last = std::clamp(static_cast<double>(fb.applied_ns[k] - s.sample_ns) * 1e-9, 0.0, iv.dt);
  // The commands applied since: from the old one's successor to the reported one. "No command"
  // on either side is a single switch.
  std::uint64_t n = 1;
  if (a != drivers::kNoCommandSeq && s.applied_seq != drivers::kNoCommandSeq) {
    if (a < s.applied_seq) return false;
    n = a - s.applied_seq;
  }
  if (n > static_cast<std::uint64_t>(kMaxGap + 1)) return false;
  // Commands go out once a cycle: across lost samples the gap's cycles space them; otherwise (two
  // commands inside one sample interval, e.g. after a late answer was used) this cycle's length.
  const double spacing = s.gap > 0 ? iv.dt / static_cast<double>(s.gap + 1) : dt;
  double misplaced = 0.0;  // Σ |Δ(law offset − k_p β)| × spacing over the estimated ones [N·m·s]
  for (std::uint64_t i = 0; i < n; ++i) {
    const std::uint64_t seq = n == 1 ? a : s.applied_seq + 1 + i;
    const auto iu = static_cast<std::size_t>(i + 1);
    iv.cmd[iu] = cmds.find(seq);
    if (iv.cmd[iu] == nullptr) return false;
    // When it took effect: reported (the last one; a late answer's record), else spaced back.
    double at = t_last - static_cast<double>(n - 1 - i) * spacing;
    bool reported = seq == a;
    for (int q = 0; q < s.known && seq != a; ++q)
      if (s.known_seq[static_cast<std::size_t>(q)] == seq) {
        at = static_cast<double>(s.known_ns[static_cast<std::size_t>(q)] - s.sample_ns) * 1e-9;
        reported = true;
      }
    // A torque on/off switch (k_d changes) at an estimated time: its error is Δk_d·β̇_ref times
    // the estimate's error (15 N·m·s/rad · 2.5 rad/s · a few ms: several times the threshold's
    // impulse) — not integrated.
    if (!reported && damping_changes(*iv.cmd[iu - 1], *iv.cmd[iu], k)) return false;
    // An estimated time is off by up to a cycle (the host's write time and the bus vary from
    // cycle to cycle: on the pty 2 or 5.5 ms into a 10 ms period, at random), and the law's
    // offset switches there: that much impulse is misplaced.
    if (!reported)
      misplaced += std::abs(law_target(*iv.cmd[iu], k, s.beta) - law_target(*iv.cmd[iu - 1], k, s.beta)) * spacing;
    iv.start[iu] = std::clamp(at, iv.start[iu - 1], iv.dt);
    iv.unsure[iu] = reported ? 0.0 : spacing;
  }
  iv.pieces = static_cast<int>(n) + 1;
  // What that does to r after the ZOH low-pass: (1 − e^{−K_O dt}) · impulse / dt.
  iv.estimate_bound = (1.0 - std::exp(-p_.K_O * iv.dt)) * misplaced / iv.dt;
  return true;
}

int FaultObserver::observe(const Feedback& fb, const CommandHistory& cmds, double t, double dt) {
  if (!std::isfinite(dt) || dt <= 0) dt = p_.period;
  const bool module_timing = fb.timing == drivers::FeedbackTiming::kModule;
  elapsed_ += dt;
  check_frame(fb, t);
  const int J = std::min(joints_, fb.joints);
  bool all_ok = frame_ok_ && J == joints_;
  link_silent_ = J > 1;
  for (int j = 0; j < J && link_silent_; ++j)
    link_silent_ = (fb.status[static_cast<std::size_t>(j)] & drivers::kStatusMissing) != 0;
  for (int j = 0; j < J; ++j) {
    const auto k = static_cast<std::size_t>(j);
    Joint& s = jt_[k];
    const bool lost = (fb.status[k] & drivers::kStatusMissing) != 0 ||
                      (module_timing && fb.sample_ns[k] == 0);
    if (module_timing && fb.late_applied_ns[k] != 0 && s.known < kMaxGap) {
      s.known_seq[static_cast<std::size_t>(s.known)] = fb.late_applied_seq[k];
      s.known_ns[static_cast<std::size_t>(s.known++)] = fb.late_applied_ns[k];
    }
    const bool ok = check_joint(fb, j, t, dt) && frame_ok_ && !lost;
    all_ok &= ok;
    if (!ok) {
      // A lost sample is bridged: the next valid one integrates over the whole gap, so the
      // differenced terms (k_d Δβ, J Δβ̇) keep telescoping. Anything else restarts the residual.
      if (lost && frame_ok_ && s.prev_valid && s.gap < kMaxGap) {
        s.gap_t[static_cast<std::size_t>(s.gap++)] = elapsed_;
      } else if (frame_ok_) {
        s.prev_valid = false;  // a repeated frame keeps the previous sample
        s.gap = 0;
      }
      continue;
    }
    // The command in effect at this sample (kModule: the one the module says it applied).
    const Command* applied = module_timing ? cmds.find(fb.applied_seq[k]) : &cmds.last();
    const Command& last_cmd = applied ? *applied : cmds.last();
    // Persistent saturation: the module law's demand beyond ±u_max (or the module says so).
    const double u_demand = drivers::module_torque(last_cmd, k, fb.beta[k], fb.beta_dot[k]);
    const bool sat = (p_.u_max > 0 && std::abs(u_demand) >= p_.u_max) ||
                     (fb.status[k] & drivers::kStatusSaturated) != 0;
    sat_lp_[k] += (1.0 - std::exp(-dt / p_.saturation_tau)) * ((sat ? 1.0 : 0.0) - sat_lp_[k]);
    if (sat_lp_[k] > p_.saturation_fraction && elapsed_ >= p_.settle)
      latch(FaultClass::kSaturation, j, t, sat_lp_[k], p_.saturation_fraction, u_demand);
    Interval iv;
    if (s.prev_valid && make_interval(fb, cmds, j, dt, iv)) residual_step(fb, iv, j, t);
    else if (s.prev_valid) ++intervals_skipped_;
    s.sample_ns = module_timing ? fb.sample_ns[k] : 0;
    s.applied_seq = fb.applied_seq[k];
    s.t_prev = elapsed_;
    s.nominal_seq = cmds.last().seq + 1;  // kNominal: this cycle's command acts from here
    s.gap = 0;
    s.known = 0;
    // Link-side filters on α = β − deflection and β̇.
    const double alpha = fb.beta[k] - fb.deflection[k];
    const double w = 2.0 * std::numbers::pi * p_.accel_filter_hz;
    if (!s.filt_init) {
      s.af = alpha;
      s.afd = s.afdd = 0.0;
      s.bdf = fb.beta_dot[k];
      s.bdd = 0.0;
      s.filt_init = true;
    } else {
      s.afdd = w * w * (alpha - s.af) - 2.0 * w * s.afd;
      s.afd += dt * s.afdd;
      s.af += dt * s.afd;
      const double ab = 1.0 - std::exp(-w * dt);
      const double bdf_new = s.bdf + ab * (fb.beta_dot[k] - s.bdf);
      s.bdd = (bdf_new - s.bdf) / dt;
      s.bdf = bdf_new;
    }
    s.beta = fb.beta[k];
    s.beta_dot = fb.beta_dot[k];
    s.defl = fb.deflection[k];
    s.prev_valid = true;
  }
  // ---- Link side: body prediction and external torques (all joints valid only) ----
  if (body_model_ && all_ok) {
    std::array<double, kMaxJoints> alpha{}, ad{}, add{}, bdd{};
    for (int j = 0; j < J; ++j) {
      const auto k = static_cast<std::size_t>(j);
      alpha[k] = fb.beta[k] - fb.deflection[k];
      ad[k] = jt_[k].afd;
      add[k] = jt_[k].afdd;
      bdd[k] = jt_[k].bdd;
    }
    if (body_model_->step(alpha.data(), ad.data(), add.data(), fb.beta.data(), fb.beta_dot.data(),
                          bdd.data(), fb.deflection.data(), dt, tau_ext_.data())) {
      BodyModel& bm = *body_model_;
      body_ = {bm.theta_N(), bm.p_x(), bm.p_z(), bm.theta_N_dot(), bm.p_x_dot(), bm.p_z_dot()};
      speed_ += (1.0 - std::exp(-dt / p_.speed_tau)) * (bm.p_x_dot() - speed_);
    }
  }
  return n_latched_;
}

}  // namespace pedalwave::observer
