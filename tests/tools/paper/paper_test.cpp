// pedalwave_paper (tools/paper/): the engine in-process (peaks, grid, determinism of the parallel
// sweep, the sweep's best against its own table) and the built executable end to end on short
// runs (every subcommand's outputs, the comparison table's rows, finite numbers, bad input).
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <bit>
#include <cstdio>
#include <cstdint>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "experiments.hpp"
#include "paper.hpp"
#include "pedalwave/toolkit/csv.hpp"

namespace {

namespace fs = std::filesystem;
namespace paper = pedalwave::paper;

const std::string kExe = PEDALWAVE_PAPER_EXE;
const fs::path kScenes = fs::path(PEDALWAVE_CONFIG_DIR) / "scenes";

std::string slurp(const fs::path& p) {
  std::ifstream f(p);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

class Paper : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() / ("pedalwave_paper_test_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(dir_);
  }
  paper::Settings settings(int jobs, const std::string& sub) {
    paper::Settings s;
    s.scenes_dir = kScenes;
    s.out_dir = dir_ / sub;
    s.jobs = jobs;
    s.progress = false;
    s.plots = false;
    s.log = &log_;
    return s;
  }
  struct Exit {
    int code = -1;
    std::string out, err;
  };
  Exit run_exe(const std::string& args) {
    const fs::path o = dir_ / "stdout.txt", e = dir_ / "stderr.txt";
    const std::string cmd = "'" + kExe + "' " + args + " >'" + o.string() + "' 2>'" + e.string() + "'";
    const int status = std::system(cmd.c_str());
    return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(o), slurp(e)};
  }
  fs::path dir_;
  std::ostringstream log_;
};

// ---- the engine ---------------------------------------------------------------------------------

TEST(PaperPeaks, OnePerPeriodAtTheMinimaWithTheirValues) {
  // y = −a_k sin(2π t / T) + 0.3 sin(6π t / T), amplitude a = 1 before t = 7 and 1.2 after: the
  // minima of each period are where the derivative vanishes; compare against a fine search.
  const double T = 2.0, dt = 1e-3;
  std::vector<double> t, y;
  for (int i = 0; i <= 14000; ++i) {
    const double ti = i * dt;
    const double a = ti < 7.0 ? 1.0 : 1.2;
    t.push_back(ti);
    y.push_back(-a * std::sin(2 * std::numbers::pi * ti / T) + 0.3 * std::sin(6 * std::numbers::pi * ti / T));
  }
  const auto idx = paper::negative_peaks(t, y, T);
  // The true minima sit at 0.5 + 2k (the third harmonic is −0.3 there too: y = −a − 0.3); only
  // full windows count, so the one at 0.5 (window reaching before t = 0) is left out: 2.5 … 12.5.
  ASSERT_EQ(idx.size(), 6u);
  for (std::size_t k = 0; k < idx.size(); ++k) {
    const double tk = 2.5 + 2.0 * static_cast<double>(k);
    EXPECT_NEAR(t[idx[k]], tk, 2e-3) << k;
    const double a = tk < 7.0 ? 1.0 : 1.2;
    EXPECT_NEAR(y[idx[k]], -a - 0.3, 1e-5) << k;
  }
  EXPECT_THROW((void)paper::negative_peaks({0.0, 1.0}, {0.0}, 1.0), std::invalid_argument);
}

TEST(PaperGrid, TheSweepGridHas151PointsWithExactTenths) {
  const auto g = paper::sweep_grid(0.0, 15.0, 0.1);
  ASSERT_EQ(g.size(), 151u);
  EXPECT_EQ(g.front(), 0.0);
  EXPECT_EQ(g.back(), 15.0);
  EXPECT_EQ(g[101], 10.1);  // the paper's best is a grid point, exactly
  EXPECT_EQ(g[3], 0.3);
  EXPECT_THROW((void)paper::sweep_grid(0, 1, 0), std::invalid_argument);
  EXPECT_THROW((void)paper::sweep_grid(2, 1, 0.1), std::invalid_argument);
}

TEST(PaperBest, ArgmaxIgnoresNonFiniteAndTakesTheFirstTie) {
  std::vector<paper::SweepPoint> p(4);
  p[0].speed = 0.01;
  p[1].speed = std::nan("");
  p[2].speed = 0.02;
  p[3].speed = 0.02;
  EXPECT_EQ(paper::best_index(p), 2u);
  p[2].speed = p[3].speed = p[0].speed = std::nan("");
  EXPECT_EQ(paper::best_index(p), p.size());
}

