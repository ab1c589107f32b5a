// pedalwave_paper — reproduce the paper's results (model-spec.md §9) with the runtime's controller
// against the plant model, closed loop at the control rate (simloop).
//
//   pedalwave_paper flat        [--duration 60]
//   pedalwave_paper friction    [--duration (scene's)]
//   pedalwave_paper stair       [--duration 60] [--k_c 0 10.1] [--every 1.5] [--heights 0.03 0.04 0.05 0.06]
//   pedalwave_paper sweep       [--from 0] [--to 15] [--step 0.1] [--duration 60] [--checks 4] [--check-h 1e-4]
//   pedalwave_paper sensitivity [--K 1 3 10 30 100] [--I_r 1e-8 5e-8 2e-7] [--no-model-options] [--duration 60]
//   pedalwave_paper all         [--duration 60] [--from --to --step --checks --check-h]
//                               (also the fitted scenes paper_fit_* when --scenes has them: a second table)
// Every subcommand also takes --out DIR (default out/paper), --scenes DIR, --jobs N, --integrator
// NAME, --h s, --rate Hz, --scene-prefix P (paper_fit_: the fitted scenes), --no-plots, --quiet, and the campaign options of the sweep's runs
// (--backend local|slurm, --slurm-config FILE, --campaign-dir, --partition, --account, --time,
// --cpus-per-task, --sbatch-opt, --chunk, --throttle, --max-retries, --poll: tools/common's
// pedalwave/campaign/cli.hpp). `pedalwave_paper campaign-worker --dir D --task I` is the entry of
// a Slurm array task (not for people). Figures (PNG, drawn by tools/figures/paper.py from out/data/) and a Markdown fragment go to
// DIR; the numbers are printed. Exit codes: 0 done; 2 bad input (one line on stderr: an option, or
// a scene file the reader refuses, also one read during the run); 1 other errors (e.g. cannot
// write DIR).
#include <CLI/CLI.hpp>

#include <cmath>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "paper.hpp"
#include "pedalwave/campaign/cli.hpp"
#include "pedalwave/simloop/plant_checks.hpp"
#include "pedalwave/config/shipped.hpp"
#include "pedalwave/toolkit/cli.hpp"

namespace {

namespace paper = pedalwave::paper;
namespace model = pedalwave::model;
namespace simloop = pedalwave::simloop;

namespace cli = pedalwave::toolkit::cli;
constexpr int kExitBadInput = cli::kExitBadInput;

struct Common {
  std::string out = "out/paper";
  std::string scenes = pedalwave::config::shipped_dir() + "/scenes";
  int jobs = paper::default_jobs();
  std::string integrator;  // empty: each scene's own
  double h = 0.0;
  double rate = 1000.0;
  std::string stair_scene = "stair";
  std::string scene_prefix;
  bool no_plots = false;
  bool quiet = false;
  bool no_lanes = false;
  int group = 8;
  pedalwave::campaign::cli::CliOptions campaign;
};

void add_common(CLI::App* sub, Common& c) {
  sub->add_option("--out", c.out, "output folder for figures and Markdown")->capture_default_str();
  sub->add_option("--scenes", c.scenes, "folder of the shipped scene files")->capture_default_str();
  sub->add_option("--jobs", c.jobs, "worker threads for independent runs")->check(CLI::Range(1, 256))
      ->capture_default_str();
  auto* integ = sub->add_option("--integrator", c.integrator,
                                 "euler | semi_implicit_euler | implicit_velocity | rk4 | dopri45 | implicit_contact (default: each "
                                 "scene's own, the work-precision study's choice)");
  auto* h = sub->add_option("--h", c.h, "plant integrator step [s] (≤ the control period; with --integrator)")
                ->check(cli::finite_positive());
  integ->needs(h);
  h->needs(integ);
  sub->add_option("--rate", c.rate, "control rate [Hz]")->check(cli::finite_positive())->capture_default_str();
  sub->add_option("--stair-scene", c.stair_scene,
                  "box scene of stair and sweep: a name in --scenes (e.g. stair_grip) or a path to a .yaml file")
      ->capture_default_str();
  sub->add_option("--scene-prefix", c.scene_prefix,
                  "prepended to the scene names in --scenes: paper_fit_ runs the identification's fitted scenes "
                  "(all runs both: the shipped scenes, then the paper_fit_* ones into DIR/paper_fit)");
  sub->add_flag("--no-plots", c.no_plots, "write no figures");
  sub->add_flag("--quiet", c.quiet, "no progress bars");
  sub->add_flag("--no-lanes", c.no_lanes,
                "step the sweep's runs one by one on the scalar plant (default: 8 at a time in lockstep, their "
                "plants in SIMD lanes, where the machine and the scene allow)");
  sub->add_option("--group", c.group,
                  "the sweep's runs per lockstep group, one campaign item (a Slurm chunk counts groups); a "
                  "member's result does not depend on its group")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  // Default campaign folder: <--out>/campaign (an empty dir here).
  pedalwave::campaign::cli::add_options(sub, c.campaign, "");
}

paper::Settings settings(const Common& c) {
  paper::Settings s;
  s.out_dir = c.out;
  s.scenes_dir = c.scenes;
  s.jobs = c.jobs;
  if (!c.integrator.empty()) {
    s.integ = model::IntegratorOptions{.method = model::parse_method(c.integrator), .h = c.h};
    model::validate(*s.integ);
  }
  s.rate_hz = c.rate;
  s.stair_scene = c.stair_scene;
  s.scene_prefix = c.scene_prefix;
  s.plots = !c.no_plots;
  s.progress = !c.quiet;
  s.lanes = !c.no_lanes;
  s.group = c.group;
  s.campaign = pedalwave::campaign::cli::options(c.campaign, c.jobs, s.progress);
  return s;
}

}  // namespace

