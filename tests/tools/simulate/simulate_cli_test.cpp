// pedalwave_sim end to end: the built executable is run on shipped scenes into a temporary folder
// and its outputs are checked against the model (tools/simulate/, the CLI contract in main.cpp).
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/model/kinematics.hpp"
#include "pedalwave/model/plant.hpp"
#include "pedalwave/toolkit/csv.hpp"

namespace {

namespace fs = std::filesystem;

const std::string kExe = PEDALWAVE_SIM_EXE;
const std::string kScenes = std::string(PEDALWAVE_CONFIG_DIR) + "/scenes/";

struct Result {
  int code = -1;       // exit code
  std::string stdout_text;
  std::string stderr_text;
};

// Runs pedalwave_sim with `args` (already shell-quoted where needed), capturing both streams.
Result run_sim(const std::string& args, const fs::path& dir, const std::string& env = "") {
  fs::create_directories(dir);
  const fs::path out = dir / "stdout.txt", err = dir / "stderr.txt";
  const std::string cmd = env + (env.empty() ? "" : " ") + "'" + kExe + "' " + args + " >'" + out.string() + "' 2>'" + err.string() + "'";
  const int status = std::system(cmd.c_str());
  Result r;
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  auto slurp = [](const fs::path& p) {
    std::ifstream f(p);
    std::stringstream ss;
    ss << f.rdbuf();
    return ss.str();
  };
  r.stdout_text = slurp(out);
  r.stderr_text = slurp(err);
  return r;
}

class SimulateCli : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::temp_directory_path() /
           ("pedalwave_sim_test_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(dir_);
  }
  fs::path dir_;
};

// The header the CLI promises (tools/simulate/sim_run.hpp), spelled out independently.
std::vector<std::string> expected_header(int N, bool flexible) {
  std::vector<std::string> q;
  for (int j = 1; j < N; ++j) q.push_back("alpha_" + std::to_string(j));
  q.insert(q.end(), {"theta_N", "p_x", "p_z"});
  if (flexible)
    for (int j = 1; j < N; ++j) q.push_back("beta_" + std::to_string(j));
  std::vector<std::string> h{"t"};
  h.insert(h.end(), q.begin(), q.end());
  for (const auto& n : q) h.push_back(n + "_dot");
  for (int k = 0; k <= 2 * N; ++k) h.push_back("fn_" + std::to_string(k));
  for (int k = 0; k <= 2 * N; ++k) h.push_back("ft_" + std::to_string(k));
  h.push_back("v_forward");
  if (flexible)
    for (int j = 1; j < N; ++j) h.push_back("tau_sea_" + std::to_string(j));
  for (int j = 1; j < N; ++j) h.push_back("u_" + std::to_string(j));
  h.insert(h.end(), {"com_x", "com_z", "head_x", "head_z"});
  return h;
}

void expect_all_finite(const pedalwave::toolkit::CsvTable& t) {
  for (std::size_t c = 0; c < t.cols(); ++c)
    for (std::size_t i = 0; i < t.rows(); ++i)
      ASSERT_TRUE(std::isfinite(t.column(c)[i])) << t.names()[c] << " row " << i;
}