TEST(PaperParallel, RethrowsTheWorkersExceptionAndRunsEveryItemOnce) {
  std::vector<int> hits(50, 0);
  paper::parallel_for(hits.size(), 3, [&](std::size_t i) { hits[i] += 1; });
  for (int h : hits) EXPECT_EQ(h, 1);
  EXPECT_THROW(paper::parallel_for(10, 2, [](std::size_t i) { if (i == 4) throw std::runtime_error("x"); }),
               std::runtime_error);
}

// The campaign layer's local backend (what `pedalwave_paper sweep` runs, each run through its
// one-line text) against the runs made directly from the in-memory specs on the thread pool the
// tool used before: every result field bit for bit (not the CPU and wall times, measurements).
TEST_F(Paper, CampaignLocalBackendGivesTheDirectRunsBitForBit) {
  const paper::Settings s = settings(2, "campaign");
  const pedalwave::model::Scene sc = paper::load(s, "stair");
  const std::string text = slurp(paper::scene_file(s, "stair"));
  std::vector<paper::RunSpec> specs;
  std::vector<std::string> lines;
  for (double k : {0.0, 2.5, 10.1}) {
    paper::RunSpec r;
    r.scene = sc;
    r.scene.duration = 2.5;
    r.k_c = k;
    r.integ = paper::integ_of(s, sc);
    r.rate_hz = 1000.0;
    specs.push_back(r);
    lines.push_back(paper::encode_spec(r, "stair", text));
  }
  std::vector<paper::RunResult> direct(specs.size());
  paper::parallel_for(specs.size(), 2, [&](std::size_t i) { direct[i] = paper::run(specs[i]); });
  pedalwave::campaign::Options o;
  o.jobs = 2;
  o.progress = false;
  const std::vector<std::string> out = pedalwave::campaign::run("t", lines, paper::run_line, o);
  ASSERT_EQ(out.size(), specs.size());
  auto bits = [](double v) { return std::bit_cast<std::uint64_t>(v); };
  for (std::size_t i = 0; i < specs.size(); ++i) {
    const paper::RunResult c = paper::decode_result(out[i]);
    const paper::RunResult& d = direct[i];
    EXPECT_EQ(c.status, d.status);
    EXPECT_EQ(c.steps, d.steps);
    EXPECT_GT(c.steps, 0u);
    const std::vector<std::pair<double, double>> pairs{
        {c.t_end, d.t_end}, {c.avg_from, d.avg_from}, {c.avg_speed, d.avg_speed}, {c.com_x_final, d.com_x_final},
        {c.t_head_cross, d.t_head_cross}, {c.stair.x_near, d.stair.x_near}, {c.stair.x_far, d.stair.x_far},
        {c.stair.top, d.stair.top}, {c.stair.t_head_on_top, d.stair.t_head_on_top},
        {c.stair.t_com_past, d.stair.t_com_past}, {c.stair.t_body_past, d.stair.t_body_past},
        {c.stair.max_head_z, d.stair.max_head_z}};
    for (std::size_t f = 0; f < pairs.size(); ++f)
      EXPECT_TRUE(bits(pairs[f].first) == bits(pairs[f].second) ||
                  (std::isnan(pairs[f].first) && std::isnan(pairs[f].second)))
          << "run " << i << " field " << f << ": " << pairs[f].first << " vs " << pairs[f].second;
    EXPECT_TRUE(std::isfinite(c.avg_speed));
  }
  // The spec's text holds the run: decoding gives the same fields back.
  const paper::RunSpec back = paper::decode_spec(lines[2]);
  EXPECT_EQ(back.k_c, 10.1);
  EXPECT_EQ(back.scene.duration, 2.5);
  EXPECT_EQ(back.integ.method, specs[2].integ.method);
  EXPECT_EQ(bits(back.integ.h), bits(specs[2].integ.h));
  EXPECT_EQ(back.scene.boxes.size(), sc.boxes.size());
  EXPECT_THROW((void)paper::decode_spec("kind=other"), std::invalid_argument);
}

