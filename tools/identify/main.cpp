// pedalwave_identify — identification of the uncertain parameters (tools/identify/README.md).
//
//   pedalwave_identify fit  [--params P.yaml] [--targets T.yaml] [--write-scenes DIR] …
//       the parameters of P (within their bounds) fitted jointly to the figures of T (default: the
//       paper's simulated figures, config/identify/), NLopt (quasi-random starts as one batch,
//       then LN_BOBYQA), every evaluation's simulations as a campaign (--backend local|slurm),
//       cached; reports residuals, sensitivities, determinacy; writes DIR/fit.json.
//   pedalwave_identify data [--recording] RECORDING(.mcap|.csv) --scene S.yaml [--no-ground] …
//       K per joint, motor friction and I_r by equation error (the motor rows, integrated over
//       windows), then the ground's μ by output error (closed-loop re-simulation).
//   pedalwave_identify campaign-worker --dir D --task I     (the Slurm array tasks' entry)
#include <CLI/CLI.hpp>

#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>

#include "fit.hpp"
#include "pedalwave/campaign/cli.hpp"
#include "pedalwave/config/shipped.hpp"
#include "pedalwave/toolkit/cli.hpp"
#include "pedalwave/toolkit/table.hpp"
#include "recording.hpp"

namespace fs = std::filesystem;
namespace cli = pedalwave::toolkit::cli;
namespace campaign = pedalwave::campaign;
using namespace pedalwave::identify;

namespace {

// The one runner of every campaign this tool runs (by the specification's kind).
std::string runner(const std::string& spec) {
  if (spec.find("kind=identify.ground") != std::string::npos) return ground_run_line(spec);
  return run_line(spec);
}

std::string fmt(double v, int sig = 4) { return pedalwave::toolkit::Table::num(v, sig); }

std::string read_text(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  if (!f) throw std::invalid_argument("cannot read " + p.string());
  std::ostringstream os;
  os << f.rdbuf();
  return os.str();
}

}  // namespace