TEST_F(SimulateCli, FreeFallComFollowsTheParabolaUnderTheGaitController) {
  const Result r = run_sim("'" + kScenes + "free_fall.yaml' --duration 0.5 --every 0.01 --out '" +
                               (dir_ / "out").string() + "' --no-plots",
                           dir_);
  ASSERT_EQ(r.code, 0) << r.stderr_text;
  const auto t = pedalwave::toolkit::CsvTable::read(dir_ / "out" / "trajectory.csv");
  EXPECT_EQ(t.names(), expected_header(6, true));
  ASSERT_EQ(t.rows(), 51u);  // t = 0, 0.01, …, 0.5
  expect_all_finite(t);

  // The whole robot's COM from the scene's initial state, through the model, not the CSV.
  const auto scene = pedalwave::config::load_scene(kScenes + "free_fall.yaml");
  pedalwave::model::Plant plant(scene);
  pedalwave::model::VectorXd q, v;
  plant.initial_state(q, v);
  const auto& m = plant.model();
  pedalwave::model::Data d(m);
  pedalwave::model::update_kinematics(m, d, q, v);
  const pedalwave::model::Vec2 c0 = pedalwave::model::center_of_mass(m, d, q);
  const pedalwave::model::Vec2 v0 = pedalwave::model::linear_momentum(m, d, v) / m.total_mass();
  const double g = scene.robot.g;
  ASSERT_GT(std::abs(v0.y()), 0.1);  // the scene throws it upwards: a real parabola
  for (std::size_t i = 0; i < t.rows(); ++i) {
    const double ti = t.column("t")[i];
    EXPECT_NEAR(ti, 0.01 * static_cast<double>(i), 1e-12);
    EXPECT_NEAR(t.column("com_z")[i], c0.y() + v0.y() * ti - 0.5 * g * ti * ti, 1e-6) << "t = " << ti;
    EXPECT_NEAR(t.column("com_x")[i], c0.x() + v0.x() * ti, 1e-6) << "t = " << ti;
    EXPECT_NEAR(t.column("v_forward")[i], v0.x(), 1e-6) << "t = " << ti;
    // No ground: no contact force anywhere.
    EXPECT_EQ(t.column("fn_0")[i], 0.0);
  }
  // The controller was running (the joints were commanded) and the body deformed.
  double u_max = 0.0;
  for (double u : t.column("u_3")) u_max = std::max(u_max, std::abs(u));
  EXPECT_GT(u_max, 1e-3);
  // The summary is printed and written, and names the run's facts.
  EXPECT_NE(r.stdout_text.find("forward speed:"), std::string::npos) << r.stdout_text;
  EXPECT_NE(r.stdout_text.find("integrator cost:"), std::string::npos);
  EXPECT_NE(r.stdout_text.find("completed at t = 0.5 s"), std::string::npos) << r.stdout_text;
  EXPECT_TRUE(fs::exists(dir_ / "out" / "summary.txt"));
  EXPECT_FALSE(fs::exists(dir_ / "out" / "shapes.png"));  // --no-plots
  EXPECT_FALSE(fs::exists(dir_ / "out" / "body.csv"));
}

TEST_F(SimulateCli, PassiveFreeFallConservesEnergy) {
  // No controller, no ground, RK4: the summary's initial and final energies agree.
  const Result r = run_sim("'" + kScenes + "free_fall.yaml' --controller none --duration 0.2 --out '" +
                               (dir_ / "out").string() + "' --no-plots --quiet",
                           dir_);
  ASSERT_EQ(r.code, 0) << r.stderr_text;
  EXPECT_TRUE(r.stdout_text.empty());  // --quiet
  const auto t = pedalwave::toolkit::CsvTable::read(dir_ / "out" / "trajectory.csv");
  for (int j = 1; j <= 5; ++j)
    for (double u : t.column("u_" + std::to_string(j))) ASSERT_EQ(u, 0.0);
  std::ifstream f(dir_ / "out" / "summary.txt");
  std::string line, energy;
  while (std::getline(f, line))
    if (line.rfind("energy", 0) == 0) energy = line;
  double e0 = 0, e1 = 0;
  ASSERT_EQ(std::sscanf(energy.c_str(), "energy [J]: initial %lf, final %lf", &e0, &e1), 2) << energy;
  EXPECT_NEAR(e1, e0, 1e-3 * std::abs(e0)) << energy;  // summary prints 4 significant digits
}