// run_group: the k_c sweep's members stepped in lockstep, their plants in SIMD lanes, each give
// what run() gives that run alone — the same status, plant steps and event times, the speed, the
// final COM and the trace to rounding (the lanes' plant equals the scalar one to ~1e-14 per step) —
// with ten members (a full group of 8 and one of 2, its free lanes padded), one of them failing
// (k_c = 1e5: the plant's state leaves the finite numbers) while the others go on. Without lanes
// (lanes false, or a scene the lanes do not run) run_group is run() bit for bit.
TEST_F(Paper, LockstepGroupGivesEachRunsResultToRounding) {
  const paper::Settings s = settings(1, "group");
  paper::RunSpec base;
  base.scene = paper::load(s, "stair");
  base.scene.duration = 6.0;
  base.integ = paper::integ_of(s, base.scene);
  base.sample_every = 0.05;
  const std::string why = paper::lockstep_refusal(base);
  if (!why.empty()) GTEST_SKIP() << "SKIPPED LOUDLY: the stair does not run in lanes here: " << why;
  const std::vector<double> ks{0.0, 1.3, 2.5, 1e5, 5.0, 7.5, 10.1, 12.0, 15.0, 3.3};
  const std::vector<paper::RunResult> group = paper::run_group(base, ks, true);
  ASSERT_EQ(group.size(), ks.size());
  double lo = 1e9, hi = -1e9;
  for (std::size_t i = 0; i < ks.size(); ++i) {
    SCOPED_TRACE("k_c = " + std::to_string(ks[i]));
    paper::RunSpec one = base;
    one.k_c = ks[i];
    const paper::RunResult d = paper::run(one);
    const paper::RunResult& g = group[i];
    EXPECT_EQ(g.status, d.status);
    EXPECT_EQ(g.steps, d.steps);
    EXPECT_EQ(g.t_end, d.t_end);
    auto same = [](double a, double b) { return a == b || (std::isnan(a) && std::isnan(b)); };
    EXPECT_TRUE(same(g.stair.t_head_on_top, d.stair.t_head_on_top)) << g.stair.t_head_on_top << " vs " << d.stair.t_head_on_top;
    EXPECT_TRUE(same(g.stair.t_com_past, d.stair.t_com_past)) << g.stair.t_com_past << " vs " << d.stair.t_com_past;
    EXPECT_TRUE(same(g.stair.max_head_z, d.stair.max_head_z) || std::abs(g.stair.max_head_z - d.stair.max_head_z) <= 1e-12)
        << g.stair.max_head_z << " vs " << d.stair.max_head_z;
    if (ks[i] == 1e5) {
      EXPECT_EQ(g.status, pedalwave::model::StepStatus::kNonFinite) << "the member meant to fail did not";
      continue;
    }
    ASSERT_EQ(d.status, pedalwave::model::StepStatus::kOk);
    EXPECT_NEAR(g.avg_speed, d.avg_speed, 1e-12);
    EXPECT_NEAR(g.com_x_final, d.com_x_final, 1e-12);
    ASSERT_EQ(g.trace.t.size(), d.trace.t.size());
    for (std::size_t k = 0; k < d.trace.t.size(); ++k) {
      EXPECT_EQ(g.trace.t[k], d.trace.t[k]);
      EXPECT_NEAR(g.trace.com_x[k], d.trace.com_x[k], 1e-12) << "sample " << k;
      EXPECT_NEAR(g.trace.tau_head[k], d.trace.tau_head[k], 1e-9) << "sample " << k;
      EXPECT_NEAR(g.trace.eta_head[k], d.trace.eta_head[k], 1e-12) << "sample " << k;
    }
    lo = std::min(lo, g.avg_speed);
    hi = std::max(hi, g.avg_speed);
  }
  EXPECT_GT(hi - lo, 1e-5) << "the members' k_c did not reach their controllers";
  // Without lanes: run() itself.
  const std::vector<paper::RunResult> plain = paper::run_group(base, {2.5}, false);
  paper::RunSpec one = base;
  one.k_c = 2.5;
  EXPECT_EQ(std::bit_cast<std::uint64_t>(plain[0].avg_speed), std::bit_cast<std::uint64_t>(paper::run(one).avg_speed));
  paper::RunSpec euler = base;
  euler.integ.method = pedalwave::model::Method::kSemiImplicitEuler;
  euler.integ.h = 2.5e-4;
  EXPECT_NE(paper::lockstep_refusal(euler), "");
}

