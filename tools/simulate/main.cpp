// pedalwave_sim — run a scene in closed loop and show what happened.
//
//   pedalwave_sim SCENE.yaml [--duration s] [--controller none|gait] [--k_c X] [--rate Hz]
//                 [--integrator NAME] [--h s] [--rtol x] [--out DIR] [--every s] [--no-plots]
//
// Writes DIR/trajectory.csv, DIR/summary.txt (also printed) and the figures DIR/{shapes, paths,
// torques,speed}.{svg,png}. Exit codes: 0 done; 2 bad input (scene file, YAML, option value; one
// error line on stderr); 3 the plant failed (non-finite state / singular mass matrix): the rows up
// to the failure are written, the summary says why; 1 any other error (e.g. cannot write DIR).
#include <CLI/CLI.hpp>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <optional>
#include <string>

#include "pedalwave/config/scene.hpp"
#include "sim_run.hpp"

namespace {

constexpr int kExitBadInput = 2;
constexpr int kExitPlantFailed = 3;

int bad_input(const std::string& what) {
  std::cerr << "pedalwave_sim: error: " << what << '\n';
  return kExitBadInput;
}

// "a number > 0" with a short message (CLI::PositiveNumber prints the whole double range).
const CLI::Validator kPositive(
    [](std::string& text) -> std::string {
      double v = 0.0;
      try {
        std::size_t used = 0;
        v = std::stod(text, &used);
        if (used != text.size()) return "'" + text + "': expected a number > 0";
      } catch (const std::exception&) {
        return "'" + text + "': expected a number > 0";
      }
      return v > 0 && std::isfinite(v) ? std::string{} : text + ": expected a number > 0";
    },
    "> 0", "positive");

}  // namespace

int main(int argc, char** argv) {
  namespace sim = pedalwave::simulate;
  namespace model = pedalwave::model;

  CLI::App app{"pedalwave_sim: simulate a scene (the runtime's gait controller against the plant "
               "model, in lockstep) and write trajectory.csv, summary.txt and plots"};
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
      ->capture_default_str();
  app.add_option("--rate", rate, "control rate [Hz]")->check(kPositive)->capture_default_str();
  app.add_option("--integrator", integrator,
                 "euler | semi_implicit_euler | implicit_velocity | rk4 | dopri45 (default: the scene's)");
  app.add_option("--h", h, "integrator step (initial step for dopri45) [s]")->check(kPositive);
  app.add_option("--rtol", rtol, "relative tolerance of dopri45")->check(kPositive);
  app.add_option("--out", out, "output folder (default: sim_out/<scene name>)");
  app.add_option("--every", every, "CSV/plot sample period [s], a multiple of 1/rate")
      ->check(kPositive)
      ->capture_default_str();
  app.add_flag("--no-plots", no_plots, "write no figures");
  app.add_flag("--quiet", quiet, "no progress bar, no printed summary");
  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    return bad_input(std::string(e.what()) + " (see --help)");
  }

  // Scene and overrides: every problem here is bad input (exit 2, one line).
  sim::RunConfig cfg;
  try {
    cfg.scene = pedalwave::config::load_scene(scene_path);
    if (cfg.scene.source.empty()) cfg.scene.source = scene_path;
    if (duration) cfg.scene.duration = *duration;
    cfg.integ = cfg.scene.integrator;
    if (integrator) cfg.integ.method = model::parse_method(*integrator);
    if (h) cfg.integ.h = *h;
    if (rtol) cfg.integ.rtol = *rtol;
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
    const std::string summary = sim::summary_text(cfg, r);
    {
      std::ofstream f(cfg.out_dir / "summary.txt");
      f << summary;
      if (!f) throw std::runtime_error("cannot write " + (cfg.out_dir / "summary.txt").string());
    }
    if (!quiet) std::cout << summary;
    if (cfg.plots)
      for (const std::string& line : sim::write_plots(cfg, r))
        if (!quiet) std::cout << "figure:           " << line << '\n';
    if (r.status != model::StepStatus::kOk) {
      std::cerr << "pedalwave_sim: the plant failed at t = " << r.t_end << " s: "
                << model::to_string(r.status) << " (rows up to then are in " << r.csv.string()
                << ")\n";
      return kExitPlantFailed;
    }
  } catch (const std::exception& e) {
    std::cerr << "pedalwave_sim: error: " << e.what() << '\n';
    return EXIT_FAILURE;
  }
  return EXIT_SUCCESS;
}
