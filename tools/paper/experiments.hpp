// The paper reproduction's engine (pedalwave_paper): one closed-loop run of a scene with the
// runtime's controller (simloop::ClosedLoop: the controller sees only β, β̇ and the deflection),
// the measures the paper reports (average forward speed, head-tip crossing, SEA torque peaks,
// stair-climb events) and a thread pool that runs many independent runs over the cores.
//
// Conventions: the robot walks toward +X, the head tip (point 2N) leads; the "head joint" is the
// joint next to the head, joint N−1 (0-based index N−2). Average forward speed is
//   v̄ = (x_COM(T) − x_COM(t_0)) / (T − t_0),   t_0 = one gait period 2π/ω (2 s for the paper's ω),
// x_COM the whole-robot centre of mass (links and rotors). Runs are deterministic: a run depends
// only on its RunSpec, never on the thread that executes it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "pedalwave/campaign/campaign.hpp"
#include "pedalwave/model/integrators.hpp"
#include "pedalwave/model/scene.hpp"
#include "pedalwave/simloop/stair_events.hpp"

namespace pedalwave::paper {

inline constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// One closed-loop run.
struct RunSpec {
  model::Scene scene;              // the scene; its duration is the run's length [s]
  double k_c = 0.0;                // adaptive admittance gain [-] (0: open-loop gait)
  model::IntegratorOptions integ;  // plant integrator
  double rate_hz = 1000.0;         // control rate [Hz]
  double sample_every = 0.0;       // trace sample period [s], a multiple of 1/rate; 0 = no trace
  double cross_x = kNaN;           // record when the head tip first reaches x ≥ cross_x [m]; NaN = no
  double avg_from = kNaN;          // start of the speed average t_0 [s]; NaN = one gait period
};

// Samples every RunSpec::sample_every (n samples).
struct Trace {
  std::vector<double> t;                        // [s], (n)
  std::vector<double> com_x, com_z;             // whole-robot COM [m], (n)
  std::vector<double> head_x, head_z;           // head tip (point 2N) [m], (n)
  std::vector<double> tail_x, tail_z;           // tail tip (point 0) [m], (n)
  std::vector<double> tau_head;                 // SEA torque K(β − α) of the head joint [N·m], (n)
  std::vector<double> eta_head;                 // spatial frequency η of the head joint [rad], (n)
  std::vector<std::vector<double>> body_x;      // [sample][point] the 2N+1 body points [m]
  std::vector<std::vector<double>> body_z;      // [sample][point] [m]
};

// Stair events (first box of the scene): simloop/stair_events.hpp, shared with pedalwave_sim.
using simloop::kOnTopAbove;
using simloop::kOnTopBelow;
using simloop::StairEvents;

struct RunResult {
  model::StepStatus status = model::StepStatus::kOk;  // kOk or the plant failure that stopped it
  double t_end = 0.0;          // plant time reached [s]
  double avg_from = 0.0;       // t_0 of the speed average [s]
  double avg_speed = kNaN;     // v̄ over [t_0, t_end] [m/s] (NaN if the run ended before t_0)
  double com_x_final = kNaN;   // [m]
  double t_head_cross = kNaN;  // head tip first x ≥ cross_x [s]
  StairEvents stair;           // when the scene has a box
  double cpu_s = 0.0;          // CPU time of this run's thread [s]
  double wall_s = 0.0;         // wall time [s]
  std::uint64_t steps = 0;     // plant steps
  Trace trace;                 // when sample_every > 0
  model::Scene resolved;       // the scene as the plant placed it (boxes at absolute x)
};

// Runs spec.scene for its duration. Throws std::invalid_argument for an invalid scene,
// integrator or sample period; a plant failure is reported in status (the measures then cover
// the time reached).
RunResult run(const RunSpec& spec);

// Runs of `base` at each of `k_c` (the k_c sweep's members: the same scene, integrator and rate,
// only the adaptive gain differs), in run()'s order of results. Stepped in lockstep, their plants'
// arithmetic in SIMD lanes (model::LanePlant, LaneStepper: each member's controller, commands,
// Jacobian refreshes and Newton iterations its own), when `lanes` is true, the machine has AVX2 or
// AVX-512, the scene is one LanePlant runs and the integrator is implicit_contact; else each with
// run(). In lanes a member's step is run()'s to rounding (tests/model/lanes_test.cpp), its result
// too over a few seconds (tests/tools/paper/paper_test.cpp, '*Group*'); over 60 s a run sensitive
// to rounding can drift further (the sweep: ≤ 0.022 mm of COM, README "The k_c sweep in lockstep
// SIMD lanes"). A member's result does not depend on its group. cpu_s and wall_s: the group's,
// shared equally.
std::vector<RunResult> run_group(const RunSpec& base, const std::vector<double>& k_c, bool lanes = true);
// Whether run_group steps `base` in lanes on this machine, or why not ("" = it does).
std::string lockstep_refusal(const RunSpec& base);

// Gait period 2π/|ω| of a scene [s].
double gait_period(const model::Scene& s);

// Negative peaks of a signal: samples i with y[i] < 0 that are the minimum of y over
// [t_i − window/2, t_i + window/2] (one per gait period for window = the gait period).
// Returns indices in ascending time.
std::vector<std::size_t> negative_peaks(const std::vector<double>& t, const std::vector<double>& y,
                                        double window);

// The tools' one thread pool (pedalwave::campaign): f(i) for i = 0 … n−1 on `jobs` threads, the
// first exception rethrown; default_jobs() = the hardware threads.
using campaign::default_jobs;
using campaign::parallel_for;

// ---- a run as one line of text (a campaign's specification and result) ------------------------------
// The specification: the scene's YAML text (`scene_text`, what spec.scene was read from; only its
// duration may differ) and every other field of spec, doubles as hex floats (exact). Throws
// std::invalid_argument for text with a newline it cannot hold.
std::string encode_spec(const RunSpec& spec, const std::string& scene_name, const std::string& scene_text);
// Back: the scene parsed from the text (config::parse_scene), its duration set. Throws
// std::invalid_argument / config::ConfigError naming the field.
RunSpec decode_spec(const std::string& line);
// Every scalar of a result (not the trace nor the resolved scene), exact.
std::string encode_result(const RunResult& r);
RunResult decode_result(const std::string& line);
// A group of runs (run_group) as one specification line: encode_spec's fields and the gains
// (kind paper.group); its result line holds every member's encode_result.
std::string encode_group(const RunSpec& base, const std::vector<double>& k_c, bool lanes,
                         const std::string& scene_name, const std::string& scene_text);
std::vector<RunResult> decode_group_result(const std::string& line);
// The campaign's runner: encode_result(run(decode_spec(line))) for a run, the members' results of
// run_group for a group.
std::string run_line(const std::string& line);

}  // namespace pedalwave::paper
