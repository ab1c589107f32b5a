// Joint identification against target figures (pedalwave_identify fit): the parameters of a
// parameter file, within their bounds, fitted to the figures of a target file by a derivative-free
// optimizer (NLopt: a batch of quasi-random starts, then LN_BOBYQA from the best), each evaluation's
// simulations run as a campaign (pedalwave::campaign: local threads or Slurm) and cached. At the
// fit: each target's residual, the sensitivities (central finite differences, one batch) and how
// well each parameter is determined (singular values of the residual Jacobian, approximate
// standard deviations, correlated pairs, undetermined directions).
#pragma once

#include <cmath>
#include <filesystem>
#include <map>
#include <mutex>
#include <string>
#include <vector>

#include "params.hpp"
#include "pedalwave/campaign/campaign.hpp"
#include "pedalwave/toolkit/json.hpp"

namespace pedalwave::identify {

// Lengths of the simulations (the paper's: flat 20 s, friction 30 s, stair 60 s).
struct Horizon {
  double flat = 20, friction = 30, stair = 60;
};

struct FitSettings {
  std::filesystem::path scenes_dir;          // flat_high_friction, flat_low_friction, friction_change, stair
  std::string stair_scene = "stair";
  Horizon horizon;
  int starts = 8;          // quasi-random starts evaluated as one batch before the local search
  int max_evals = 60;      // local search evaluations per choice combination
  double xtol = 1e-3;      // local search: stop when the normalized step falls below this
  double fd_step = 0.02;   // finite differences: step in the normalized [0, 1] coordinate
  std::filesystem::path cache_file;  // evaluations cache (appended); empty = in memory only
  campaign::Options campaign;
  bool progress = true;
  std::ostream* log = nullptr;  // progress lines; nullptr = none
};

// The simulations of one parameter set: scene runs as one-line campaign specifications.
// run_line is the campaign's runner (and the Slurm worker's): a specification → its measures.
std::string run_line(const std::string& spec);

// The measures of one parameter set (NaN where a run failed or a figure is undefined).
struct Measures {
  double v_flat_high = NAN, v_flat_low = NAN, peak_change = NAN, v_stair0 = NAN, v_stair_kc = NAN;
  double t_body_past0 = NAN, t_body_past_kc = NAN;  // stair: whole body past the box [s]
  int peaks_before = 0, peaks_after = 0;
  [[nodiscard]] double get(Measure m) const;
};

// A point: one value per FitParam (continuous: the value in its unit; choice: the index).
using Point = std::vector<double>;

class Evaluator {
 public:
  Evaluator(std::vector<FitParam> params, Targets targets, FitSettings settings);
  // The measures of many points, every simulation not in the cache run as one campaign.
  std::vector<Measures> evaluate(const std::vector<Point>& points, const std::string& label);
  // Residuals r_i = (measure − value) / tolerance; a NaN measure gives kFailedResidual.
  [[nodiscard]] std::vector<double> residuals(const Measures& m) const;
  static constexpr double kFailedResidual = 1e3;
  [[nodiscard]] const std::vector<FitParam>& params() const { return params_; }
  [[nodiscard]] const Targets& targets() const { return targets_; }
  [[nodiscard]] const FitSettings& settings() const { return settings_; }
  [[nodiscard]] std::size_t simulations_run() const { return sims_run_; }
  [[nodiscard]] std::size_t cache_hits() const { return cache_hits_; }
  [[nodiscard]] std::size_t evaluations() const { return evaluations_; }
  // The base scenes with a point applied (name → scene YAML text), for the fitted scene files.
  [[nodiscard]] std::vector<std::pair<std::string, std::string>> fitted_scene_yaml(const Point& p) const;
  // The start point (the scenes' values unless the file gives a start).
  [[nodiscard]] Point start_point(const std::vector<int>& choice) const;

 private:
  std::vector<std::string> specs_of(const Point& p) const;
  std::vector<FitParam> params_;
  Targets targets_;
  FitSettings settings_;
  std::map<std::string, std::string> scene_text_;  // name → YAML text
  std::map<std::string, std::string> cache_;       // spec hash → result
  std::size_t sims_run_ = 0, cache_hits_ = 0, evaluations_ = 0, batches_ = 0;
};

struct ParamReport {
  std::string name, unit;
  double value = 0;              // at the fit (choice: the index)
  std::string word;              // choice: the word
  double lo = 0, hi = 0;
  bool at_bound = false;         // within 1 % of the range of a bound
  double sigma_lo = NAN, sigma_hi = NAN;  // ±1σ interval (approximate; NaN = undetermined)
  std::vector<double> sensitivity;  // d measure / d(10 % of the parameter) per target (log: ×1.1)
};

struct FitResult {
  Point best;
  double cost = 0;  // ½ Σ r²
  Measures measures;
  std::vector<double> residuals;
  std::vector<ParamReport> params;  // continuous and choice
  std::vector<double> singular_values;
  std::vector<std::string> correlated;   // "K ~ I_r: ρ = −0.97"
  std::vector<std::string> undetermined; // directions of the null space, by their largest components
  std::vector<std::pair<std::string, double>> combos;  // each choice combination's best cost
  std::size_t evaluations = 0, simulations = 0, cache_hits = 0;
  std::string nlopt_status;
};

FitResult fit(Evaluator& ev);
// Sensitivities and determinacy at p (one batch of 2·p central differences).
void analyse(Evaluator& ev, FitResult& r);

toolkit::Json to_json(const Evaluator& ev, const FitResult& r);
std::string report_text(const Evaluator& ev, const FitResult& r);

}  // namespace pedalwave::identify
