// The paper's experiments (model-spec.md §9), each a function that runs, writes its figures' data
// (drawn by tools/figures/paper.py) and a Markdown fragment (from its template in
// tools/paper/report/) into Settings::out_dir, prints its numbers and returns them:
//   flat         average forward speed at μ = 0.82 and μ = 0.40, their ratio
//   friction     head-joint SEA torque over the friction change (the paper's Fig. 7), peak change
//   stair        k_c = 0 against k_c = 10.1 over the stair: climb events, speed, shapes (Fig. 10)
//   sweep        average speed against k_c over the stair (Fig. 9), best k_c, gain, accuracy check
//   sensitivity  how the above move with the unpublished K and I_r (and two model options)
//   all          everything and paper_table.md (paper's experiment | paper's simulation | ours)
// Numbers are never hard-coded: the paper's values appear only as the reference column (in the
// report's templates, tools/paper/report/*.md.in; PaperValues below for the fitted notes).
#pragma once

#include <optional>

#include <cstddef>
#include <filesystem>
#include <iosfwd>
#include <string>
#include <vector>

#include "experiments.hpp"

namespace pedalwave::paper {

// The paper's reported values (model-spec.md §9), for the comparison column only.
struct PaperValues {
  static constexpr double kFlatSpeedExp = 0.0240;      // μ = 0.82, experiment [m/s]
  static constexpr double kFlatSpeedSim = 0.0218;      // μ = 0.82, the paper's simulation [m/s]
  static constexpr double kFrictionGainExp = 0.203;    // v(0.82)/v(0.40) − 1, experiment [-]
  static constexpr double kFrictionGainSim = 0.137;    // same, simulation [-]
  static constexpr double kPeakChangeExp = 0.043;      // torque-peak change, experiment [-]
  static constexpr double kPeakChangeSim = 0.163;      // same, simulation [-]
  static constexpr double kStairSpeedExp = 0.013;      // stair, k_c = 10.1, experiment [m/s]
  static constexpr double kStairSpeedSim = 0.0213;     // stair, k_c = 10.1, simulation (≈) [m/s]
  static constexpr double kStairGainSim = 0.248;       // k_c = 10.1 over k_c = 0, simulation [-]
  static constexpr double kBestKc = 10.1;              // the paper's best k_c [-]
};

// What every experiment shares.
struct Settings {
  std::filesystem::path scenes_dir;          // folder of the shipped scenes (config/scenes)
  std::filesystem::path out_dir = "out/paper";  // figures and Markdown go here (created)
  // Plant integrator for every run; unset = each scene's own (its `integrator:`, chosen by the
  // work-precision study to stay within 1 mm of the reference: tools/workprec/README.md).
  std::optional<model::IntegratorOptions> integ;
  // Prepended to every scene name (not to a path): "paper_fit_" runs the identification's fitted
  // scenes (config/scenes/paper_fit_*.yaml) in place of the shipped assumptions.
  std::string scene_prefix;
  std::string stair_scene = "stair";         // the box scene of `stair` and `sweep` (`all` also runs
                                             // "stair_grip", the calibrated edge friction, into
                                             // out_dir/stair_grip)
  double rate_hz = 1000.0;                   // control rate [Hz]
  int jobs = 1;                              // worker threads for independent runs
  // Where the sweep's runs go (pedalwave::campaign): backend local (jobs threads, the default) or
  // slurm (job arrays; campaign folders under campaign.slurm.dir, empty = out_dir/campaign). Its
  // jobs and progress are this struct's.
  campaign::Options campaign;
  // The sweep's runs 8 at a time in lockstep, their plants in SIMD lanes (run_group), where the
  // machine and the scene allow; false: one by one on the scalar plant.
  bool lanes = true;
  // The sweep's runs per lockstep group, one campaign item each (1: every run its own item).
  int group = 8;
  bool progress = true;                      // progress bars on stderr
  bool plots = true;                         // write figures
  std::ostream* log = nullptr;               // printed numbers (nullptr = std::cout)
};

// Loads config/scenes/<name>.yaml from settings.scenes_dir.
// The file of scene `name`: a path as given when it names a folder or ends in .yaml, else
// <scenes_dir>/<name>.yaml.
std::filesystem::path scene_file(const Settings& s, const std::string& name);
model::Scene load(const Settings& s, const std::string& name);

// The integrator a run of this scene uses: Settings::integ if set, else the scene's own.
model::IntegratorOptions integ_of(const Settings& s, const model::Scene& scene);

// ---- flat ----------------------------------------------------------------------------------------
struct FlatResult {
  double duration = 0.0;     // [s]
  double avg_from = 0.0;     // t_0 of the speed average [s]
  double v_high = kNaN;      // μ = 0.82 [m/s]
  double v_low = kNaN;       // μ = 0.40 [m/s]
  double ratio = kNaN;       // v_high / v_low [-]
  double gain = kNaN;        // ratio − 1 [-]
  std::string markdown;      // also written to out_dir/flat.md
};
FlatResult flat(const Settings& s, double duration = 60.0);

// ---- friction ------------------------------------------------------------------------------------
struct FrictionResult {
  double duration = 0.0;        // [s]
  double cross_x = 0.0;         // where μ changes [m]
  double t_cross = kNaN;        // head tip first reaches cross_x [s]
  std::vector<double> peak_t_before, peak_before;  // negative peaks before the crossing [s], [N·m]
  std::vector<double> peak_t_after, peak_after;    // after it [s], [N·m]
  double mean_before = kNaN;    // mean |peak| before (first gait period excluded) [N·m]
  double mean_after = kNaN;     // mean |peak| after [N·m]
  double change = kNaN;         // mean_after / mean_before − 1 [-]
  std::string markdown;         // also out_dir/friction.md
};
// duration ≤ 0: the scene's.
FrictionResult friction(const Settings& s, double duration = 0.0);

// ---- stair ---------------------------------------------------------------------------------------
struct StairCase {
  double k_c = 0.0;
  RunResult run;                // with trace
};
// The same comparison over lower boxes: which height the robot can climb.
struct StairHeight {
  double height = 0.0;          // box height [m]
  std::vector<double> speed;    // per k_c of StairResult::cases [m/s]
  std::vector<double> t_body_past;  // per k_c: whole body past the box [s] (NaN = never)
};
struct StairResult {
  double duration = 0.0;        // [s]
  std::vector<StairCase> cases;
  std::vector<StairHeight> heights;  // box-height scan (empty when not asked)
  std::string markdown;         // also out_dir/stair.md
};
// heights: box heights [m] for the scan (each run for every k_c, no trace); empty = none.
StairResult stair(const Settings& s, double duration = 60.0, std::vector<double> k_c = {0.0, 10.1},
                  double snapshot_every = 1.5, std::vector<double> heights = {0.03, 0.04, 0.05, 0.06});

// ---- sweep ---------------------------------------------------------------------------------------
struct SweepOptions {
  double from = 0.0, to = 15.0, step = 0.1;  // k_c grid [-]
  double duration = 60.0;                    // per run [s]
  int checks = 4;              // k_c values re-run at check_h (0 = none): k_c = 0, the best,
                               // the paper's 10.1 (if in range), the middle of the grid
  double check_h = 1e-4;       // finer integrator step for the accuracy check [s]
};
struct SweepPoint {
  double k_c = 0.0;
  double speed = kNaN;         // v̄ [m/s]
  StairEvents stair;
  model::StepStatus status = model::StepStatus::kOk;
  double cpu_s = 0.0;          // [s]
};
struct SweepCheck {
  double k_c = 0.0;
  double speed = kNaN;         // at the sweep's integrator [m/s]
  double speed_fine = kNaN;    // at check_h [m/s]
};
struct SweepResult {
  SweepOptions options;
  std::vector<SweepPoint> points;
  std::size_t best = 0;        // index of the highest speed (ties: the smallest k_c)
  double v0 = kNaN;            // speed at k_c = 0 [m/s] (a grid point, or an extra run)
  double gain = kNaN;          // points[best].speed / v0 − 1 [-]
  double wall_s = 0.0;         // wall time of the grid runs [s] (slurm: submission to gathering)
  double cpu_s = 0.0;          // summed CPU time of the grid runs [s]
  double realtime_factor = 0.0;  // simulated seconds (all runs) per wall second
  int jobs = 1;
  std::vector<SweepCheck> checks;
  std::string markdown;        // also out_dir/sweep.md
};
// k_c values from, from + step, … ≤ to (+ step/1000), rounded to 1e-9. Throws on step ≤ 0 or to < from.
std::vector<double> sweep_grid(double from, double to, double step);
// Index of the maximum finite speed (ties: the first); points.size() if none is finite.
std::size_t best_index(const std::vector<SweepPoint>& points);
SweepResult sweep(const Settings& s, const SweepOptions& o);

// ---- sensitivity ---------------------------------------------------------------------------------
struct SensitivityOptions {
  std::vector<double> K{1, 3, 10, 30, 100};     // SEA stiffness values [N·m/rad]
  std::vector<double> I_r{1e-8, 5e-8, 2e-7};    // rotor inertia values [kg·m²]
  bool model_options = true;   // also: friction at the link COMs only; v_s = 1e-4
  double flat_duration = 60.0, friction_duration = 0.0, stair_duration = 60.0;  // [s]
  double k_c = 10.1;           // adaptive gain of the stair's second run
};
struct SensitivityRow {
  std::string parameter;       // "K", "I_r", "baseline", or a model option
  std::string value;           // as printed
  double v_high = kNaN, v_low = kNaN, gain = kNaN;  // flat [m/s], [-]
  double peak_change = kNaN;   // friction [-]
  double stair_v0 = kNaN, stair_vkc = kNaN;         // stair k_c = 0 and k_c [m/s]
  double stair_gain = kNaN;    // stair_vkc / stair_v0 − 1 [-]
  int peaks_before = 0, peaks_after = 0;            // friction: peaks on either side of the crossing
  double past0 = kNaN, pastkc = kNaN;               // whole body past the box [s] (NaN = never)
  double top0 = kNaN, topkc = kNaN;                 // head on top [s] (NaN = never)
};
struct SensitivityResult {
  SensitivityOptions options;
  std::vector<SensitivityRow> rows;  // baseline first
  std::string markdown;        // also out_dir/sensitivity.md
};
SensitivityResult sensitivity(const Settings& s, const SensitivityOptions& o);

// ---- all -----------------------------------------------------------------------------------------
struct AllOptions {
  double flat_duration = 60.0, friction_duration = 0.0, stair_duration = 60.0;
  SweepOptions sweep;
  SensitivityOptions sensitivity;
  // The fitted scenes (pedalwave_identify fit --write-scenes): flat, friction, stair and sweep run
  // again with this scene prefix into out_dir/paper_fit, when --scenes has all four files; empty = not.
  std::string fitted_prefix = "paper_fit_";
};
// The same experiments on another scene set (AllOptions::fitted_prefix), for the second table.
struct FittedResult {
  std::string prefix;          // "paper_fit_"
  std::string parameters;      // the fitted values, as one line
  FlatResult flat;
  FrictionResult friction;
  StairResult stair;
  SweepResult sweep;
};
struct AllResult {
  FlatResult flat;
  FrictionResult friction;
  StairResult stair;
  SweepResult sweep;
  StairResult stair_grip;      // the same on "stair_grip" (out_dir/stair_grip)
  SweepResult sweep_grip;
  SensitivityResult sensitivity;
  std::optional<FittedResult> fitted;  // the fitted scenes (unset: not run)
  std::string table;           // out_dir/paper_table.md
  std::size_t table_rows = 0;  // rows of the comparison table
  std::size_t fitted_rows = 0; // rows of the fitted scenes' table (0: none)
};
AllResult all(const Settings& s, const AllOptions& o);

// The comparison table (Markdown, with a sentence per difference) from the results: the templates
// tools/paper/report/table.md.in and fitted.md.in filled with the computed values
// (toolkit::TemplateError naming the template's line when they disagree).
// With r.fitted, a second table follows: the paper's simulation, the shipped scenes and the fitted
// ones side by side (fitted_rows: its rows).
std::string paper_table(const AllResult& r, std::size_t* rows = nullptr, std::size_t* fitted_rows = nullptr);

}  // namespace pedalwave::paper