TEST_F(SimulateCli, FlatSceneWritesCsvSummaryAndFigures) {
  const Result r = run_sim("'" + kScenes + "flat_high_friction.yaml' --duration 0.4 --every 0.02 --out '" +
                               (dir_ / "out").string() + "'",
                           dir_);
  ASSERT_EQ(r.code, 0) << r.stderr_text;
  const auto t = pedalwave::toolkit::CsvTable::read(dir_ / "out" / "trajectory.csv");
  EXPECT_EQ(t.names(), expected_header(6, true));
  ASSERT_EQ(t.rows(), 21u);  // 0.4 / 0.02 + 1
  expect_all_finite(t);
  // The robot rests on the ground: contact forces carry (about) its weight once settled.
  const std::size_t last = t.rows() - 1;
  double fn = 0.0;
  for (int k = 0; k <= 12; ++k) fn += t.column("fn_" + std::to_string(k))[last];
  EXPECT_GT(fn, 0.5 * (6 * 0.1 + 5 * 0.02) * 9.81);
  EXPECT_LT(fn, 3.0 * (6 * 0.1 + 5 * 0.02) * 9.81);
  EXPECT_NE(r.stdout_text.find("max penetration:"), std::string::npos);
  // The figures' data (tools/figures/simulate.py draws them; tests/tools/figures checks it).
  const auto body = pedalwave::toolkit::CsvTable::read(dir_ / "out" / "body.csv");
  EXPECT_EQ(body.rows(), 21u);
  EXPECT_EQ(body.cols(), 5u + 2u * 13u);  // t, COM, head tip, x and z of the 2N+1 points
  EXPECT_TRUE(fs::exists(dir_ / "out" / "figures.json"));
  if (std::system("/usr/bin/python3 -c 'import matplotlib, numpy' 2>/dev/null") == 0) {
    for (const char* f : {"shapes.png", "paths.png", "torques.png", "speed.png"})
      EXPECT_TRUE(fs::exists(dir_ / "out" / f)) << f << "\n" << r.stdout_text;
    // 0.4 s is shorter than one gait cycle (2 s): no gait-cycle figure.
    EXPECT_FALSE(fs::exists(dir_ / "out" / "gait_cycle.png"));
  } else {
    EXPECT_NE(r.stderr_text.find("figures skipped"), std::string::npos) << r.stderr_text;
    std::printf("SKIPPED the figures' part: /usr/bin/python3 has no matplotlib\n");
  }
}

// Without an interpreter (or matplotlib) for the figures the run still succeeds and writes its
// data; stderr says the figures were skipped and why, also with --quiet.
TEST_F(SimulateCli, WithoutPythonTheDataAreWrittenAndTheFiguresSkippedLoudly) {
  const Result r = run_sim("'" + kScenes + "flat_high_friction.yaml' --duration 0.2 --quiet --out '" +
                               (dir_ / "out").string() + "'",
                           dir_, "PEDALWAVE_PYTHON=" + (dir_ / "no-python").string());
  ASSERT_EQ(r.code, 0) << r.stderr_text;
  EXPECT_TRUE(fs::exists(dir_ / "out" / "trajectory.csv"));
  EXPECT_TRUE(fs::exists(dir_ / "out" / "body.csv"));
  EXPECT_FALSE(fs::exists(dir_ / "out" / "shapes.png"));
  EXPECT_NE(r.stderr_text.find("pedalwave_sim: figures skipped: cannot run the interpreter " +
                               (dir_ / "no-python").string()),
            std::string::npos) << r.stderr_text;
}

// Obstacle scenes get the stair events in the summary (simloop/stair_events.hpp, the code
// pedalwave_paper uses); scenes without a box get none.
TEST_F(SimulateCli, ObstacleScenesPrintTheStairEvents) {
  auto stair_line = [](const std::string& text) {
    const std::size_t at = text.find("\nstair:");
    return at == std::string::npos ? std::string() : text.substr(at + 1, text.find('\n', at + 1) - at - 1);
  };
  // The shipped stair, 1 s: the head lands on the box top at once; the COM is not past it.
  Result r = run_sim("'" + kScenes + "stair.yaml' --duration 1 --no-plots --out '" + (dir_ / "stair").string() + "'", dir_);
  ASSERT_EQ(r.code, 0) << r.stderr_text;
  std::string line = stair_line(r.stdout_text);
  double t_top = -1;
  ASSERT_EQ(std::sscanf(line.c_str(), "stair: head on top %lf s, COM past never, whole body past never", &t_top), 1) << line;
  EXPECT_GT(t_top, 0.0);
  EXPECT_LT(t_top, 1.0);
  // A box behind the robot: COM and whole body past it from the start.
  const fs::path behind = dir_ / "behind.yaml";
  std::ofstream(behind) << "name: behind\nground: {}\nobstacles:\n  - {x_near: -1.0, width: 0.1, height: 0.02}\n";
  r = run_sim("'" + behind.string() + "' --duration 0.1 --no-plots --out '" + (dir_ / "behind").string() + "'", dir_);
  ASSERT_EQ(r.code, 0) << r.stderr_text;
  line = stair_line(r.stdout_text);
  EXPECT_EQ(line.rfind("stair:            head on top never, COM past 0 s, whole body past 0 s (box x = -1 … -0.9 m, top 0.02 m)", 0), 0u)
      << line;
  r = run_sim("'" + kScenes + "flat_high_friction.yaml' --duration 0.1 --no-plots --out '" + (dir_ / "flat").string() + "'", dir_);
  ASSERT_EQ(r.code, 0) << r.stderr_text;
  EXPECT_EQ(stair_line(r.stdout_text), "") << "no box, no stair events";
}

