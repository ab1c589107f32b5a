// The simulation CLI's engine (pedalwave_sim): runs a scene in closed loop (simloop::ClosedLoop —
// the runtime's controller and simulated-plant driver in lockstep), records the trajectory to CSV,
// computes the summary (speed, energy, penetration, integrator cost) and draws the plots.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "pedalwave/model/plant.hpp"
#include "pedalwave/model/scene.hpp"
#include "pedalwave/simloop/closed_loop.hpp"
#include "pedalwave/simloop/stair_events.hpp"
#include "pedalwave/toolkit/figures.hpp"

namespace pedalwave::simulate {

// Everything the command line decides (after the scene file and the overrides are read).
struct RunConfig {
  model::Scene scene;                 // the scene, with --duration applied
  model::IntegratorOptions integ;     // the scene's integrator with --integrator/--h/--rtol applied
  simloop::Options loop;              // control rate [Hz], controller on/off, k_c
  double every = 0.01;                // CSV/plot sample period [s], a multiple of 1/rate
  std::filesystem::path out_dir;      // output folder (created)
  bool plots = true;                  // write SVG/PNG figures
  bool progress = true;               // progress bar on stderr
};

// Checks what the scene and the options cannot check alone (sample period against the control
// period, duration against the sample period). Throws std::invalid_argument naming the option,
// its value and what was expected.
void validate(const RunConfig& c);

// CSV column names for a model, in order:
//   t,
//   alpha_1 … alpha_{N-1}, theta_N, p_x, p_z, beta_1 … beta_{N-1} (flexible only)   q
//   the same names with the suffix _dot                                              q̇
//   fn_0 … fn_{2N}, ft_0 … ft_{2N}    normal / tangential contact force per body point [N]
//                                     (point k: 0 tail tip, 2i+1 link COM, 2j+2 joint, 2N head tip)
//   v_forward                         whole-robot COM x velocity [m/s] (+X is forward)
//   tau_sea_1 … tau_sea_{N-1}         SEA torque K (β − α) [N·m] (flexible only)
//   u_1 … u_{N-1}                     commanded motor torque [N·m] (the controller's u; 0 passive)
//   com_x, com_z, head_x, head_z      whole-robot COM and head-tip position [m]
std::vector<std::string> trajectory_columns(const model::Model& m);

// What a run measured (also the data of the plots).
struct RunResult {
  model::StepStatus status = model::StepStatus::kOk;  // kOk, or the failure that stopped the run
  double t_end = 0.0;             // plant time reached [s]
  std::size_t rows = 0;           // CSV rows written
  // Samples at the CSV times (n rows).
  std::vector<double> t;          // [s]
  std::vector<double> com_x, com_z, head_x, head_z;  // [m]
  std::vector<double> v_forward;  // [m/s]
  std::vector<std::vector<double>> tau_sea;  // [joint][row] [N·m] (empty for rigid joints)
  std::vector<std::vector<double>> u;        // [joint][row] [N·m]
  std::vector<std::vector<double>> body_x, body_z;  // [row][point] the 2N+1 body points [m]
  // Summary.
  double avg_speed = 0.0;         // (com_x(T) − com_x(t0)) / (T − t0) [m/s]
  double avg_from = 0.0;          // t0: 1 s, or 0 when the run is not longer than 1 s [s]
  double e_initial = 0.0, e_final = 0.0, e_min = 0.0, e_max = 0.0;  // mechanical energy [J]
  // Elastic energy in the ground at t = 0, Σ_k ½ k δ_k² over the body points below ground.z [J]
  // (not part of the mechanical energy above: a start in penetration releases it).
  double e_ground_initial = 0.0;
  double w_motor = 0.0;           // ∫ u_act · (motor rates) dt, trapezoid per control period [J]
  double w_joint_friction = 0.0;  // ∫ b β̇² dt dissipated in the motor bearings [J]
  double max_penetration = 0.0;   // deepest penetration over all control periods [m]
  double max_penetration_initial = 0.0;  // deepest penetration at t = 0 [m]
  bool has_box = false;           // the scene has an obstacle: stair events below
  simloop::StairEvents stair;     // its first box's (simloop/stair_events.hpp), checked every 10 ms
  model::IntegratorStats stats;   // plant integrator counters
  double wall_s = 0.0;            // wall time of the simulation loop [s]
  std::filesystem::path csv;      // where the trajectory went
  model::Scene scene;             // the scene as the plant resolved it (boxes placed) for plots
};

// Runs the scene for its duration; writes out_dir/trajectory.csv as it goes (flushed on failure
// too). A plant failure (non-finite state, singular mass matrix) stops the run: the rows so far
// stay written and result.status says why. Throws std::runtime_error on an output error.
RunResult run(const RunConfig& c);

// The summary text (also written to out_dir/summary.txt by the CLI).
std::string summary_text(const RunConfig& c, const RunResult& r);

// Figures: writes body.csv (every sample's body points, COM and head tip) and figures.json (title,
// gait period, average speed, the scene's ground, boxes and μ patches) into out_dir and runs
// tools/figures/simulate.py on them: shapes (snake snapshots over time), gait_cycle, paths (head
// tip and COM), torques (SEA and commanded, one panel per joint), speed (.png). Returns what was
// drawn, or why not (no matplotlib: the data stay).
toolkit::FigureOutcome write_plots(const RunConfig& c, const RunResult& r);

}  // namespace pedalwave::simulate
