// The work-precision study behind pedalwave_workprec: runs of one scene with one integrator,
// sampled every control period, compared against a tight dopri45 reference.
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "pedalwave/model/integrators.hpp"
#include "pedalwave/model/scene.hpp"

namespace pedalwave::workprec {

// One simulated run: the scene in closed loop (gait controller at `rate_hz`, module-side PD) or
// open loop (zero commands), integrated with `integ` for `duration` seconds.
struct RunSpec {
  model::Scene scene;
  bool closed_loop = true;
  double rate_hz = 1000.0;      // control rate = sample rate [Hz]
  double duration = 10.0;       // simulated time [s]
  model::IntegratorOptions integ;
  std::uint64_t max_evaluations = 0;  // stop as kFailed ("too costly") beyond this; 0 = no cap
};

// Samples every control period (and at t = 0).
struct Trajectory {
  int joints = 0;                 // N−1 [-]
  std::vector<double> t;          // sample times [s], (n)
  std::vector<double> com_x;      // whole-robot COM x [m], (n)
  std::vector<double> com_z;      // whole-robot COM z [m], (n)
  std::vector<double> alpha;      // joint angles α [rad], (n·(N−1)), sample-major
};

enum class RunStatus : std::uint8_t { kOk, kUnstable, kFailed };
const char* to_string(RunStatus s);

struct RunResult {
  RunStatus status = RunStatus::kOk;
  std::string why;                // for kUnstable/kFailed: the step status or the blow-up
  double t_fail = 0.0;            // simulated time reached [s]
  double wall_s = 0.0;            // wall time of the run [s] (median over repeats)
  double cpu_s = 0.0;             // CPU time of the run's thread [s] (median over repeats)
  std::uint64_t evaluations = 0;  // acceleration / implicit-term evaluations [-]
  std::uint64_t steps = 0;        // accepted steps [-]
  std::uint64_t rejected = 0;     // rejected (adaptive) steps [-]
  Trajectory traj;                // empty unless recorded
};

// Runs `spec` once; records the trajectory when `record`. A NaN/Inf or a blow-up (|q̇|∞ > 1e3, far
// beyond any motion of this robot) ends the run as kUnstable; an adaptive step below h_min, a
// failed evaluation or the evaluation cap as kFailed — never a crash.
RunResult run_once(const RunSpec& spec, bool record);

// Errors of a run against a reference sampled at the same times.
struct Errors {
  double com_final = 0.0;  // |COM(T) − COM_ref(T)| [m]
  double com_max = 0.0;    // max over samples of |COM − COM_ref| [m]
  double alpha_max = 0.0;  // max over samples and joints of |α − α_ref| [rad]
};
Errors compare(const Trajectory& run, const Trajectory& ref);

// The fidelity study's model variants (applied to a scene by index; 0 = the scene as shipped).
struct Variant {
  std::string name;
  std::function<void(model::Scene&)> apply;
};
const std::vector<Variant>& fidelity_variants();

// ---- a run as one line of text (a campaign's specification and result; pedalwave::campaign) ------
// The specification: the scene's YAML text (what spec.scene was read from, by config::parse_scene;
// only its fidelity variant and the fields of RunSpec differ), the variant index, every field of
// RunSpec, whether to record the trajectory and the timing repeats; doubles exact (hex floats).
std::string encode_spec(const RunSpec& spec, const std::string& scene_name, const std::string& scene_text,
                        int variant, bool record, int repeats);
// The runner: run_once (repeated for timing: runs under 1 s CPU `repeats` times, the median wall
// and CPU time, the first run's results) → encode_result. Everything but wall_s and cpu_s depends
// only on the specification (bit-identical on any backend).
std::string run_line(const std::string& spec);
std::string encode_result(const RunResult& r);
RunResult decode_result(const std::string& line);

}  // namespace pedalwave::workprec
