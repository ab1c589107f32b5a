// The identification's parameters and targets (pedalwave_identify, tools/identify/README.md).
//
// Every scene parameter the tool can fit is one row of kParameterTable (params.cpp): its name, unit,
// where it lives in a scene file (section.key), whether it is searched on a log scale, and how it is
// applied to a model::Scene. A new scene parameter is one more row (the module size, link_shape and
// module_size, is the latest). A parameter is continuous (bounded) or a choice among words (friction
// law, where friction acts): choices are enumerated, the continuous ones fitted for each.
//
// A fit's parameter file (YAML) says which parameters, their plausible bounds and the reason for
// each bound; a target file says which figures to reproduce, their values and the tolerance each
// residual is measured in.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "pedalwave/model/scene.hpp"

namespace pedalwave::identify {

struct ParamDef {
  std::string name;          // as in the parameter file, e.g. "K"
  std::string unit;          // for reports
  std::string section, key;  // where a scene file holds it: robot.K
  bool log_scale = false;    // searched in log(value) (positive, spans decades)
  std::vector<std::string> choices;  // non-empty: a word, the index into choices is the value
  std::function<void(model::Scene&, double)> apply;       // value (or choice index) → scene
  std::function<double(const model::Scene&)> get;         // scene → value (or choice index)
  std::string description;
};

// The table (rows in a fixed order; names unique).
const std::vector<ParamDef>& parameter_table();
// The row named `name`; throws std::invalid_argument listing the known names.
const ParamDef& find_param(const std::string& name);

// One parameter of a fit.
struct FitParam {
  const ParamDef* def = nullptr;
  double lo = 0, hi = 0;        // bounds (continuous) [unit]
  double start = 0;             // start value; NaN = the scene's
  std::vector<int> choices;     // choice parameters: the indices allowed
  std::string reason;           // why these bounds (the file's text)
  [[nodiscard]] bool is_choice() const { return !def->choices.empty(); }
};

// Reads a parameter file:
//   parameters:
//     - {name: K, min: 0.5, max: 30, reason: "..."}            # continuous, start = the scene's
//     - {name: I_r, min: 1e-8, max: 1e-6, start: 5e-8, reason: "..."}
//     - {name: friction_law, choices: [regularized, tanh], reason: "..."}
// Errors (config::ConfigError) name the file, line, key, value and what was expected (an unknown
// parameter lists the table's names; min ≥ max, a log parameter with min ≤ 0, an unknown word).
std::vector<FitParam> load_params(const std::string& file);

// A figure to reproduce and how it is computed from the runs (Measure).
enum class Measure { flat_speed, friction_gain, torque_peak_change, stair_speed, stair_gain };
const char* to_string(Measure m);

struct Target {
  Measure measure = Measure::flat_speed;
  double value = 0;      // the figure [m/s or a ratio: 0.137 = +13.7 %]
  double tolerance = 0;  // residual unit: r = (model − value) / tolerance  (> 0)
  std::string source;    // where the figure comes from
};
struct Targets {
  std::vector<Target> list;
  double k_c = 10.1;     // the adaptive gain of the stair targets
};
// Reads a target file:
//   k_c: 10.1
//   targets:
//     - {measure: flat_speed, value: 0.0218, tolerance: 0.001, source: "paper §9, simulation"}
Targets load_targets(const std::string& file);

}  // namespace pedalwave::identify