// A group through its one-line text and the campaign's local backend: the direct run_group's
// results bit for bit, in order; a member's result independent of its group; a malformed gain
// list is named.
TEST_F(Paper, GroupLinesThroughTheCampaignGiveTheDirectGroupBitForBit) {
  const paper::Settings s = settings(2, "group_campaign");
  paper::RunSpec base;
  base.scene = paper::load(s, "stair");
  base.scene.duration = 3.0;
  base.integ = paper::integ_of(s, base.scene);
  const std::string text = slurp(paper::scene_file(s, "stair"));
  const std::vector<std::vector<double>> groups{{0.0, 4.0, 8.0}, {10.1}};
  std::vector<std::string> lines;
  for (const auto& g : groups) lines.push_back(paper::encode_group(base, g, true, "stair", text));
  pedalwave::campaign::Options o;
  o.jobs = 2;
  o.progress = false;
  const std::vector<std::string> out = pedalwave::campaign::run("g", lines, paper::run_line, o);
  ASSERT_EQ(out.size(), groups.size());
  for (std::size_t i = 0; i < groups.size(); ++i) {
    const std::vector<paper::RunResult> c = paper::decode_group_result(out[i]);
    const std::vector<paper::RunResult> d = paper::run_group(base, groups[i], true);
    ASSERT_EQ(c.size(), groups[i].size());
    for (std::size_t j = 0; j < c.size(); ++j) {
      EXPECT_EQ(std::bit_cast<std::uint64_t>(c[j].avg_speed), std::bit_cast<std::uint64_t>(d[j].avg_speed));
      EXPECT_EQ(std::bit_cast<std::uint64_t>(c[j].com_x_final), std::bit_cast<std::uint64_t>(d[j].com_x_final));
      EXPECT_EQ(c[j].steps, d[j].steps);
      EXPECT_TRUE(std::isfinite(c[j].avg_speed));
    }
  }
  // A member's result does not depend on its group: k_c = 4 alone (its lane's company padding
  // copies of it) is the second member of {0, 4, 8} bit for bit.
  const std::vector<paper::RunResult> alone = paper::run_group(base, {4.0}, true);
  const std::vector<paper::RunResult> in_group = paper::decode_group_result(out[0]);
  EXPECT_EQ(std::bit_cast<std::uint64_t>(alone[0].avg_speed), std::bit_cast<std::uint64_t>(in_group[1].avg_speed));
  EXPECT_EQ(std::bit_cast<std::uint64_t>(alone[0].com_x_final), std::bit_cast<std::uint64_t>(in_group[1].com_x_final));
  std::string bad = lines[0];
  const auto at = bad.rfind("\tk_c=");  // the group's list (the base's own k_c is inside its text)
  ASSERT_NE(at, std::string::npos);
  bad.replace(at, 5, "\tk_c=zero,");
  try {
    (void)paper::run_line(bad);
    ADD_FAILURE() << "a malformed gain list was accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("expected a comma-separated list of numbers"), std::string::npos) << e.what();
  }
}

TEST_F(Paper, AdaptiveGainReachesTheControllerAndZeroKeepsTheNominalEta) {
  paper::Settings s = settings(1, "eta");
  paper::RunSpec spec;
  spec.scene = paper::load(s, "stair");
  spec.scene.duration = 3.0;
  spec.integ = paper::integ_of(s, spec.scene);
  spec.sample_every = 0.05;
  const paper::RunResult r0 = paper::run(spec);
  spec.k_c = 10.1;
  const paper::RunResult r1 = paper::run(spec);
  ASSERT_EQ(r0.status, pedalwave::model::StepStatus::kOk);
  ASSERT_EQ(r1.status, pedalwave::model::StepStatus::kOk);
  double dev0 = 0, dev1 = 0;
  for (double e : r0.trace.eta_head) dev0 = std::max(dev0, std::abs(e - spec.scene.gait.eta));
  for (double e : r1.trace.eta_head) dev1 = std::max(dev1, std::abs(e - spec.scene.gait.eta));
  EXPECT_EQ(dev0, 0.0);
  EXPECT_GT(dev1, 1e-3);  // measured SEA torques of ~0.05 N·m move η by ~k_c Q_e / K_d
  // The box is resolved ahead of the head and the speed average starts after one gait period.
  EXPECT_NEAR(r0.avg_from, 2.0, 1e-12);
  EXPECT_GT(r0.stair.x_far, r0.stair.x_near);
  EXPECT_TRUE(std::isfinite(r0.avg_speed));
}

