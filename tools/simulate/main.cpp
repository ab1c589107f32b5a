// pedalwave_sim — run a scene in closed loop and show what happened.
//
//   pedalwave_sim SCENE.yaml [--duration s] [--controller none|gait] [--k_c X] [--rate Hz]
//                 [--integrator NAME] [--h s] [--rtol x] [--out DIR] [--every s] [--no-plots]
//
// Writes DIR/trajectory.csv, DIR/summary.txt (also printed), the figures' data DIR/body.csv and
// DIR/figures.json, and the figures DIR/{shapes,gait_cycle,paths,torques,speed}.png (drawn by
// tools/figures/simulate.py; skipped with a message without matplotlib). Exit codes: 0 done; 2 bad input (scene file, YAML, option value; one
// error line on stderr); 3 the plant failed (non-finite state / singular mass matrix): the rows up
// to the failure are written, the summary says why; 1 any other error (e.g. cannot write DIR).
#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/model/stability.hpp"
#include "pedalwave/simloop/plant_checks.hpp"
#include "pedalwave/toolkit/cli.hpp"
#include "sim_run.hpp"

namespace {

namespace cli = pedalwave::toolkit::cli;
constexpr const char* kTool = "pedalwave_sim";

int bad_input(const std::string& what) { return cli::bad_input(kTool, what); }

const CLI::Validator kPositive = cli::finite_positive();

}  // namespace

int main(int argc, char** argv) {
  namespace sim = pedalwave::simulate;
  namespace model = pedalwave::model;

  CLI::App app{"pedalwave_sim: simulate a scene (the runtime's gait controller against the plant "
               "model, in lockstep) and write trajectory.csv, summary.txt and figures (tools/figures/simulate.py)"};
  std::string scene_path;
  std::optional<double> duration, h, rtol;
  std::optional<std::string> integrator;
  std::string controller = "gait";
  double k_c = 0.0, rate = 1000.0, every = 0.01;
  std::string out;
  bool no_plots = false, quiet = false;
  app.add_option("scene", scene_path, "scene file (YAML), e.g. config/scenes/flat_high_friction.yaml")
      ->required();
  app.add_option("--duration", duration, "simulated time [s] (default: the scene's)")
      ->check(kPositive);
  app.add_option("--controller", controller, "gait: the runtime's gait + adaptive + PD controller; "
                 "none: passive robot (zero motor commands)")
      ->check(CLI::IsMember({"none", "gait"}))
      ->capture_default_str();
  app.add_option("--k_c", k_c, "adaptive admittance gain k_c (0 = open-loop gait)")
      ->check(cli::finite_in(-1e3, 1e3))
      ->capture_default_str();
  app.add_option("--rate", rate, "control rate [Hz]")->check(kPositive)->capture_default_str();
  app.add_option("--integrator", integrator,
                 "euler | semi_implicit_euler | implicit_velocity | rk4 | dopri45 | implicit_contact (default: the scene's)");
  app.add_option("--h", h, "integrator step (initial step for dopri45) [s], ≤ the control period")
      ->check(cli::finite_in(1e-7, 0.1));
  app.add_option("--rtol", rtol, "relative tolerance of dopri45 (only with dopri45)")->check(cli::finite_in(1e-14, 1));
  app.add_option("--out", out, "output folder (default: sim_out/<scene name>)");
  app.add_option("--every", every, "CSV/plot sample period [s], a multiple of 1/rate")
      ->check(kPositive)
      ->capture_default_str();
  app.add_flag("--no-plots", no_plots, "write no figures");
  app.add_flag("--quiet", quiet, "no progress bar, no printed summary");
  if (const auto rc = cli::parse(app, argc, argv, kTool)) return *rc;

  // Scene and overrides: every problem here is bad input (exit 2, one line).
  sim::RunConfig cfg;
  try {
    // pedalwave_sim injects no faults: a scene with a faults: list is refused, not run fault-free.
    cfg.scene = pedalwave::config::load_scene(scene_path, {.faults = false, .consumer = kTool});
    if (cfg.scene.source.empty()) cfg.scene.source = scene_path;
    if (duration) cfg.scene.duration = *duration;
    cfg.integ = cfg.scene.integrator;
    if (integrator) cfg.integ.method = model::parse_method(*integrator);
    if (h) cfg.integ.h = *h;
    if (rtol && !model::is_adaptive(cfg.integ.method))
      throw std::invalid_argument("--rtol " + std::to_string(*rtol) + ": expected --integrator dopri45 (the "
                                  "tolerance of the adaptive method; the integrator is " +
                                  std::string(model::to_string(cfg.integ.method)) + ")");
    if (rtol) cfg.integ.rtol = *rtol;
    // The plant advances one control period per step of the loop: a longer step is never taken
    // (the summary would say h = 10 s while 1 ms steps ran). The daemon's simulated plant applies
    // the same rule (simloop/plant_checks.hpp).
    if (const std::string why = pedalwave::simloop::step_problem(cfg.integ, rate); !why.empty()) {
      std::ostringstream os;
      os << (h ? "--h " : cfg.scene.source + ": integrator.h = ") << cfg.integ.h << ": " << why;
      throw std::invalid_argument(os.str());
    }
    model::validate(cfg.integ);
    model::validate(cfg.scene);
    cfg.loop.rate_hz = rate;
    cfg.loop.controller = controller == "gait";
    cfg.loop.k_c = k_c;
    cfg.every = every;
    cfg.out_dir = out.empty() ? std::filesystem::path("sim_out") / cfg.scene.name : std::filesystem::path(out);
    cfg.plots = !no_plots;
    cfg.progress = !quiet;
    sim::validate(cfg);
    if (cfg.loop.controller)  // the controller's own checks (gains, rate, stability)
      (void)pedalwave::control::GaitController(
          pedalwave::simloop::controller_params(cfg.scene, rate, k_c));
  } catch (const std::exception& e) {
    return bad_input(e.what());
  }

  try {
    const sim::RunResult r = sim::run(cfg);
    const bool failed = r.status != model::StepStatus::kOk;
    std::string summary = sim::summary_text(cfg, r);
    // A run that went numerically wrong: the stability limit of the scene's fastest mode and a
    // step that would work (model/stability), in the summary and on stderr.
    std::string advice;
    if (failed) {
      const auto gains = cfg.loop.controller ? model::ControlGains{} : model::ControlGains{0.0, 0.0};
      advice = pedalwave::simloop::stability_advice(cfg.scene, gains, cfg.integ, cfg.scene.duration);
      summary += "stability:        " + advice + "\n";
    }
    {
      std::ofstream f(cfg.out_dir / "summary.txt");
      f << summary;
      if (!f) throw std::runtime_error("cannot write " + (cfg.out_dir / "summary.txt").string());
    }
    if (!quiet) std::cout << summary;
    if (cfg.plots) {
      const auto figures = sim::write_plots(cfg, r);
      if (figures.status == pedalwave::toolkit::FigureOutcome::Status::drawn) {
        if (!quiet) std::cout << "figures:          " << figures.message << '\n';
      } else {  // loudly, also with --quiet: the data are written, the figures are not
        std::cerr << "pedalwave_sim: " << figures.message << '\n';
      }
    }
    if (failed) {
      std::cerr << "pedalwave_sim: the plant failed at t = " << r.t_end << " s: "
                << model::to_string(r.status) << " (rows up to then are in " << r.csv.string()
                << "); " << advice << '\n';
      return cli::kExitNumerical;
    }
  } catch (...) {
    return cli::exit_for_current_exception(kTool);  // a refused value: 2; cannot write DIR: 1
  }
  return cli::kExitOk;
}
