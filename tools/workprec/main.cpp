// pedalwave_workprec — what accuracy costs in time (model-spec.md §10, DESIGN.md "Simulation").
//
// Work-precision study (default): for each scene a dopri45 reference (tight rtol, its own error
// estimated against rtol × 10), then every integrator over a sweep of steps (tolerances for
// dopri45), the walking scenes in closed loop (gait controller at 1 kHz, module-side PD), free fall
// open loop. Errors: COM position (final, max over time), joint angles (max), sampled every control
// period; cost: wall and thread CPU time (median of repeats), derivative evaluations. Writes a
// Markdown table and log-log figures per scene, all points as CSV, and a summary naming the
// cheapest run within 1 mm max COM error against explicit Euler at 1e-4 s (the paper's choice).
//
// Fidelity study (--fidelity): flexible vs rigid joints, Coulomb vs regularized (v_s = 1e-4, 1e-3,
// 1e-2) vs tanh vs stick–slip friction on the flat and stair scenes: forward speed and cost.
#include <CLI/CLI.hpp>

#include "pedalwave/toolkit/cli.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iostream>
#include <map>
#include <mutex>
#include <sstream>

#include "pedalwave/campaign/campaign.hpp"
#include "pedalwave/campaign/cli.hpp"
#include "pedalwave/config/scene.hpp"
#include "pedalwave/config/shipped.hpp"
#include "pedalwave/model/stability.hpp"
#include "pedalwave/toolkit/csv.hpp"
#include "pedalwave/toolkit/figures.hpp"
#include "pedalwave/toolkit/progress.hpp"
#include "pedalwave/toolkit/table.hpp"
#include "study.hpp"

namespace fs = std::filesystem;
namespace model = pedalwave::model;
namespace tk = pedalwave::toolkit;
using namespace pedalwave::workprec;