TEST_F(Paper, ParallelSweepGivesTheSameNumbersAsSerialAndItsBestIsItsTablesArgmax) {
  paper::SweepOptions o;
  o.from = 0.0;
  o.to = 15.0;
  o.step = 5.0;  // 0, 5, 10, 15
  o.duration = 4.0;
  o.checks = 1;
  o.check_h = 1.25e-4;  // finer than the stair scene's 2.5e-4
  const paper::SweepResult serial = paper::sweep(settings(1, "serial"), o);
  const paper::SweepResult parallel = paper::sweep(settings(2, "parallel"), o);
  ASSERT_EQ(serial.points.size(), 4u);
  ASSERT_EQ(parallel.points.size(), serial.points.size());
  for (std::size_t i = 0; i < serial.points.size(); ++i) {
    EXPECT_EQ(serial.points[i].k_c, parallel.points[i].k_c);
    EXPECT_TRUE(std::isfinite(serial.points[i].speed)) << i;
    // Bit for bit: a run depends only on its spec, never on the thread.
    EXPECT_EQ(serial.points[i].speed, parallel.points[i].speed) << "k_c = " << serial.points[i].k_c;
    EXPECT_EQ(serial.points[i].stair.max_head_z, parallel.points[i].stair.max_head_z);
  }
  EXPECT_EQ(serial.best, parallel.best);
  // The best is the argmax of the written table, and its gain is against the k_c = 0 row.
  const auto csv = pedalwave::toolkit::CsvTable::read(dir_ / "parallel" / "sweep.csv");
  const auto& k = csv.column("k_c");
  const auto& v = csv.column("speed_m_s");
  ASSERT_EQ(k.size(), 4u);
  std::size_t arg = 0;
  for (std::size_t i = 1; i < v.size(); ++i)
    if (v[i] > v[arg]) arg = i;
  EXPECT_EQ(k[arg], parallel.points[parallel.best].k_c);
  EXPECT_DOUBLE_EQ(parallel.v0, v[0]);
  EXPECT_DOUBLE_EQ(parallel.gain, v[arg] / v[0] - 1.0);
  // The accuracy check re-ran k_c = 0 at the finer step: a different, finite, close number.
  ASSERT_EQ(parallel.checks.size(), 1u);
  EXPECT_EQ(parallel.checks[0].k_c, 0.0);
  EXPECT_EQ(parallel.checks[0].speed, v[0]);
  EXPECT_TRUE(std::isfinite(parallel.checks[0].speed_fine));
  EXPECT_NEAR(parallel.checks[0].speed_fine, v[0], 5e-3);
  EXPECT_NE(slurp(dir_ / "parallel" / "sweep.md").find("Best k_c = **"), std::string::npos);
}

// The report's templates (tools/paper/report/table.md.in, fitted.md.in) and the values the tool sets agree: every
// placeholder has a value and every value a placeholder (else a TemplateError naming the line),
// also with no runs at all ("—" in every cell), and the tables keep their rows.
TEST(PaperReport, TheTemplatesAndTheToolsValuesAgree) {
  paper::AllResult r;
  std::size_t rows = 0, fitted_rows = 1;
  std::string md = paper::paper_table(r, &rows, &fitted_rows);
  EXPECT_EQ(rows, 18u);
  EXPECT_EQ(fitted_rows, 0u);
  EXPECT_EQ(md.find("{{"), std::string::npos) << md;
  EXPECT_EQ(md.rfind("## The paper's results, reproduced (`pedalwave_paper all`)\n\n| case ", 0), 0u) << md;
  EXPECT_NE(md.find("| flat, μ = 0.82: average speed "), std::string::npos) << md;
  r.fitted = paper::FittedResult{};
  r.fitted->prefix = "paper_fit_";
  r.fitted->parameters = "K = 1 N·m/rad";
  md = paper::paper_table(r, &rows, &fitted_rows);
  EXPECT_EQ(rows, 18u);
  EXPECT_EQ(fitted_rows, 9u);
  EXPECT_EQ(md.find("{{"), std::string::npos) << md;
  EXPECT_NE(md.find("`pedalwave_paper sweep --scene-prefix paper_fit_`"), std::string::npos) << md;
  EXPECT_NE(md.find("config/identify/): K = 1 N·m/rad. Tolerances"), std::string::npos) << md;
}