TEST_F(SimulateCli, RigidJointsHaveNoMotorColumns) {
  const fs::path scene = dir_ / "rigid.yaml";
  std::ofstream(scene) << "name: rigid\nrobot: {N: 4, joints: rigid}\n"
                          "ground: {k: 350, d: 15, mu: 0.82}\ninitial: {pose: gait_start}\n"
                          "integrator: {method: implicit_velocity, h: 5.0e-4}\n";
  const Result r = run_sim("'" + scene.string() + "' --duration 0.1 --out '" + (dir_ / "out").string() +
                               "' --no-plots --quiet",
                           dir_);
  ASSERT_EQ(r.code, 0) << r.stderr_text;
  const auto t = pedalwave::toolkit::CsvTable::read(dir_ / "out" / "trajectory.csv");
  EXPECT_EQ(t.names(), expected_header(4, false));
  EXPECT_EQ(t.rows(), 11u);
  expect_all_finite(t);
}

TEST_F(SimulateCli, MissingSceneFileIsBadInputNamingTheFile) {
  const std::string missing = (dir_ / "no_such_scene.yaml").string();
  const Result r = run_sim("'" + missing + "' --out '" + (dir_ / "out").string() + "'", dir_);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.stderr_text.find(missing), std::string::npos) << r.stderr_text;
  EXPECT_EQ(std::count(r.stderr_text.begin(), r.stderr_text.end(), '\n'), 1) << r.stderr_text;
  EXPECT_FALSE(fs::exists(dir_ / "out"));
}

TEST_F(SimulateCli, BadYamlIsBadInputNamingFileAndKey) {
  const fs::path scene = dir_ / "bad.yaml";
  std::ofstream(scene) << "name: bad\nground: {k: 350, mu: high}\n";
  const Result r = run_sim("'" + scene.string() + "' --out '" + (dir_ / "out").string() + "'", dir_);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.stderr_text.find(scene.string()), std::string::npos) << r.stderr_text;
  EXPECT_NE(r.stderr_text.find("ground.mu"), std::string::npos) << r.stderr_text;
}

TEST_F(SimulateCli, BadOptionValuesAreBadInput) {
  const std::string scene = "'" + kScenes + "free_fall.yaml' --out '" + (dir_ / "out").string() + "' ";
  for (const std::string opt :
       {"--controller fancy", "--integrator leapfrog", "--h -1", "--rate abc",
        "--every 0.0015" /* not a multiple of 1/rate */, "--duration 0", "--unknown-flag"}) {
    const Result r = run_sim(scene + opt, dir_);
    EXPECT_EQ(r.code, 2) << opt << ": " << r.stderr_text;
    EXPECT_EQ(std::count(r.stderr_text.begin(), r.stderr_text.end(), '\n'), 1)
        << opt << ": " << r.stderr_text;
  }
}

TEST_F(SimulateCli, NonFiniteStateStopsTheRunWithExitCode3) {
  // Explicit Euler with h = 10 ms against the module PD (K_D / n² I_r ≈ 4600 1/s) diverges.
  const Result r = run_sim("'" + kScenes + "flat_high_friction.yaml' --integrator euler --h 0.01 "
                           "--rate 100 --duration 5 --out '" + (dir_ / "out").string() + "' --no-plots",
                           dir_);
  EXPECT_EQ(r.code, 3) << r.stderr_text;
  EXPECT_NE(r.stderr_text.find("NaN"), std::string::npos) << r.stderr_text;
  EXPECT_NE(r.stdout_text.find("STOPPED"), std::string::npos) << r.stdout_text;
  const auto t = pedalwave::toolkit::CsvTable::read(dir_ / "out" / "trajectory.csv");
  EXPECT_GT(t.rows(), 1u);
  EXPECT_LT(t.rows(), 501u);
  expect_all_finite(t);  // only good states were written
}