namespace {

const std::vector<model::Method> kMethods = {
    model::Method::kExplicitEuler, model::Method::kSemiImplicitEuler,
    model::Method::kImplicitVelocity, model::Method::kRK4, model::Method::kDormandPrince45,
    model::Method::kImplicitContact};

struct Job {
  int scene = 0;        // index into the scenes
  int variant = 0;      // fidelity variant (0 = the scene as read)
  RunSpec spec;
  bool record = true;
  int repeats = 1;      // more repeats when a run is short
  double est_cost = 0;  // for ordering: longest first
  RunResult result;
};

// The scenes a study runs: each file's text (what the runs' specifications carry) and the scene
// read from it, the same way in the tool and in a Slurm array task (config::parse_scene).
struct SceneFile {
  std::string name, text;
  model::Scene scene;
};
SceneFile read_scene_file(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw std::invalid_argument("cannot read scene file " + path);
  std::ostringstream os;
  os << f.rdbuf();
  SceneFile sf{path, os.str(), {}};
  sf.scene = pedalwave::config::parse_scene(sf.text, path);
  return sf;
}

// Runs the jobs as one campaign (pedalwave::campaign: the local thread pool with a progress bar,
// or Slurm job arrays), longest first; each run goes through its one-line specification and
// result either way, so the results (all but the timings) are bit-identical between backends.
void run_jobs(std::vector<Job*>& jobs, const std::vector<SceneFile>& scenes,
              const pedalwave::campaign::Options& co, const std::string& name) {
  std::stable_sort(jobs.begin(), jobs.end(), [](const Job* a, const Job* b) { return a->est_cost > b->est_cost; });
  std::vector<std::string> specs;
  specs.reserve(jobs.size());
  for (const Job* j : jobs) {
    const SceneFile& sf = scenes[static_cast<size_t>(j->scene)];
    specs.push_back(encode_spec(j->spec, sf.name, sf.text, j->variant, j->record, j->repeats));
  }
  const std::vector<std::string> res = pedalwave::campaign::run(name, specs, run_line, co);
  for (size_t i = 0; i < jobs.size(); ++i) jobs[i]->result = decode_result(res[i]);
}

std::string num(double v, int sig = 3) { return tk::Table::num(v, sig); }

std::string method_label(model::Method m) {
  switch (m) {
    case model::Method::kExplicitEuler: return "explicit Euler";
    case model::Method::kSemiImplicitEuler: return "semi-implicit Euler";
    case model::Method::kImplicitVelocity: return "implicit velocity";
    case model::Method::kRK4: return "RK4";
    case model::Method::kDormandPrince45: return "dopri45";
    case model::Method::kImplicitContact: return "implicit contact";
  }
  return "?";
}

std::string setting(const model::IntegratorOptions& o) {
  return model::is_adaptive(o.method) ? "rtol " + num(o.rtol, 2) : "h " + num(o.h, 2);
}

// Estimated cost (evaluations) of a run, to start the long ones first.
double estimate(const RunSpec& s) {
  const double stages = s.integ.method == model::Method::kRK4                ? 4
                        : s.integ.method == model::Method::kImplicitVelocity ? 3
                        : s.integ.method == model::Method::kImplicitContact  ? 9
                                                                              : 1;
  if (model::is_adaptive(s.integ.method)) return s.duration / 2e-4 * 7 * (1 - std::log10(s.integ.rtol) / 10);
  return s.duration / s.integ.h * stages;
}

std::string limit_text(const std::string& name, const model::MethodLimit& l) {
  std::string t = name + " " + num(l.h_max) + " s (" + model::to_string(l.dominant) + ")";
  if (l.h_blowup > l.h_max)
    t += ", blow-up " + num(l.h_blowup) + " s (" + model::to_string(l.blowup_dominant) + ")";
  return t;
}

model::IntegratorOptions dopri(double rtol) {
  return {.method = model::Method::kDormandPrince45, .h = 1e-5, .rtol = rtol, .atol = rtol * 1e-2,
          .h_min = 1e-15, .h_max = 1e-3};
}

struct Options {
  std::vector<std::string> scenes;
  double duration = 10.0;
  std::string out = "workprec_out";
  int jobs = 2;
  int repeats = 3;
  double ref_rtol = 1e-8;
  bool quick = false;
  bool fidelity = false;
  bool quiet = false;
  int jacobian_age = model::IntegratorOptions{}.jacobian_age;  // implicit_contact's runs
  pedalwave::campaign::Options campaign;
};

// ---- work-precision -----------------------------------------------------------------------------

int work_precision(const Options& opt) {
  std::vector<SceneFile> files;
  std::vector<model::Scene> scenes;
  for (const auto& p : opt.scenes) {
    files.push_back(read_scene_file(p));
    scenes.push_back(files.back().scene);
  }
  const int S = static_cast<int>(scenes.size());
  auto base = [&](int s) {
    RunSpec r;
    r.scene = scenes[static_cast<size_t>(s)];
    r.closed_loop = r.scene.ground_on;  // free fall (no ground) runs open loop
    // Open loop has no control period: sample every 2 ms so that h = 2e-3 is a real step.
    if (!r.closed_loop) r.rate_hz = 500.0;
    r.duration = opt.duration;
    return r;
  };

  // References: rtol and rtol/10 (the latter is the reference; their difference bounds the error).
  std::vector<Job> refs(static_cast<size_t>(2 * S));
  std::vector<Job*> ptrs;
  for (int s = 0; s < S; ++s)
    for (int k = 0; k < 2; ++k) {
      Job& j = refs[static_cast<size_t>(2 * s + k)];
      j.scene = s;
      j.spec = base(s);
      j.spec.integ = dopri(k == 0 ? opt.ref_rtol : opt.ref_rtol / 10);
      j.est_cost = estimate(j.spec) * 3;
      ptrs.push_back(&j);
    }
  run_jobs(ptrs, files, opt.campaign, "references");
  for (const Job& j : refs)
    if (j.result.status != RunStatus::kOk) {
      std::cerr << "reference for " << scenes[static_cast<size_t>(j.scene)].name << " failed: " << j.result.why
                << " at t = " << j.result.t_fail << " s\n";
      return 3;
    }

  // The sweep.
  const std::vector<double> fixed_h = opt.quick ? std::vector<double>{1e-4, 5e-4, 1e-3}
                                                : std::vector<double>{1e-5, 2e-5, 5e-5, 1e-4, 2e-4, 2.5e-4, 5e-4, 1e-3};
  const std::vector<double> rk4_h = opt.quick ? std::vector<double>{1e-4, 5e-4}
                                              : std::vector<double>{5e-5, 1e-4, 2e-4, 5e-4, 1e-3};
  const std::vector<double> rtols = opt.quick ? std::vector<double>{1e-3, 1e-6}
                                              : std::vector<double>{1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9};
  std::vector<Job> runs;
  for (int s = 0; s < S; ++s) {
    const RunSpec b = base(s);
    for (model::Method m : kMethods) {
      std::vector<double> hs = m == model::Method::kRK4 ? rk4_h : fixed_h;
      // implicit_contact: three evaluations per step; below 5e-5 s it only adds cost.
      if (m == model::Method::kImplicitContact)
        hs.erase(std::remove_if(hs.begin(), hs.end(), [](double h) { return h < 5e-5; }), hs.end());
      if (!b.closed_loop && m != model::Method::kDormandPrince45) hs.push_back(2e-3);  // > period
      if (m == model::Method::kDormandPrince45) {
        for (double rt : rtols) {
          Job j;
          j.scene = s;
          j.spec = b;
          j.spec.integ = dopri(rt);
          runs.push_back(j);
        }
        continue;
      }
      for (double h : hs) {
        Job j;
        j.scene = s;
        j.spec = b;
        j.spec.integ = {.method = m, .h = h};
        j.spec.integ.jacobian_age = opt.jacobian_age;
        runs.push_back(j);
      }
    }
  }
  ptrs.clear();
  for (Job& j : runs) {
    j.repeats = opt.repeats;
    j.est_cost = estimate(j.spec);
    ptrs.push_back(&j);
  }
  run_jobs(ptrs, files, opt.campaign, "work-precision");

  // Results.
  fs::create_directories(opt.out);
  tk::CsvWriter csv(fs::path(opt.out) / "work_precision.csv",
                    {"scene", "method", "h", "rtol", "status", "wall_s", "cpu_s", "evaluations",
                     "steps", "rejected", "com_err_final_m", "com_err_max_m", "alpha_err_max_rad",
                     "t_reached_s"});
  {
    std::ostringstream c;
    c << "pedalwave_workprec: duration " << opt.duration << " s, reference dopri45 rtol "
      << opt.ref_rtol / 10 << "\nscene ids:";
    for (int s = 0; s < S; ++s) c << ' ' << s << '=' << scenes[static_cast<size_t>(s)].name;
    c << "\nmethod ids:";
    for (model::Method m : kMethods) c << ' ' << static_cast<int>(m) << '=' << model::to_string(m);
    c << "\nstatus: 0 ok, 1 unstable (NaN or blow-up), 2 failed; errors are NaN unless ok";
    c << "\nimplicit_contact jacobian_age: " << opt.jacobian_age;
    csv.comment(c.str());
  }
  std::ostringstream summary;
  summary << "# Work-precision study\n\n"
          << "Duration " << opt.duration << " s per run; errors against a dopri45 reference (rtol "
          << num(opt.ref_rtol / 10, 2) << "), sampled every control period (1 ms; open loop every "
          << "2 ms, so that h = 2e-3 is a real step). Time is the "
          << "run's thread CPU time (median of " << opt.repeats
          << " repeats for runs under 1 s); wall time is in the CSV.\n\n";
  tk::Table best({"scene", "loop", "ref. error (COM, α)", "cheapest within 1 mm (max COM)", "CPU [s]",
                  "evals", "Euler 1e-4: CPU [s]", "evals", "× cheaper (CPU, evals)"});

  for (int s = 0; s < S; ++s) {
    const model::Scene& sc = scenes[static_cast<size_t>(s)];
    const Trajectory& ref = refs[static_cast<size_t>(2 * s + 1)].result.traj;
    const Errors ref_err = compare(refs[static_cast<size_t>(2 * s)].result.traj, ref);
    const bool closed = sc.ground_on;
    const model::ControlGains gains = closed ? model::ControlGains{30, 15} : model::ControlGains{0, 0};
    const model::StabilityReport pred = model::predict_stability(sc, gains);

    tk::Table t({"method", "setting", "status", "CPU [s]", "wall [s]", "evaluations",
                 "COM err final [m]", "COM err max [m]", "α err max [rad]"});
    const Job* cheapest = nullptr;
    const Job* euler4 = nullptr;
    for (const Job& j : runs) {
      if (j.scene != s) continue;
      const RunResult& r = j.result;
      const bool ok = r.status == RunStatus::kOk;
      Errors e{NAN, NAN, NAN};
      if (ok) e = compare(r.traj, ref);
      const model::Method m = j.spec.integ.method;
      csv.row({static_cast<double>(s), static_cast<double>(static_cast<int>(m)), j.spec.integ.h,
               model::is_adaptive(m) ? j.spec.integ.rtol : NAN, static_cast<double>(static_cast<int>(r.status)),
               r.wall_s, r.cpu_s, static_cast<double>(r.evaluations), static_cast<double>(r.steps),
               static_cast<double>(r.rejected), e.com_final, e.com_max, e.alpha_max, r.t_fail});
      t.add_row({method_label(m), setting(j.spec.integ),
                 ok ? "ok" : std::string(to_string(r.status)) + " at " + num(r.t_fail, 3) + " s",
                 num(r.cpu_s), num(r.wall_s), std::to_string(r.evaluations), ok ? num(e.com_final) : "—",
                 ok ? num(e.com_max) : "—", ok ? num(e.alpha_max) : "—"});
      if (ok && e.com_max <= 1e-3 && (!cheapest || r.cpu_s < cheapest->result.cpu_s)) cheapest = &j;
      if (m == model::Method::kExplicitEuler && std::abs(j.spec.integ.h - 1e-4) < 1e-12) euler4 = &j;
    }

    // Per-scene Markdown.
    std::ostringstream md;
    md << "## " << sc.name << (closed ? " (closed loop)" : " (open loop)") << "\n\n"
       << "Reference: dopri45 rtol " << num(opt.ref_rtol / 10, 2) << " ("
       << refs[static_cast<size_t>(2 * s + 1)].result.evaluations << " evaluations); against rtol "
       << num(opt.ref_rtol, 2) << " it differs by " << num(ref_err.com_max) << " m (COM, max) and "
       << num(ref_err.alpha_max) << " rad (α, max) — an upper bound on the reference's own error.\n\n"
       << "Predicted stability limits (model/stability.hpp, K_p = " << gains.K_p << ", K_D = " << gains.K_D
       << "): " << limit_text("explicit Euler", pred.euler) << ", "
       << limit_text("semi-implicit Euler", pred.semi_implicit) << ", " << limit_text("RK4", pred.rk4)
       << "; dopri45's steps are held near " << num(pred.dopri.h_max) << " s. (Friction-set limits are "
       << "soft: above them the stick band chatters, runs blow up above the second value.)\n\n"
       << t.to_markdown() << "\n";
    if (cheapest) {
      md << "Cheapest within 1 mm max COM error: **" << method_label(cheapest->spec.integ.method) << ", "
         << setting(cheapest->spec.integ) << "** (" << num(cheapest->result.cpu_s) << " s CPU, "
         << cheapest->result.evaluations << " evaluations)";
      if (euler4 && euler4->result.status == RunStatus::kOk)
        md << ": " << num(euler4->result.cpu_s / cheapest->result.cpu_s, 2) << "× less CPU time and "
           << num(static_cast<double>(euler4->result.evaluations) / static_cast<double>(cheapest->result.evaluations), 2)
           << "× fewer evaluations than explicit Euler at 1e-4 s";
      else if (euler4)
        md << "; explicit Euler at 1e-4 s is unstable here";
      md << ".\n\n";
    } else {
      md << "No run met 1 mm max COM error.\n\n";
    }
    std::ofstream(fs::path(opt.out) / (sc.name + ".md")) << md.str();
    summary << md.str();

    // Summary row.
    std::string ch = "none", cc = "—", ce = "—", ec = "—", ee = "—", ratio = "—";
    if (cheapest) {
      ch = method_label(cheapest->spec.integ.method) + ", " + setting(cheapest->spec.integ);
      cc = num(cheapest->result.cpu_s);
      ce = std::to_string(cheapest->result.evaluations);
    }
    if (euler4) {
      if (euler4->result.status == RunStatus::kOk) {
        ec = num(euler4->result.cpu_s);
        ee = std::to_string(euler4->result.evaluations);
        if (cheapest)
          ratio = num(euler4->result.cpu_s / cheapest->result.cpu_s, 2) + ", " +
                  num(static_cast<double>(euler4->result.evaluations) /
                          static_cast<double>(cheapest->result.evaluations), 2);
      } else {
        ec = "unstable";
      }
    }
    best.add_row({sc.name, closed ? "closed" : "open", num(ref_err.com_max, 2) + " m, " + num(ref_err.alpha_max, 2) + " rad",
                  ch, cc, ce, ec, ee, ratio});
  }
  csv.close();
  summary << "## Summary\n\n" << best.to_markdown();
  std::ofstream(fs::path(opt.out) / "summary.md") << summary.str();
  if (!opt.quiet) std::cout << best.to_text();
  std::cout << "wrote " << (fs::path(opt.out) / "summary.md").string() << ", work_precision.csv\n";
  // The work-precision figures from the CSV (tools/figures/workprec.py): <scene>_com.png, _alpha.png.
  const tk::FigureOutcome figures = tk::draw_figures("workprec.py", {opt.out});
  (figures.status == tk::FigureOutcome::Status::drawn ? std::cout : std::cerr) << figures.message << '\n';
  return 0;
}

// ---- fidelity -----------------------------------------------------------------------------------

int fidelity(const Options& opt) {
  const std::vector<Variant>& variants = fidelity_variants();
  std::vector<SceneFile> files;
  std::vector<model::Scene> scenes;
  for (const auto& p : opt.scenes) {
    files.push_back(read_scene_file(p));
    scenes.push_back(files.back().scene);
  }
  // dopri45 cannot resolve an exact sign switch: give it up when its step falls below 1e-9 s or it
  // spends more than 100× the implicit run's evaluations.
  model::IntegratorOptions dp = dopri(1e-6);
  dp.h_min = 1e-9;
  const std::vector<model::IntegratorOptions> integs = {
      {.method = model::Method::kImplicitVelocity, .h = 1e-4}, dp};
  std::vector<Job> jobs;
  for (size_t s = 0; s < scenes.size(); ++s)
    for (size_t v = 0; v < variants.size(); ++v)
      for (const auto& in : integs) {
        Job j;
        j.scene = static_cast<int>(s);
        j.variant = static_cast<int>(v);
        j.spec.scene = scenes[s];
        variants[v].apply(j.spec.scene);
        j.spec.closed_loop = true;
        j.spec.duration = opt.duration;
        j.spec.integ = in;
        j.spec.max_evaluations = static_cast<std::uint64_t>(100 * opt.duration / 1e-4);
        j.est_cost = estimate(j.spec);
        jobs.push_back(j);
      }
  std::vector<Job*> ptrs;
  for (Job& j : jobs) ptrs.push_back(&j);
  run_jobs(ptrs, files, opt.campaign, "fidelity");

  fs::create_directories(opt.out);
  tk::CsvWriter csv(fs::path(opt.out) / "fidelity.csv",
                    {"scene", "variant", "method", "status", "speed_cm_s", "cpu_s", "wall_s", "evaluations", "steps"});
  std::ostringstream md;
  md << "# Model fidelity: forward speed and cost\n\nClosed loop (gait at 1 kHz, module-side PD, k_c = 0), "
     << opt.duration << " s. Speed = (x_COM(T) − x_COM(0)) / T, +X is toward the head. Each variant is "
     << "run with implicit_velocity at h = 1e-4 s (the paper's step) and with dopri45 at rtol 1e-6 (its "
     << "evaluations show how stiff the variant is).\n\n";
  for (size_t s = 0; s < scenes.size(); ++s) {
    tk::Table t({"variant", "speed [cm/s] (implicit 1e-4)", "speed [cm/s] (dopri45 1e-6)", "CPU [s] implicit",
                 "evals implicit", "CPU [s] dopri45", "evals dopri45"});
    for (size_t v = 0; v < variants.size(); ++v) {
      std::vector<std::string> row{variants[v].name};
      std::vector<std::string> cost;
      for (size_t k = 0; k < integs.size(); ++k) {
        const Job& j = jobs[(s * variants.size() + v) * integs.size() + k];
        const RunResult& r = j.result;
        const bool ok = r.status == RunStatus::kOk && !r.traj.com_x.empty();
        const double speed = ok ? 100.0 * (r.traj.com_x.back() - r.traj.com_x.front()) / opt.duration : NAN;
        row.push_back(ok ? num(speed, 3) : std::string(to_string(r.status)) + " (" + r.why + ")");
        cost.push_back(num(r.cpu_s));
        cost.push_back(std::to_string(r.evaluations));
        csv.row({static_cast<double>(s), static_cast<double>(v), static_cast<double>(static_cast<int>(j.spec.integ.method)),
                 static_cast<double>(static_cast<int>(r.status)), speed, r.cpu_s, r.wall_s,
                 static_cast<double>(r.evaluations), static_cast<double>(r.steps)});
      }
      row.push_back(cost[0]);
      row.push_back(cost[1]);
      row.push_back(cost[2]);
      row.push_back(cost[3]);
      t.add_row(row);
    }
    md << "## " << scenes[s].name << "\n\n" << t.to_markdown() << "\n";
  }
  csv.close();
  std::ofstream(fs::path(opt.out) / "fidelity.md") << md.str();
  if (!opt.quiet) std::cout << md.str();
  std::cout << "wrote " << (fs::path(opt.out) / "fidelity.md").string() << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (pedalwave::campaign::cli::is_worker(argc, argv))
    return pedalwave::campaign::worker_main(argc - 1, argv + 1, run_line, "pedalwave_workprec");
  CLI::App app{"pedalwave_workprec: what accuracy costs in time — integrators against a tight "
               "reference on the shipped scenes (or, with --fidelity, model variants)"};
  Options opt;
  const std::string dir = pedalwave::config::shipped_dir() + "/scenes";
  app.add_option("scenes", opt.scenes, "scene files (default: the shipped scenes; --fidelity: flat_high_friction and stair)");
  app.add_option("--duration", opt.duration, "simulated time per run [s]")->check(CLI::PositiveNumber)->capture_default_str();
  app.add_option("--out", opt.out, "output folder")->capture_default_str();
  app.add_option("--jobs", opt.jobs, "parallel runs (threads)")->check(CLI::Range(1, 64))->capture_default_str();
  app.add_option("--repeats", opt.repeats, "timing repeats for runs under 1 s CPU (median)")->check(CLI::Range(1, 20))->capture_default_str();
  app.add_option("--ref-rtol", opt.ref_rtol, "reference check tolerance; the reference itself uses a tenth of it")
      ->check(CLI::PositiveNumber)->capture_default_str();
  app.add_flag("--quick", opt.quick, "a few points per method (smoke test)");
  app.add_flag("--fidelity", opt.fidelity, "model-fidelity study instead of the work-precision study");
  app.add_flag("--quiet", opt.quiet, "no progress bar");
  app.add_option("--jacobian-age", opt.jacobian_age,
                 "implicit_contact: most later steps a factored Jacobian serves (0: fresh at every evaluation)")
      ->check(CLI::Range(0, 1000))->capture_default_str();
  // The runs as a campaign: --backend local|slurm and the Slurm options (default campaign folder:
  // <--out>/campaign).
  pedalwave::campaign::cli::CliOptions camp;
  pedalwave::campaign::cli::add_options(&app, camp, "");
  if (const auto rc = pedalwave::toolkit::cli::parse(app, argc, argv, "pedalwave_workprec")) return *rc;
  if (opt.scenes.empty()) {
    if (opt.fidelity)
      opt.scenes = {dir + "/flat_high_friction.yaml", dir + "/stair.yaml"};
    else
      for (const char* n : {"free_fall", "flat_high_friction", "flat_low_friction", "friction_change", "stair",
                            "stair_grip"})
        opt.scenes.push_back(dir + "/" + n + ".yaml");
  }
  try {
    opt.campaign = pedalwave::campaign::cli::options(camp, opt.jobs, !opt.quiet);
    if (opt.campaign.slurm.dir.empty()) opt.campaign.slurm.dir = fs::path(opt.out) / "campaign";
    return opt.fidelity ? fidelity(opt) : work_precision(opt);
  } catch (const std::exception& e) {
    std::cerr << "pedalwave_workprec: " << e.what() << '\n';
    return 2;
  }
}