// ---- the executable -----------------------------------------------------------------------------

TEST_F(Paper, AllRunsEndToEndWithEveryTableRowAndFiniteNumbers) {
  const fs::path out = dir_ / "all";
  const Exit e = run_exe("all --out '" + out.string() + "' --scenes '" + kScenes.string() +
                         "' --quiet --duration 4 --friction-duration 12 --from 0 --to 0.2 --step 0.1 --checks 1 "
                         "--K 3 10 --I_r 5e-8");
  ASSERT_EQ(e.code, 0) << e.err;
  for (const char* f : {"paper_table.md", "paper.md", "flat.md", "friction.md", "stair.md", "sweep.md",
                        "sensitivity.md", "sweep.csv", "data/flat_com.json", "data/flat_high.csv",
                        "data/friction_torque.json", "data/stair_kc10.1.json", "data/stair_kc10.1.csv",
                        "data/stair_progress.json", "data/sweep_speed.json", "data/sensitivity_K.json",
                        "stair_grip/stair.md", "stair_grip/sweep.md", "stair_grip/sweep.csv",
                        "paper_fit/flat.md", "paper_fit/friction.md", "paper_fit/stair.md", "paper_fit/sweep.md"})
    EXPECT_TRUE(fs::exists(out / f)) << f;
  // The figures, drawn from data/ by tools/figures/paper.py where Debian's python3 has matplotlib.
  if (std::system("/usr/bin/python3 -c 'import matplotlib, numpy' 2>/dev/null") == 0) {
    for (const char* f : {"flat_com.png", "friction_torque.png", "stair_shapes_kc0.png", "stair_shapes_kc10.1.png",
                          "stair_film_kc0.png", "stair_progress.png", "sweep_speed.png", "sensitivity_K.png",
                          "stair_grip/stair_shapes_kc10.1.png"})
      EXPECT_TRUE(fs::exists(out / f)) << f;
  } else {
    std::printf("SKIPPED the figures' part: /usr/bin/python3 has no matplotlib\n");
  }
  const std::string both = slurp(out / "paper_table.md");
  // The shipped scenes' table, then the fitted scenes' (config/scenes/paper_fit_*).
  const auto second = both.find("## The fitted scenes beside today's assumptions");
  ASSERT_NE(second, std::string::npos) << both;
  const std::string table = both.substr(0, second), fitted = both.substr(second);
  const std::vector<std::string> cases{
      "flat, μ = 0.82: average speed", "flat, μ = 0.40: average speed", "speed gain μ = 0.82 over 0.40",
      "SEA torque-peak change after the head enters μ = 0.40", "stair, k_c = 10.1: average speed (60 s)",
      "stair, k_c = 0: average speed (60 s)", "stair, k_c = 10.1: climb", "stair, k_c = 0: climb",
      "k_c sweep: best k_c (0 … 15 step 0.1)", "k_c sweep: best over k_c = 0",
      "stair gain of k_c = 10.1 over k_c = 0", "sweep wall time (151 × 60 s)",
      "stair, edge μ = 1.5 (calibrated), k_c = 10.1: average speed (60 s)",
      "stair, edge μ = 1.5 (calibrated), k_c = 0: average speed (60 s)",
      "stair, edge μ = 1.5 (calibrated), k_c = 10.1: climb", "stair, edge μ = 1.5 (calibrated), k_c = 0: climb",
      "stair, edge μ = 1.5 (calibrated): gain of k_c = 10.1 over 0",
      "k_c sweep, edge μ = 1.5 (calibrated): best k_c, gain over k_c = 0"};
  std::size_t rows = 0;
  std::istringstream lines(table);
  for (std::string line; std::getline(lines, line);)
    if (line.rfind("| ", 0) == 0) ++rows;
  EXPECT_EQ(rows, cases.size() + 2) << table;  // + the header and the alignment row
  for (const std::string& c : cases) {
    const auto at = table.find("| " + c + " ");
    ASSERT_NE(at, std::string::npos) << c;
    const std::string row = table.substr(at, table.find('\n', at) - at);
    EXPECT_EQ(row.find("nan"), std::string::npos) << row;
    EXPECT_EQ(row.find("inf"), std::string::npos) << row;
  }
  // A sentence on every difference, and the printed numbers are finite.
  for (const char* n : {"**Flat speed**", "**Friction speed gain**", "**Torque-peak change**", "**Stair**",
                        "**k_c sweep**", "**Stair with a grippier edge"})
    EXPECT_NE(table.find(n), std::string::npos) << n;
  // The fitted table: every row, its numbers finite, its shipped column the first table's "ours".
  const std::vector<std::string> fcases{
      "flat, μ = 0.82: average speed", "flat, μ = 0.40: average speed", "speed gain μ = 0.82 over 0.40",
      "SEA torque-peak change after the head enters μ = 0.40", "stair, k_c = 10.1: average speed (60 s)",
      "stair, k_c = 0: average speed (60 s)", "stair, k_c = 10.1: climb", "stair gain of k_c = 10.1 over k_c = 0",
      "k_c sweep: best k_c, gain over k_c = 0"};
  std::size_t frows = 0;
  std::istringstream flines(fitted);
  for (std::string line; std::getline(flines, line);)
    if (line.rfind("| ", 0) == 0) ++frows;
  EXPECT_EQ(frows, fcases.size() + 2) << fitted;
  auto cells = [](const std::string& md, const std::string& c) {
    const auto at = md.find("| " + c + " ");
    std::vector<std::string> cs;
    if (at == std::string::npos) return cs;
    std::istringstream row(md.substr(at + 1, md.find('\n', at) - at - 1));
    for (std::string cell; std::getline(row, cell, '|');) {
      cell.erase(0, cell.find_first_not_of(' '));
      cell.erase(cell.find_last_not_of(' ') + 1);
      cs.push_back(cell);
    }
    return cs;
  };
  for (const std::string& c : fcases) {
    const auto row = cells(fitted, c);
    ASSERT_EQ(row.size(), 5u) << c << "\n" << fitted;
    for (const std::string& cell : row) {
      EXPECT_EQ(cell.find("nan"), std::string::npos) << c << ": " << cell;
      EXPECT_EQ(cell.find("inf"), std::string::npos) << c << ": " << cell;
    }
    EXPECT_NE(row[4].find("--scene-prefix paper_fit_"), std::string::npos) << row[4];
  }
  EXPECT_EQ(cells(fitted, "flat, μ = 0.82: average speed")[2], cells(table, "flat, μ = 0.82: average speed")[3]);
  EXPECT_NE(fitted.find("K = "), std::string::npos) << fitted;  // the fitted parameters' line
  EXPECT_NE(fitted.find(", links "), std::string::npos) << fitted;
  EXPECT_NE(e.out.find("speed μ = 0.82: "), std::string::npos);
  EXPECT_EQ(e.out.find("nan"), std::string::npos) << e.out;
  EXPECT_EQ(e.out.find("STOPPED"), std::string::npos) << e.out;
  // The sensitivity table has the baseline, K = 10 and the two model options.
  const std::string sens = slurp(out / "sensitivity.md");
  for (const char* r : {"| baseline", "| K [N·m/rad] | 10", "| friction at", "| v_s [m/s]"})
    EXPECT_NE(sens.find(r), std::string::npos) << r;
}