// Issue 15: every bad input is one line and exit 2, naming the option or the file, line and key.
TEST_F(SimulateCli, ContradictionsAndAbsurdValuesAreBadInput) {
  const std::string flat = "'" + kScenes + "flat_high_friction.yaml' --no-plots --quiet --out '" + (dir_ / "out").string() + "' ";
  struct Case {
    std::string args, message;
  };
  for (const Case& c : std::vector<Case>{
           {"--h 0.005", "pedalwave_sim: error: --h 0.005: expected a step ≤ the control period 1/rate = 0.001 s\n"},
           {"--h 10", "'10': expected a finite number in [1e-07, 0.1]"},
           {"--rtol 1e-6", "pedalwave_sim: error: --rtol 0.000001: expected --integrator dopri45"},
           {"--k_c 1e300", "'1e300': expected a finite number in [-1000, 1000]"},
           {"--duration nan", "'nan': expected a finite number > 0"},
           {"--duration inf", "'inf': expected a finite number > 0"}}) {
    const Result r = run_sim(flat + c.args, dir_);
    EXPECT_EQ(r.code, 2) << c.args << ": " << r.stderr_text;
    EXPECT_NE(r.stderr_text.find(c.message), std::string::npos) << c.args << ": " << r.stderr_text;
    EXPECT_EQ(std::count(r.stderr_text.begin(), r.stderr_text.end(), '\n'), 1) << c.args << ": " << r.stderr_text;
  }
  EXPECT_FALSE(fs::exists(dir_ / "out" / "trajectory.csv"));
}

TEST_F(SimulateCli, SceneValuesAreBlamedOnTheSceneKeyAndFaultsAreNotIgnored) {
  const fs::path long_scene = dir_ / "long.yaml";
  std::ofstream(long_scene) << "name: long\nground: {}\nduration: 1e300\n";
  Result r = run_sim("'" + long_scene.string() + "' --out '" + (dir_ / "out").string() + "'", dir_);
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(r.stderr_text, "pedalwave_sim: error: " + long_scene.string() +
                               ":3:11: duration = \"1e300\": expected a number in (0, 1e+06] [s]\n");
  const fs::path faulty = dir_ / "faulty.yaml";
  std::ofstream(faulty) << "name: faulty\nground: {}\nfaults:\n  - {type: torque_gain, joint: 1, value: 0}\n";
  r = run_sim("'" + faulty.string() + "' --out '" + (dir_ / "out").string() + "'", dir_);
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(r.stderr_text.rfind("pedalwave_sim: error: " + faulty.string() +
                                    ":4:3: faults = [list]: expected no faults: list (pedalwave_sim does not inject them",
                                0),
            0u)
      << r.stderr_text;
  const fs::path dup = dir_ / "dup.yaml";
  std::ofstream(dup) << "name: dup\nrobot: {N: 6, N: 40}\n";
  r = run_sim("'" + dup.string() + "' --out '" + (dir_ / "out").string() + "'", dir_);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.stderr_text.find(dup.string() + ":2:15: robot.N = \"40\": expected each key once"), std::string::npos)
      << r.stderr_text;
  const fs::path empty = dir_ / "empty.yaml";
  std::ofstream(empty) << "\n";
  r = run_sim("'" + empty.string() + "'", dir_);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.stderr_text.find("the file is empty"), std::string::npos) << r.stderr_text;
  r = run_sim("'" + dir_.string() + "'", dir_);
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.stderr_text.find(dir_.string() + ": is a directory: expected a YAML file"), std::string::npos) << r.stderr_text;
}