int main(int argc, char** argv) {
  if (campaign::cli::is_worker(argc, argv))
    return campaign::worker_main(argc - 1, argv + 1, runner, "pedalwave_identify");
  CLI::App app{"pedalwave_identify: fit the uncertain parameters to target figures, or a robot's K, "
               "I_r and friction to a recording of its walk"};
  app.require_subcommand(1);
  const std::string shipped = pedalwave::config::shipped_dir();
  int jobs = campaign::default_jobs();
  bool quiet = false;

  // ---- fit ----
  auto* fitc = app.add_subcommand("fit", "joint fit of scene parameters to target figures");
  std::string params_file = shipped + "/identify/paper_params.yaml";
  std::string targets_file = shipped + "/identify/paper_targets.yaml";
  std::string scenes = shipped + "/scenes", stair_scene = "stair", out = "out/identify", write_scenes;
  FitSettings fs_;
  bool smoke = false, no_cache = false;
  campaign::cli::CliOptions fit_campaign;
  fitc->add_option("--params", params_file, "parameters, bounds and reasons (YAML)")->capture_default_str();
  fitc->add_option("--targets", targets_file, "target figures (YAML)")->capture_default_str();
  fitc->add_option("--scenes", scenes, "folder of flat_high_friction, flat_low_friction, friction_change and the stair scene")
      ->capture_default_str();
  fitc->add_option("--stair-scene", stair_scene, "box scene: a name in --scenes or a .yaml path")->capture_default_str();
  fitc->add_option("--flat-duration", fs_.horizon.flat, "flat runs [s]")->check(cli::finite_positive())->capture_default_str();
  fitc->add_option("--friction-duration", fs_.horizon.friction, "friction-change run [s]")->check(cli::finite_positive())
      ->capture_default_str();
  fitc->add_option("--stair-duration", fs_.horizon.stair, "stair runs [s]")->check(cli::finite_positive())->capture_default_str();
  fitc->add_option("--starts", fs_.starts, "quasi-random starts per choice combination (one batch)")
      ->check(CLI::Range(1, 10000))->capture_default_str();
  fitc->add_option("--max-evals", fs_.max_evals, "local search evaluations per choice combination")
      ->check(CLI::Range(0, 100000))->capture_default_str();
  fitc->add_option("--xtol", fs_.xtol, "local search: stop below this step (normalized parameters)")
      ->check(cli::finite_positive())->capture_default_str();
  fitc->add_option("--fd-step", fs_.fd_step, "finite-difference step (normalized parameters)")
      ->check(CLI::Range(1e-6, 0.5))->capture_default_str();
  fitc->add_option("--out", out, "output folder (fit.json, fit.md, cache.tsv)")->capture_default_str();
  fitc->add_option("--write-scenes", write_scenes, "write the fitted scenes as DIR/paper_fit_<scene>.yaml");
  fitc->add_flag("--no-cache", no_cache, "do not read or append <out>/cache.tsv");
  fitc->add_flag("--smoke", smoke, "CI-sized: 4 s flat, 8 s friction, 4 s stair runs, 2 starts, 4 local steps");
  fitc->add_option("--jobs", jobs, "threads (local backend)")->check(CLI::Range(1, 256))->capture_default_str();
  fitc->add_flag("--quiet", quiet, "no progress");
  campaign::cli::add_options(fitc, fit_campaign, "");

  // ---- data ----
  auto* datac = app.add_subcommand("data", "K per joint, motor friction, I_r and ground μ from a recording");
  std::string recording, scene_file, json_out;
  MotorFitOptions mo;
  GroundFitOptions go;
  std::string pd = "module";
  bool no_ground = false;
  campaign::cli::CliOptions data_campaign;
  datac->add_option("recording,--recording", recording,
                    "the recording: an MCAP file (the daemon's telemetry.record or pedalwave_monitor --record "
                    "run.mcap), the CSV recorder's run.csv (run.joint_state.csv + run.controller_state.csv), or "
                    "pedalwave_sim's trajectory.csv sampled every control period")
      ->required();
  datac->add_option("--scene", scene_file, "the recording's scene (gait, start, robot): needed for the ground fit");
  auto* n_opt = datac->add_option("--n", mo.n, "gear ratio (default: the recording's robot_description, else 255)")
                    ->check(cli::finite_positive())->capture_default_str();
  datac->add_option("--pd", pd, "where the PD runs: module (within the period) or host (u held)")
      ->check(CLI::IsMember({"module", "host"}))->capture_default_str();
  datac->add_option("--kp", mo.K_p, "PD K_p [N·m/rad]")->capture_default_str();
  datac->add_option("--kd", mo.K_D, "PD K_D [N·m·s/rad]")->capture_default_str();
  datac->add_option("--window", mo.window, "integration window [s]")->check(cli::finite_positive())->capture_default_str();
  datac->add_option("--skip", mo.skip, "ignore the first seconds")->check(CLI::Range(0.0, 1e6))->capture_default_str();
  datac->add_option("--mu-min", go.lo, "ground μ lower bound")->capture_default_str();
  datac->add_option("--mu-max", go.hi, "ground μ upper bound")->capture_default_str();
  datac->add_flag("--no-ground", no_ground, "stage 1 only (no simulation)");
  datac->add_option("--json", json_out, "write the result as JSON");
  datac->add_option("--jobs", jobs, "threads (local backend)")->check(CLI::Range(1, 256))->capture_default_str();
  datac->add_flag("--quiet", quiet, "no progress");
  campaign::cli::add_options(datac, data_campaign, "campaign");

  if (const auto rc = cli::parse(app, argc, argv, "pedalwave_identify")) return *rc;

  try {
    if (*fitc) {
      if (smoke) {
        fs_.horizon = {4.0, 8.0, 4.0};
        fs_.starts = 2;
        fs_.max_evals = 4;
      }
      fs_.scenes_dir = scenes;
      fs_.stair_scene = stair_scene;
      fs_.progress = !quiet;
      fs_.log = &std::cerr;
      fit_campaign.app = fitc;
      fs_.campaign = campaign::cli::options(fit_campaign, jobs, !quiet);
      if (fs_.campaign.slurm.dir.empty()) fs_.campaign.slurm.dir = fs::path(out) / "campaign";
      fs::create_directories(out);
      if (!no_cache) fs_.cache_file = fs::path(out) / "cache.tsv";
      Evaluator ev(load_params(params_file), load_targets(targets_file), fs_);
      const FitResult r = fit(ev);
      const std::string text = report_text(ev, r);
      std::cout << text;
      pedalwave::toolkit::Json j = to_json(ev, r);
      j.set("params_file", params_file).set("targets_file", targets_file);
      std::ofstream(fs::path(out) / "fit.json") << j.dump(2) << '\n';
      std::ofstream(fs::path(out) / "fit.md") << text;
      std::cout << "wrote " << (fs::path(out) / "fit.json").string() << '\n';
      if (!write_scenes.empty()) {
        fs::create_directories(write_scenes);
        for (const auto& [stem, yaml] : ev.fitted_scene_yaml(r.best)) {
          const fs::path p = fs::path(write_scenes) / ("paper_fit_" + stem + ".yaml");
          std::ofstream f(p);
          f << "# Parameters fitted by pedalwave_identify fit (parameters " << fs::path(params_file).filename().string()
            << ", targets " << fs::path(targets_file).filename().string() << ", horizons " << fmt(fs_.horizon.flat, 3)
            << "/" << fmt(fs_.horizon.friction, 3) << "/" << fmt(fs_.horizon.stair, 3) << " s, cost " << fmt(r.cost)
            << ").\n# The best set within the stated bounds; at it (target: figure -> this model):\n";
          for (std::size_t k = 0; k < ev.targets().list.size(); ++k) {
            const Target& t = ev.targets().list[k];
            f << "#   " << to_string(t.measure) << ": " << fmt(t.value, 4) << " -> " << fmt(r.measures.get(t.measure), 4)
              << " (residual " << fmt(r.residuals[k], 3) << " tolerances)\n";
          }
          f << yaml;
          if (!f) throw std::runtime_error("cannot write " + p.string());
          std::cout << "wrote " << p.string() << '\n';
        }
      }
    } else {
      mo.module_pd = pd == "module";
      const Recording rec = read_recording(recording);
      for (const std::string& note : rec.notes) std::cerr << "pedalwave_identify: note: " << note << '\n';
      if (n_opt->count() == 0 && rec.gear_ratio > 0) mo.n = rec.gear_ratio;
      const MotorFit m = fit_motor(rec, mo);
      const long long span = cycle_of(rec, rec.t.size() - 1) - cycle_of(rec, 0) + 1;
      std::cout << "Recording " << rec.source << ": " << rec.joints << " joints, " << rec.t.size() << " samples every "
                << fmt(sample_period(rec) * 1e3) << " ms over " << fmt(rec.t.back() - rec.t.front()) << " s";
      if (span > static_cast<long long>(rec.t.size())) std::cout << " (" << span - static_cast<long long>(rec.t.size()) << " periods without a sample: skipped by the loop or lost)";
      std::cout << "\n";
      if (rec.gear_ratio > 0) {
        std::cout << "The robot's description in the recording: gear ratio n = " << fmt(rec.gear_ratio)
                  << (n_opt->count() == 0 ? " (used)" : " (--n " + fmt(mo.n) + " used)") << ", configured K =";
        for (double k : rec.nominal_K) std::cout << ' ' << fmt(k);
        std::cout << " N·m/rad, I_r = " << fmt(rec.nominal_I_r) << " kg·m²\n";
      }
      pedalwave::toolkit::Table t({"joint", "K [N·m/rad]", "±σ"});
      for (std::size_t j = 0; j < m.K.size(); ++j) t.add_row({std::to_string(j + 1), fmt(m.K[j]), fmt(m.K_se[j], 2)});
      std::cout << "Stage 1, equation error (" << m.windows << " windows of " << mo.window << " s, " << m.rows
                << " rows, θ̇ term " << (m.theta_term ? "used" : "not recorded: I_r biased by O(1/n)") << ")\n"
                << t.to_markdown() << "motor friction b = " << fmt(m.b) << " ± " << fmt(m.b_se, 2) << " N·m·s/rad\n"
                << "I_r = " << fmt(m.I_r) << " ± " << fmt(m.I_r_se, 2) << " kg·m² (n² I_r = " << fmt(mo.n * mo.n * m.I_r)
                << ")\nresidual RMS of ∫u over a window: " << fmt(m.residual_rms, 3) << " N·m·s\n";
      pedalwave::toolkit::Json j = pedalwave::toolkit::Json::object();
      pedalwave::toolkit::Json K = pedalwave::toolkit::Json::array(), Ks = pedalwave::toolkit::Json::array();
      for (std::size_t i = 0; i < m.K.size(); ++i) K.push(m.K[i]), Ks.push(m.K_se[i]);
      j.set("K", K).set("K_sigma", Ks).set("b", m.b).set("b_sigma", m.b_se).set("I_r", m.I_r).set("I_r_sigma", m.I_r_se)
          .set("windows", m.windows).set("residual_rms", m.residual_rms)
          .set("samples", static_cast<double>(rec.t.size())).set("periods_missing", static_cast<double>(span) - static_cast<double>(rec.t.size()));
      if (!no_ground) {
        if (scene_file.empty()) throw std::invalid_argument("--scene: the recording's scene is needed for the ground fit (or --no-ground)");
        data_campaign.app = datac;
        go.campaign = campaign::cli::options(data_campaign, jobs, !quiet);
        if (!(go.lo > 0 && go.lo < go.hi)) throw std::invalid_argument("--mu-min/--mu-max: expected 0 < min < max");
        const GroundFit g = fit_ground_mu(recording, read_text(scene_file), m, go);
        std::cout << "Stage 2, output error: ground μ = " << fmt(g.mu) << " ± " << fmt(g.mu_sigma, 2) << " (residual RMS "
                  << fmt(g.rms, 3) << " rad over α and β − α, " << g.simulations << " simulations)\n";
        j.set("mu", g.mu).set("mu_sigma", g.mu_sigma).set("rms", g.rms).set("simulations", g.simulations);
      }
      if (!json_out.empty()) std::ofstream(json_out) << j.dump(2) << '\n';
    }
  } catch (...) {
    return cli::exit_for_current_exception("pedalwave_identify");
  }
  return cli::kExitOk;
}