TEST_F(Paper, BadInputExitsTwoWithOneLine) {
  for (const std::string args : {"sweep --step 0", "flat --integrator euler --h 0.01", "flat --integrator magic --h 1e-4",
                                 "flat --h 1e-4", "stair --stair-scene nowhere",
                                 "sensitivity --K 0", "sweep --from 3 --to 1", "nonsense", "stair --k_c 1e300",
                                 "flat --duration inf", "flat --rate nan",
                                 "flat --scene-prefix nothing_", "all --scene-prefix paper_fit_"}) {
    const Exit e = run_exe(args + " --quiet --out '" + (dir_ / "bad").string() + "'");
    EXPECT_EQ(e.code, 2) << args << ": " << e.err;
    EXPECT_NE(e.err.find("error"), std::string::npos) << args;
    EXPECT_EQ(std::count(e.err.begin(), e.err.end(), '\n'), 1) << args << ": " << e.err;
  }
}

// Issue 15: a wrong subcommand is named; --stair-scene takes a path as given.
TEST_F(Paper, ABadSubcommandIsNamedAndAStairScenePathIsTakenAsGiven) {
  Exit e = run_exe("dance --quiet");
  EXPECT_EQ(e.code, 2);
  EXPECT_EQ(e.err, "pedalwave_paper: error: 'dance' is not a subcommand: expected one of flat, friction, stair, "
                   "sweep, sensitivity, all (see --help)\n");
  const std::string path = (dir_ / "my_stair.yaml").string();
  e = run_exe("stair --quiet --stair-scene '" + path + "' --out '" + (dir_ / "bad").string() + "'");
  EXPECT_EQ(e.code, 2);
  EXPECT_NE(e.err.find("no scene file " + path + "\n"), std::string::npos) << e.err;
  EXPECT_EQ(e.err.find("my_stair.yaml.yaml"), std::string::npos) << e.err;
  paper::Settings s;
  s.scenes_dir = "/scenes";
  EXPECT_EQ(paper::scene_file(s, "stair_grip"), std::filesystem::path("/scenes/stair_grip.yaml"));
  EXPECT_EQ(paper::scene_file(s, path), std::filesystem::path(path));
  EXPECT_EQ(paper::scene_file(s, "rel/x.yaml"), std::filesystem::path("rel/x.yaml"));
}

