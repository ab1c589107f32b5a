// A robot's K per joint, motor friction, I_r and ground friction from a recording of its walk
// (pedalwave_identify data).
//
// Stage 1, equation error (linear least squares, no simulation): the motor rows of the model
// (model-spec.md §4) for joint j,
//     n² I_r β̈_j − n I_r θ̈_j + K_j (β_j − α_j) + b β̇_j = u_j(t),
// integrated over windows [t_a, t_b] of whole control periods so that no signal is differentiated:
//     ∫u_j dt = K_j ∫(β_j − α_j) dt + b ∫β̇_j dt + I_r [n² Δβ̇_j − n Δθ̇_j].
// u_j(t) is the torque the module applies within each period: with the PD on the module
// (pd placement module, the default) the recorded command u_k plus the PD's change along the
// period, u_k − K_p (β(t) − β_k) − K_D (β̇(t) − β̇_k); with the PD on the host, u_k held. ∫β̇ is
// taken from the encoder (β_b − β_a), exact whatever the motor's fast dynamics within a period
// (n² I_r / K_D is below a period): the encoder's noise enters ×K_D, which a motor-side encoder
// (output resolution 2π / (counts · n), ~6e-6 rad for 4096 counts and n = 255) keeps small. The
// unknowns K_1 … K_{N−1}, b and I_r enter linearly; the windows' residuals give their standard
// errors. The θ̇ term (a 1/n correction) is used when the recording has θ̇ (simulated recordings);
// without it I_r is biased by O(1/n).
// Stage 2, output error (simulation, NLopt): the ground's μ from the recorded deflections β − α
// and joint angles α: the recording's scene with stage 1's K, b, I_r is simulated in closed loop
// for candidate μ, one campaign batch of a grid, then a bounded local search (LN_SBPLX); the
// residual's variance and the sensitivity give μ's standard deviation.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "pedalwave/campaign/campaign.hpp"
#include "pedalwave/model/scene.hpp"

namespace pedalwave::identify {

// Samples every control period, per joint [j][k].
struct Recording {
  int joints = 0;
  std::vector<double> t;                                  // [s]
  std::vector<std::vector<double>> alpha, beta, beta_dot, u;  // [rad], [rad], [rad/s], [N·m]
  // Optional (simulated recordings): α̇_j and θ̇_N, for the absolute link rates θ̇_j = θ̇_N + Σ_{k≥j} α̇_k
  // of the motor rows' 1/n term; empty = not recorded.
  std::vector<std::vector<double>> alpha_dot;             // [rad/s]
  std::vector<double> theta_N_dot;                        // [rad/s]
  // The samples' cycle numbers (the robot's seq) when cycles are missing (a telemetry recording
  // that lost samples): t_k = t_0 + h (cycle_k − cycle_0). Empty: one sample every period.
  std::vector<long long> cycle;
  // What the robot's description (<ns>/pedalwave/robot_description) says, when the recording has
  // it: the gear ratio n and the configured K_j and I_r; 0 / empty = not recorded.
  double gear_ratio = 0, nominal_I_r = 0;
  std::vector<double> nominal_K;
  std::string source;
  std::vector<std::string> notes;  // what the reader wants the user to know (an unfinished file)
};

// The control period h [s] (from the first and last samples and their cycles) and sample k's cycle
// (k when the recording has no gaps).
double sample_period(const Recording& r);
long long cycle_of(const Recording& r, std::size_t k);

// Any recording, by its kind: an MCAP file (extension .mcap or the MCAP magic) → read_recording_mcap;
// the CSV recorder's files (run.joint_state.csv, or run.csv when the recorder wrote
// run.<topic>.csv) → read_recorder_csv; else pedalwave_sim's trajectory.csv → read_recording_csv.
Recording read_recording(const std::filesystem::path& file);

// The robot's telemetry recorded as MCAP (the daemon's telemetry.record, pedalwave_monitor --record
// run.mcap): the topics <ns>/pedalwave/joint_state (β, β̇, α) and <ns>/pedalwave/controller_state
// (u, mode), decoded by the ros2msg schemas the file carries and joined by cycle (seq; their
// stamp_ns must agree), the cycles in mode RUNNING kept, t the controller time. Throws naming the
// file and what is missing (a topic, a field) or wrong (a cycle twice, uneven t).
Recording read_recording_mcap(const std::filesystem::path& file);
// The same from the CSV recorder's run.joint_state.csv and run.controller_state.csv.
Recording read_recorder_csv(const std::filesystem::path& joint_state_csv,
                            const std::filesystem::path& controller_state_csv);
// One cycle of each topic, and their join (read_recording_mcap and read_recorder_csv share it).
struct JointRow {
  long long seq = 0, stamp_ns = 0;
  double t = 0;
  std::vector<double> beta, beta_dot, alpha;
};
struct ControllerRow {
  long long seq = 0, stamp_ns = 0;
  double mode = 0;
  std::vector<double> u;
};
Recording join_telemetry(const std::vector<JointRow>& joints, const std::vector<ControllerRow>& controller,
                         const std::string& source);

// pedalwave_sim's trajectory.csv (t, alpha_j, beta_j, beta_j_dot, u_j; θ̇ from theta_N_dot and
// alpha_j_dot when present), j = 1 … N−1. Throws std::runtime_error naming the file and the column
// (a missing one, unequal sample spacing).
Recording read_recording_csv(const std::filesystem::path& file);
// Writes the columns read_recording_csv reads (tests and tools).
void write_recording_csv(const Recording& r, const std::filesystem::path& file);

struct MotorFitOptions {
  double n = 255;           // gear ratio [-] (published)
  bool module_pd = true;    // PD applied on the module within the period (else host: u held)
  double K_p = 30, K_D = 15;
  double window = 0.05;     // [s], whole control periods
  double skip = 0.0;        // ignore the first seconds [s]
};
struct MotorFit {
  std::vector<double> K, K_se;  // [N·m/rad]
  double b = 0, b_se = 0;       // [N·m·s/rad]
  double I_r = 0, I_r_se = 0;   // [kg·m²]
  double residual_rms = 0;      // of ∫u over a window [N·m·s]
  int rows = 0, windows = 0;
  bool theta_term = false;
};
MotorFit fit_motor(const Recording& r, const MotorFitOptions& o);

struct GroundFitOptions {
  double lo = 0.1, hi = 1.5;  // μ bounds [-]
  int grid = 8;               // first batch
  int max_evals = 30;         // local search
  double rate_hz = 0;         // 0 = from the recording's sample period
  campaign::Options campaign;
};
struct GroundFit {
  double mu = 0, mu_sigma = 0;
  double rms = 0;             // residual RMS at the fit [rad]
  int simulations = 0;
};
// `recording`: the file read_recording_csv reads (the campaign's runs read it: a path the nodes
// share); `scene_yaml`: the recording's scene (gait, initial pose, robot, integrator) as YAML text,
// simulated with stage 1's K, b and I_r and each candidate μ (ground and patches scaled alike).
GroundFit fit_ground_mu(const std::filesystem::path& recording, const std::string& scene_yaml,
                        const MotorFit& motor, const GroundFitOptions& o);
// The campaign runner of fit_ground_mu (and its Slurm worker): one simulation → the residual sum.
std::string ground_run_line(const std::string& spec);

}  // namespace pedalwave::identify