// A run that goes numerically wrong prints no speed and says which step would work.
TEST_F(SimulateCli, FailedRunPrintsNoSpeedAndGivesTheStabilityLimit) {
  const Result r = run_sim("'" + kScenes + "flat_high_friction.yaml' --integrator euler --h 0.01 "
                           "--rate 100 --duration 5 --out '" + (dir_ / "out").string() + "' --no-plots",
                           dir_);
  EXPECT_EQ(r.code, 3) << r.stderr_text;
  EXPECT_EQ(r.stdout_text.find("cm/s average"), std::string::npos) << r.stdout_text;
  EXPECT_NE(r.stdout_text.find("forward speed:    none (the run went numerically wrong)"), std::string::npos)
      << r.stdout_text;
  EXPECT_NE(r.stdout_text.find("stability:        h = "), std::string::npos) << r.stdout_text;
  EXPECT_NE(r.stderr_text.find("stability limit"), std::string::npos) << r.stderr_text;
  EXPECT_NE(r.stderr_text.find("use h ≤"), std::string::npos) << r.stderr_text;
  // Issue 15: only finite, meaningful values after the failure — no nan, inf or absurd numbers
  // (the diverging states' energy, motor work, penetration: "last good -nan", "motors -inf",
  // "max penetration 5.81e+143 mm") — but the time of the last good step.
  // Values print as nan, -nan, inf, -inf (lowercase; the status text "NaN/Inf" names the failure).
  const std::regex non_finite(R"((^|[^A-Za-z])[-+]?(nan|inf)([^A-Za-z]|$))");
  const std::regex absurd(R"([0-9]e\+0*[1-9][0-9]+)");  // ≥ 1e10 in any unit
  for (const std::string* text : {&r.stdout_text, &r.stderr_text}) {
    EXPECT_FALSE(std::regex_search(*text, non_finite)) << *text;
    EXPECT_FALSE(std::regex_search(*text, absurd)) << *text;
  }
  EXPECT_NE(r.stdout_text.find("the last good step ended at t = "), std::string::npos) << r.stdout_text;
  // The advised step works: the same run with it completes.
  const std::string use = "use h ≤ ";
  const std::size_t at = r.stderr_text.find(use);
  ASSERT_NE(at, std::string::npos) << r.stderr_text;
  const double h = std::stod(r.stderr_text.substr(at + use.size()));
  ASSERT_TRUE(h > 0 && h <= 0.01) << r.stderr_text;
  std::ostringstream args;
  args << "'" << kScenes << "flat_high_friction.yaml' --integrator euler --h " << h
       << " --rate 100 --duration 5 --out '" << (dir_ / "advised").string() << "' --no-plots --quiet";
  const Result advised = run_sim(args.str(), dir_);
  EXPECT_EQ(advised.code, 0) << args.str() << "\n" << advised.stderr_text;
}

// A start inside the ground: the energy line says what the ground holds at t = 0.
TEST_F(SimulateCli, EnergyLineNamesTheEnergyStoredInTheGroundAtTheStart) {
  const fs::path scene = dir_ / "sunk.yaml";
  std::ofstream(scene) << "name: sunk\nground: {k: 350, d: 15, mu: 0.82}\ninitial: {pose: flat, height: -0.001}\n"
                          "duration: 0.05\n";
  const Result r = run_sim("'" + scene.string() + "' --controller none --no-plots --quiet --out '" +
                               (dir_ / "out").string() + "'",
                           dir_);
  ASSERT_EQ(r.code, 0) << r.stderr_text;
  const std::string summary = [&] {
    std::ifstream f(dir_ / "out" / "summary.txt");
    std::stringstream ss;
    ss << f.rdbuf();
    return ss.str();
  }();
  // Flat: all 13 points 1 mm deep: 13 × ½ · 350 · (1e-3)² = 2.275e-3 J.
  EXPECT_NE(summary.find("; 0.002275 J more stored in the ground at t = 0 (the start is 1 mm inside it)"),
            std::string::npos) << summary;
  const Result flat = run_sim("'" + kScenes + "flat_high_friction.yaml' --duration 0.05 --no-plots --quiet --out '" +
                                  (dir_ / "out2").string() + "'",
                              dir_);
  ASSERT_EQ(flat.code, 0);
  std::ifstream f(dir_ / "out2" / "summary.txt");
  std::stringstream ss;
  ss << f.rdbuf();
  EXPECT_EQ(ss.str().find("stored in the ground"), std::string::npos) << "a start resting on the ground stores none";
}

}  // namespace