int main(int argc, char** argv) {
  if (pedalwave::campaign::cli::is_worker(argc, argv))
    return pedalwave::campaign::worker_main(argc - 1, argv + 1, paper::run_line, "pedalwave_paper");
  CLI::App app{"pedalwave_paper: reproduce the paper's results (flat ground, friction change, stair, "
               "the k_c sweep) with the runtime's controller against the plant model"};
  app.require_subcommand(1);
  Common c;
  double duration = 60.0, friction_duration = 0.0, every = 1.5;
  std::vector<double> k_c{0.0, 10.1};
  std::vector<double> heights{0.03, 0.04, 0.05, 0.06};
  paper::SweepOptions sw;
  paper::SensitivityOptions se;
  bool no_model_options = false;

  auto* flat = app.add_subcommand("flat", "average forward speed at μ = 0.82 and μ = 0.40");
  add_common(flat, c);
  flat->add_option("--duration", duration, "simulated time per run [s]")->check(cli::finite_positive())->capture_default_str();

  auto* fric = app.add_subcommand("friction", "head-joint SEA torque across the friction change (Fig. 7)");
  add_common(fric, c);
  fric->add_option("--duration", friction_duration, "simulated time [s] (default: the scene's)")
      ->check(cli::finite_positive());

  auto* stair = app.add_subcommand("stair", "k_c = 0 against k_c = 10.1 over the stair (Fig. 10)");
  add_common(stair, c);
  stair->add_option("--duration", duration, "simulated time per run [s]")->check(cli::finite_positive())->capture_default_str();
  stair->add_option("--k_c", k_c, "adaptive gains to compare")->check(cli::finite_in(-1e3, 1e3))->capture_default_str();
  stair->add_option("--heights", heights, "box heights of the height scan [m] (none: --heights with no value)")
      ->expected(0, -1)->capture_default_str();
  stair->add_option("--every", every, "snapshot spacing of the shape plots [s]")->check(cli::finite_positive())
      ->capture_default_str();

  auto* sweep = app.add_subcommand("sweep", "average speed over the stair against k_c (Fig. 9)");
  add_common(sweep, c);
  sweep->add_option("--from", sw.from, "first k_c")->capture_default_str();
  sweep->add_option("--to", sw.to, "last k_c")->capture_default_str();
  sweep->add_option("--step", sw.step, "k_c step")->check(cli::finite_positive())->capture_default_str();
  sweep->add_option("--duration", sw.duration, "simulated time per run [s]")->check(cli::finite_positive())
      ->capture_default_str();
  sweep->add_option("--checks", sw.checks, "k_c values re-run at --check-h (0 = none)")->check(CLI::Range(0, 16))
      ->capture_default_str();
  sweep->add_option("--check-h", sw.check_h, "finer step of the accuracy check [s]")->check(cli::finite_positive())
      ->capture_default_str();

  auto* sens = app.add_subcommand("sensitivity", "how the results move with K and I_r (unpublished)");
  add_common(sens, c);
  sens->add_option("--K", se.K, "SEA stiffness values [N·m/rad]")->capture_default_str();
  sens->add_option("--I_r", se.I_r, "rotor inertia values [kg·m²]")->capture_default_str();
  sens->add_flag("--no-model-options", no_model_options, "skip the friction-at-COM and v_s rows");
  sens->add_option("--duration", duration, "flat and stair runs [s]")->check(cli::finite_positive())->capture_default_str();
  sens->add_option("--friction-duration", friction_duration, "friction runs [s] (default: the scene's)")
      ->check(cli::finite_positive());

  auto* all = app.add_subcommand("all", "everything, and DIR/paper_table.md");
  add_common(all, c);
  all->add_option("--duration", duration, "flat, stair, sweep and sensitivity runs [s]")
      ->check(cli::finite_positive())->capture_default_str();
  all->add_option("--friction-duration", friction_duration, "friction runs [s] (default: the scene's)")
      ->check(cli::finite_positive());
  all->add_option("--from", sw.from, "first k_c of the sweep")->capture_default_str();
  all->add_option("--to", sw.to, "last k_c of the sweep")->capture_default_str();
  all->add_option("--step", sw.step, "k_c step of the sweep")->check(cli::finite_positive())->capture_default_str();
  all->add_option("--checks", sw.checks, "k_c values re-run at --check-h")->check(CLI::Range(0, 16))
      ->capture_default_str();
  all->add_option("--check-h", sw.check_h, "finer step of the accuracy check [s]")->check(cli::finite_positive())
      ->capture_default_str();
  all->add_option("--K", se.K, "sensitivity: SEA stiffness values [N·m/rad]")->capture_default_str();
  all->add_option("--I_r", se.I_r, "sensitivity: rotor inertia values [kg·m²]")->capture_default_str();

  if (const auto rc = cli::parse(app, argc, argv, "pedalwave_paper")) return *rc;

  paper::Settings s;
  try {
    c.campaign.app = app.get_subcommands().front();  // the campaign options given are this one's
    s = settings(c);
    if (s.integ)  // the rule pedalwave_sim and the daemon use (simloop/plant_checks.hpp)
      if (const std::string why = simloop::step_problem(*s.integ, s.rate_hz, "1/rate"); !why.empty())
        throw std::invalid_argument("--h " + std::to_string(s.integ->h) + ": " + why);
    if (*all && !s.scene_prefix.empty())
      throw std::invalid_argument("--scene-prefix " + s.scene_prefix +
                                  ": not with all (it runs the shipped scenes, then the paper_fit_* ones)");
    (void)paper::sweep_grid(sw.from, sw.to, sw.step);
    if (const auto f = paper::scene_file(s, s.stair_scene); !std::filesystem::exists(f))
      throw std::invalid_argument("--stair-scene " + s.stair_scene + ": no scene file " + f.string());
    (void)paper::load(s, s.stair_scene);  // read now: a refused file is one line before any run
    for (double K : se.K)
      if (!(K > 0)) throw std::invalid_argument("--K " + std::to_string(K) + ": expected > 0 [N·m/rad]");
    for (double I : se.I_r)
      if (!(I > 0)) throw std::invalid_argument("--I_r " + std::to_string(I) + ": expected > 0 [kg·m²]");
    se.model_options = !no_model_options;
    se.flat_duration = se.stair_duration = duration;
    se.friction_duration = friction_duration;
  } catch (const std::exception& e) {
    std::cerr << "pedalwave_paper: error: " << e.what() << '\n';
    return kExitBadInput;
  }

  try {
    std::cout << "pedalwave_paper: output in " << s.out_dir.string() << ", " << s.jobs << " threads"
              << (s.campaign.backend == pedalwave::campaign::Backend::slurm ? " (the sweep's runs: Slurm job arrays), "
                                                                           : ", ")
              << (s.integ ? std::string(model::to_string(s.integ->method)) + " h = " + std::to_string(s.integ->h) + " s"
                          : std::string("each scene's own integrator"))
              << ", control " << s.rate_hz
              << " Hz\n";
    if (*flat) {
      paper::flat(s, duration);
    } else if (*fric) {
      paper::friction(s, friction_duration);
    } else if (*stair) {
      paper::stair(s, duration, k_c, every, heights);
    } else if (*sweep) {
      paper::sweep(s, sw);
    } else if (*sens) {
      paper::sensitivity(s, se);
    } else if (*all) {
      paper::AllOptions o;
      o.flat_duration = o.stair_duration = duration;
      o.friction_duration = friction_duration;
      o.sweep = sw;
      o.sweep.duration = duration;
      o.sensitivity = se;
      const paper::AllResult r = paper::all(s, o);
      std::cout << '\n' << r.table;
    }
  } catch (...) {
    // A scene file read during the run (--stair-scene, the shipped scenes) that the reader refuses
    // (config::ConfigError) or a value refused later (std::invalid_argument): exit 2, one line.
    return cli::exit_for_current_exception("pedalwave_paper");
  }
  return cli::kExitOk;
}