// Issue 15: a scene file the reader refuses — a duplicate key, an empty file, a value out of range,
// a faults: list — is bad input (exit 2, the reader's one line naming the file), not an internal
// error (exit 1): as --stair-scene (read before any run) and as a scene read during the run
// (--scenes).
TEST_F(Paper, ARefusedSceneFileExitsTwoWithTheReadersLine) {
  const std::string stair = slurp(kScenes / "stair.yaml");
  std::string stiff = stair;
  const std::string robot = "robot: {N: 6, joints: flexible}";
  ASSERT_NE(stiff.find(robot), std::string::npos);
  stiff.replace(stiff.find(robot), robot.size(), "robot: {N: 6, joints: flexible, K: 1e308}");
  struct Case {
    std::string name, text, message;
  };
  for (const Case& c : std::vector<Case>{
           {"dup.yaml", "name: dup\nrobot: {N: 6, N: 40}\n", ":2:15: robot.N = \"40\": expected each key once"},
           {"empty.yaml", "\n", "the file is empty"},
           {"stiff.yaml", stiff, "robot.K = \"1e308\": expected a number in (0, 1e+06] [N·m/rad]"},
           {"faulty.yaml", stair + "faults:\n  - {type: torque_gain, joint: 1, value: 0}\n",
            "expected no faults: list (pedalwave_paper does not inject them"}}) {
    SCOPED_TRACE(c.name);
    const fs::path f = dir_ / c.name;
    std::ofstream(f) << c.text;
    Exit e = run_exe("stair --quiet --no-plots --duration 0.5 --heights --stair-scene '" + f.string() + "' --out '" +
                     (dir_ / "out").string() + "'");
    EXPECT_EQ(e.code, 2) << e.err;
    EXPECT_EQ(e.err.rfind("pedalwave_paper: error: " + f.string() + ":", 0), 0u) << e.err;
    EXPECT_NE(e.err.find(c.message), std::string::npos) << e.err;
    EXPECT_EQ(std::count(e.err.begin(), e.err.end(), '\n'), 1) << e.err;
  }
  // A scene of the run itself (flat reads flat_high_friction.yaml from --scenes).
  const fs::path scenes = dir_ / "scenes";
  fs::create_directories(scenes);
  for (const char* n : {"stair", "flat_low_friction"}) fs::copy_file(kScenes / (std::string(n) + ".yaml"), scenes / (std::string(n) + ".yaml"));
  std::ofstream(scenes / "flat_high_friction.yaml") << "name: dup\nname: again\n";
  const Exit e = run_exe("flat --quiet --no-plots --duration 0.5 --scenes '" + scenes.string() + "' --out '" +
                         (dir_ / "out").string() + "'");
  EXPECT_EQ(e.code, 2) << e.err;
  EXPECT_NE(e.err.find("pedalwave_paper: error: " + (scenes / "flat_high_friction.yaml").string() + ":2:"),
            std::string::npos) << e.err;
  EXPECT_EQ(std::count(e.err.begin(), e.err.end(), '\n'), 1) << e.err;
}

}  // namespace
