// Scene files: every shipped scene loads and runs briefly; bad files are rejected with messages
// that name the file, line, key, value and expectation; only the named effects exist.
#include <gtest/gtest.h>

#include <cmath>

#include <filesystem>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/model/plant.hpp"

using namespace pedalwave;
using config::ConfigError;

namespace {
std::string error_of(const std::string& yaml) {
  try {
    config::parse_scene(yaml, "bad.yaml");
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

TEST(SceneFiles, EveryShippedSceneLoadsAndRuns) {
  int count = 0;
  for (const auto& f : std::filesystem::directory_iterator(PEDALWAVE_CONFIG_DIR "/scenes")) {
    if (f.path().extension() != ".yaml") continue;
    ++count;
    SCOPED_TRACE(f.path().string());
    const model::Scene s = config::load_scene(f.path().string());
    model::Simulation sim(s);
    ASSERT_EQ(sim.advance_to(0.05), model::StepStatus::kOk);
    EXPECT_TRUE(sim.q().allFinite());
  }
  EXPECT_GE(count, 5);
}

TEST(SceneFiles, ShippedScenesSayWhatTheyContain) {
  const auto stair = config::load_scene(PEDALWAVE_CONFIG_DIR "/scenes/stair.yaml");
  ASSERT_EQ(stair.boxes.size(), 1u);
  EXPECT_DOUBLE_EQ(stair.boxes[0].height, 0.06);
  EXPECT_DOUBLE_EQ(stair.boxes[0].width, 0.11);
  EXPECT_DOUBLE_EQ(stair.boxes[0].ahead_of_head, 0.05);
  EXPECT_TRUE(std::isnan(stair.boxes[0].edge_mu)) << "the shipped stair's edge friction is its mu";
  const auto grip = config::load_scene(PEDALWAVE_CONFIG_DIR "/scenes/stair_grip.yaml");
  ASSERT_EQ(grip.boxes.size(), 1u);
  EXPECT_DOUBLE_EQ(grip.boxes[0].mu, 0.82);
  EXPECT_DOUBLE_EQ(grip.boxes[0].edge_mu, 1.5);
  EXPECT_NEAR(stair.gait.eta, -2 * M_PI / 5, 1e-15);
  // The box is placed 5 cm ahead of the head tip of the initial state.
  model::Plant p(stair);
  model::VectorXd q, v;
  p.initial_state(q, v);
  model::update_kinematics(p.model(), p.data(), q, v);
  const double head = model::point_position(p.model(), p.data(), q, p.model().point_head()).x();
  EXPECT_NEAR(p.scene().boxes[0].x_near - head, 0.05, 1e-12);

  const auto change = config::load_scene(PEDALWAVE_CONFIG_DIR "/scenes/friction_change.yaml");
  ASSERT_EQ(change.ground.patches.size(), 1u);
  EXPECT_DOUBLE_EQ(change.ground.patches[0].mu, 0.40);
  const auto fall = config::load_scene(PEDALWAVE_CONFIG_DIR "/scenes/free_fall.yaml");
  EXPECT_FALSE(fall.ground_on);
  EXPECT_TRUE(fall.boxes.empty());
}

TEST(SceneFiles, ErrorsNameFileLineKeyValueAndExpectation) {
  std::string e = error_of("ground:\n  k: 350\n  mu: high\n");
  EXPECT_NE(e.find("bad.yaml:3:"), std::string::npos) << e;
  EXPECT_NE(e.find("ground.mu = \"high\""), std::string::npos) << e;
  EXPECT_NE(e.find("expected a number"), std::string::npos) << e;

  e = error_of("grund: {k: 350}\n");
  EXPECT_NE(e.find("unknown key 'grund'"), std::string::npos) << e;
  EXPECT_NE(e.find("expected one of"), std::string::npos) << e;

  e = error_of("ground: {mu: -1}\n");
  EXPECT_NE(e.find("ground.mu = \"-1\": expected a number in [0, 10]"), std::string::npos) << e;

  e = error_of("robot: {N: 1}\n");
  EXPECT_NE(e.find("robot.N = \"1\": expected an integer in [2, 64]"), std::string::npos) << e;

  e = error_of("robot: {I_r: 0}\n");
  EXPECT_NE(e.find("I_r = 0"), std::string::npos) << e;
  EXPECT_NE(e.find("rigid"), std::string::npos) << e;

  e = error_of("integrator: {method: magic}\n");
  EXPECT_NE(e.find("integrator.method = \"magic\": expected one of euler"), std::string::npos) << e;

  e = error_of("ground: {}\nobstacles:\n  - {width: 0.1, height: 0.06}\n");
  EXPECT_NE(e.find("exactly one of x_near"), std::string::npos) << e;

  e = error_of("ground: {}\nobstacles:\n  - {x_near: 0.2, edge_mu: -1}\n");
  EXPECT_NE(e.find("edge_mu = \"-1\": expected a number in [0, 10]"), std::string::npos) << e;

  e = error_of("ground: {friction: sticky}\n");
  EXPECT_NE(e.find("one of coulomb, regularized, tanh, stick_slip"), std::string::npos) << e;

  e = error_of("initial: {pose: explicit, q: [1, 2]}\n");
  EXPECT_NE(e.find("initial.q"), std::string::npos) << e;

  e = error_of("ground: [1, 2\n");
  EXPECT_NE(e.find("YAML syntax error"), std::string::npos) << e;

  EXPECT_THROW(config::load_scene("/nonexistent/scene.yaml"), ConfigError);
}

TEST(SceneFiles, AnglesMayBeWrittenWithPi) {
  const auto s = config::parse_scene("gait: {A_p: pi/4, omega: 2*pi, eta: -2*pi/5}\n", "x.yaml");
  EXPECT_DOUBLE_EQ(s.gait.A_p, M_PI / 4);
  EXPECT_DOUBLE_EQ(s.gait.omega, 2 * M_PI);
  EXPECT_DOUBLE_EQ(s.gait.eta, -2 * M_PI / 5);
}

// A start deep inside the ground or a box is refused for every pose (k·depth ≤ 10 × the weight;
// 6.87 N at k = 1e5 allows 0.69 mm), blamed on what put the robot there.
TEST(SceneFiles, ADeepStartIsRefusedForEveryPoseAndInsideBoxes) {
  // pose: explicit, the robot flat 2 cm into the ground: q = [α×5, θ_N, p_x, p_z, β×5].
  std::string e = error_of("ground: {k: 1e5}\ninitial:\n  pose: explicit\n"
                           "  q: [0, 0, 0, 0, 0, 0, 0, -0.02, 0, 0, 0, 0, 0]\n");
  EXPECT_EQ(e.rfind("bad.yaml:4:6: initial.q = [list]: expected a start at most 0.0006867", 0), 0u) << e;
  EXPECT_NE(e.find("this start is 0.02 m deep"), std::string::npos) << e;
  // A box the flat robot lies inside (its top 5 cm above the links).
  e = error_of("ground: {k: 1e5}\nobstacles:\n  - {x_near: -0.1, width: 0.2, height: 0.05}\n");
  EXPECT_EQ(e.rfind("bad.yaml:3:3: obstacles = [list]: expected a start at most 0.0006867", 0), 0u) << e;
  EXPECT_NE(e.find("inside an obstacle"), std::string::npos) << e;
  // The same box ahead of the head, and a resting explicit start, load.
  EXPECT_EQ(error_of("ground: {k: 1e5}\nobstacles:\n  - {ahead_of_head: 0.05, width: 0.2, height: 0.05}\n"), "");
  EXPECT_EQ(error_of("ground: {k: 1e5}\ninitial:\n  pose: explicit\n"
                     "  q: [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]\n"), "");
}

// initial.theta: the base angle, default the one that levels the chord (model::InitialState).
TEST(SceneFiles, InitialThetaIsTheBaseAngle) {
  const auto s = config::parse_scene("ground: {}\ninitial: {pose: gait_start, theta: 0.3}\n", "x.yaml");
  EXPECT_DOUBLE_EQ(s.initial.theta, 0.3);
  EXPECT_TRUE(std::isnan(config::parse_scene("initial: {pose: gait_start}\n", "x.yaml").initial.theta));
  std::string e = error_of("initial: {pose: gait_start, theta: 4}\n");
  EXPECT_NE(e.find("initial.theta = \"4\": expected a number in [-3.14159"), std::string::npos) << e;
  e = error_of("initial:\n  pose: explicit\n  theta: 0\n  q: [0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]\n");
  EXPECT_NE(e.find("bad.yaml:3:10: initial.theta = \"0\": expected no theta with pose: explicit"), std::string::npos) << e;
  // The shipped 6-link scenes keep link N flat (theta: 0), the start the README's numbers had.
  for (const char* name : {"flat_high_friction", "flat_low_friction", "friction_change", "stair", "stair_grip"})
    EXPECT_EQ(config::load_scene(std::string(PEDALWAVE_CONFIG_DIR "/scenes/") + name + ".yaml").initial.theta, 0.0)
        << name;
}
