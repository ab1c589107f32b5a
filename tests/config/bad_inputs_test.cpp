// Bad input in the YAML files (issue 15): every documented key of a scene and of a daemon
// configuration refuses a wrong type, a value out of its range and a repeated key, each with one
// line naming the file, line, key, value and what was expected
// (`bad.yaml:3:6: ground.k = "1e308": expected a number in (0, 1e+07] [N/m]`). A table drives it:
// one row per key, its YAML with `@` where the value goes. It stays whole: a key the readers accept
// without a row fails EveryKeyTheReadersAcceptHasARow, a scene key missing from
// config/scenes/README.md's table fails EverySceneKeyWithARowIsInTheReadmeTable, a daemon key
// missing from config/runtime/README.md's tables fails EveryDaemonKeyWithARowIsInTheReadmeTable.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <cctype>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include "pedalwave/config/daemon.hpp"
#include "pedalwave/config/scene.hpp"

using namespace pedalwave;
using config::ConfigError;

namespace {

struct KeyRow {
  std::string path;       // the key path the message must name
  std::string yaml;       // the file, `@` where the value goes (on its own line)
  std::string good;       // a value the key accepts
  std::string bad_type;   // a value of the wrong type
  std::string bad_range;  // a value of the right type, out of its range ("" = no range); a list
                          // `[x]` for a list key: the message names its element, path[0] = "x"
  std::string expected;   // what the range message says it expected
};

// How a message shows a value: a list as [list], a map as {map}, a scalar quoted.
std::string shown(const std::string& v) {
  return v[0] == '[' ? "[list]" : v[0] == '{' ? "{map}" : "\"" + v + "\"";
}

std::string with(const std::string& yaml, const std::string& v) {
  std::string s = yaml;
  s.replace(s.find('@'), 1, v);
  return s;
}
// 1-based line of the `@`.
int line_of_value(const std::string& yaml) {
  return 1 + static_cast<int>(std::count(yaml.begin(), yaml.begin() + static_cast<long>(yaml.find('@')), '\n'));
}
// The same file with the `@` line given twice (the second one is the duplicate).
std::string duplicated(const std::string& yaml, const std::string& v) {
  const std::size_t at = yaml.find('@');
  const std::size_t b = yaml.rfind('\n', at) + 1;  // npos + 1 = 0 on the first line
  const std::size_t e = yaml.find('\n', at);
  const std::string line = yaml.substr(b, e - b + 1);
  std::string s = yaml;
  s.insert(b, line);
  return with(with(s, v), v);
}

template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const ConfigError& e) {
    return e.what();
  }
  return "(no error)";
}

std::string scene_error(const std::string& yaml) {
  return error_of([&] { config::parse_scene(yaml, "bad.yaml"); });
}
std::string daemon_error(const std::string& yaml) {
  return error_of([&] { config::parse_daemon_config(yaml, "bad.yaml", PEDALWAVE_CONFIG_DIR "/runtime"); });
}

bool one_line(const std::string& e) { return e.find('\n') == std::string::npos; }

// Runs the three checks of one row with `error` (scene or daemon).
template <class E>
void check_row(const KeyRow& k, E&& error) {
  SCOPED_TRACE(k.path);
  const std::string at = "bad.yaml:" + std::to_string(line_of_value(k.yaml)) + ":";
  EXPECT_EQ(error(with(k.yaml, k.good)), "(no error)") << "the good value " << k.good;
  std::string e = error(with(k.yaml, k.bad_type));
  EXPECT_EQ(e.rfind(at, 0), 0u) << e;
  EXPECT_NE(e.find(k.path + " = " + shown(k.bad_type) + ": expected "), std::string::npos) << e;
  EXPECT_TRUE(one_line(e)) << e;
  if (!k.bad_range.empty()) {
    e = error(with(k.yaml, k.bad_range));
    EXPECT_EQ(e.rfind(at, 0), 0u) << e;
    const bool element = k.bad_range[0] == '[';
    const std::string named = element ? k.path + "[0] = \"" + k.bad_range.substr(1, k.bad_range.size() - 2) + "\""
                                      : k.path + " = \"" + k.bad_range + "\"";
    EXPECT_NE(e.find(named + ": expected " + k.expected), std::string::npos) << e;
    EXPECT_TRUE(one_line(e)) << e;
  }
  // The duplicate is reported where it stands: the line after the first.
  e = error(duplicated(k.yaml, k.good));
  const std::string dup_at = "bad.yaml:" + std::to_string(line_of_value(k.yaml) + 1) + ":";
  EXPECT_EQ(e.rfind(dup_at, 0), 0u) << e;
  EXPECT_NE(e.find(k.path + " = " + shown(k.good) + ": expected each key once"), std::string::npos) << e;
  EXPECT_TRUE(one_line(e)) << e;
}

const std::vector<KeyRow> kSceneKeys = {
    {"name", "name: @\n", "stair", "[1]", "runs/stair", "a name of 1 … 63 characters, no '/'"},
    {"description", "description: @\n", "a stair", "{a: 1}", "", ""},
    {"robot.N", "robot:\n  N: @\n", "8", "six", "1", "an integer in [2, 64]"},
    {"robot.m_l", "robot:\n  m_l: @\n", "0.2", "heavy", "0", "a number in (0, 1000] [kg]"},
    {"robot.link_length", "robot:\n  link_length: @\n", "0.08", "long", "1e300", "a number in (0, 10] [m]"},
    {"robot.I_l", "robot:\n  I_l: @\n", "1e-4", "[1, 2]", "-1", "a number in (0, 1000]"},
    {"robot.m_r", "robot:\n  m_r: @\n", "0.03", "x", "-0.1", "a number in [0, 1000] [kg]"},
    {"robot.I_r", "robot:\n  I_r: @\n", "1e-7", "x", "5", "a number in [0, 1]"},
    {"robot.n", "robot:\n  n: @\n", "100", "x", "0", "a number in (0, 100000]"},
    {"robot.K", "robot:\n  K: @\n", "5", "stiff", "1e308", "a number in (0, 1e+06] [N·m/rad]"},
    {"robot.g", "robot:\n  g: @\n", "3.7", "x", "-9.81", "a number in [0, 100]"},
    {"robot.joints", "robot:\n  joints: @\n", "rigid", "[1]", "elastic", "one of flexible, rigid"},
    {"robot.rigid_variant", "robot:\n  joints: rigid\n  rigid_variant: @\n", "paper", "[1]", "printed",
     "one of exact_limit, paper"},
    {"robot.link_shape", "robot:\n  link_shape: @\n", "segment", "[1]", "round", "one of segment, capsule, box"},
    {"robot.link_radius", "robot:\n  link_shape: capsule\n  link_radius: @\n", "0.015", "x", "0",
     "a number in (0, 1] [m]"},
    {"robot.link_height", "robot:\n  link_shape: box\n  link_height: @\n", "0.03", "x", "-0.03",
     "a number in (0, 2] [m]"},
    {"ground.z", "ground:\n  z: @\n", "0.1", "low", "1e300", "a number in [-1000, 1000] [m]"},
    {"ground.k", "ground:\n  k: @\n", "1000", "soft", "1e308", "a number in (0, 1e+07] [N/m]"},
    {"ground.d", "ground:\n  d: @\n", "10", "x", "-1", "a number in [0, 100000]"},
    {"ground.mu", "ground:\n  mu: @\n", "0.5", "high", "-1", "a number in [0, 10]"},
    {"ground.friction", "ground:\n  friction: @\n", "tanh", "[1]", "sticky", "one of coulomb, regularized, tanh, stick_slip"},
    {"ground.v_s", "ground:\n  v_s: @\n", "0.01", "x", "0", "a number in (0, 10]"},
    {"ground.k_t", "ground:\n  k_t: @\n", "500", "x", "-5", "a number in (0, 1e+08]"},
    {"ground.friction_at_com", "ground:\n  friction_at_com: @\n", "true", "maybe", "", ""},
    {"ground.patches[0].x_begin", "ground:\n  patches:\n    - mu: 0.4\n      x_begin: @\n", "0.3", "far",
     "1e300", "a number in [-10000, 10000] [m]"},
    {"ground.patches[0].mu", "ground:\n  patches:\n    - x_begin: 0.3\n      mu: @\n", "0.4", "x", "-0.4",
     "a number in [0, 10]"},
    {"obstacles[0].x_near", "ground: {}\nobstacles:\n  - width: 0.1\n    x_near: @\n", "0.2", "near", "nan",
     "a number in [-10000, 10000] [m]"},
    {"obstacles[0].ahead_of_head", "ground: {}\nobstacles:\n  - width: 0.1\n    ahead_of_head: @\n", "0.05",
     "x", "inf", "a number in [-10000, 10000]"},
    {"obstacles[0].width", "ground: {}\nobstacles:\n  - x_near: 0.2\n    width: @\n", "0.1", "wide", "0",
     "a number in (0, 1000] [m]"},
    {"obstacles[0].height", "ground: {}\nobstacles:\n  - x_near: 0.2\n    height: @\n", "0.05", "x", "20",
     "a number in (0, 10] [m]"},
    {"obstacles[0].mu", "ground: {}\nobstacles:\n  - x_near: 0.2\n    mu: @\n", "0.5", "x", "11", "a number in [0, 10]"},
    {"obstacles[0].edge_mu", "ground: {}\nobstacles:\n  - x_near: 0.2\n    edge_mu: @\n", "1.5", "x", "-1",
     "a number in [0, 10]"},
    {"obstacles[0].corner_contact", "ground: {}\nobstacles:\n  - x_near: 0.2\n    corner_contact: @\n", "false",
     "sometimes", "", ""},
    {"obstacles[0].type", "ground: {}\nobstacles:\n  - x_near: 0.2\n    type: @\n", "box", "[1]", "sphere", "one of box"},
    {"joint_friction.motor_viscous", "joint_friction:\n  motor_viscous: @\n", "0.01", "x", "-1",
     "a number in [0, 1000]"},
    {"torque_limit.u_max", "torque_limit:\n  u_max: @\n", "1", "x", "0", "a number in (0, 10000] [N·m]"},
    {"sensor_noise.beta_sigma", "sensor_noise:\n  beta_sigma: @\n", "1e-3", "x", "-1", "a number in [0, 10] [rad]"},
    {"sensor_noise.beta_dot_sigma", "sensor_noise:\n  beta_dot_sigma: @\n", "1e-2", "x", "1e9", "a number in [0, 1000]"},
    {"sensor_noise.deflection_sigma", "sensor_noise:\n  deflection_sigma: @\n", "1e-3", "x", "-1", "a number in [0, 10]"},
    {"sensor_noise.encoder_resolution", "sensor_noise:\n  encoder_resolution: @\n", "1e-3", "x", "2", "a number in [0, 1]"},
    {"sensor_noise.deflection_resolution", "sensor_noise:\n  deflection_resolution: @\n", "1e-3", "x", "-2",
     "a number in [0, 1]"},
    {"sensor_noise.seed", "sensor_noise:\n  seed: @\n", "7", "x", "-1", "an integer in [0, "},
    {"initial.pose", "initial:\n  pose: @\n", "air", "[1]", "upside_down", "one of flat, gait_start, air, explicit"},
    {"initial.x", "initial:\n  x: @\n", "0.5", "x", "1e300", "a number in [-10000, 10000] [m]"},
    {"initial.height", "initial:\n  height: @\n", "0.1", "x", "-0.5", "a number in [-0.1, 100] [m]"},
    {"initial.theta", "initial:\n  pose: gait_start\n  theta: @\n", "0.3", "x", "4", "a number in [-3.14159, 3.14159] [rad]"},
    {"initial.q", "initial:\n  pose: explicit\n  q: @\n", "[0, 0, 0, 0, 0, 0, 0, 0.5, 0, 0, 0, 0, 0]", "{a: 1}",
     "[1e5]", "a number in [-10000, 10000] [rad or m]"},
    {"initial.v", "initial:\n  v: @\n", "0", "{a: 1}", "1e9", "a number in [-1000, 1000]"},
    {"gait.A_p", "gait:\n  A_p: @\n", "pi/4", "x", "7", "a number in [-3.14159, 3.14159] [rad]"},
    {"gait.omega", "gait:\n  omega: @\n", "2*pi", "x", "1e6", "a number in [-100, 100] [rad/s]"},
    {"gait.eta", "gait:\n  eta: @\n", "-2*pi/5", "x", "100", "a number in [-6.28319, 6.28319] [rad]"},
    {"duration", "duration: @\n", "5", "long", "1e300", "a number in (0, 1e+06] [s]"},
    {"integrator.method", "integrator:\n  method: @\n", "rk4", "[1]", "magic", "one of euler"},
    {"integrator.h", "integrator:\n  h: @\n", "1e-4", "x", "1e-15", "a number in [1e-07, 0.1] [s]"},
    {"integrator.rtol", "integrator:\n  method: dopri45\n  rtol: @\n", "1e-6", "x", "0", "a number in (0, 1]"},
    {"integrator.atol", "integrator:\n  method: dopri45\n  atol: @\n", "1e-6", "x", "-1", "a number in (0, 1]"},
    {"integrator.h_min", "integrator:\n  method: dopri45\n  h_min: @\n", "1e-9", "x", "1", "a number in [1e-12, 0.1]"},
    {"integrator.h_max", "integrator:\n  method: dopri45\n  h_max: @\n", "1e-3", "x", "10", "a number in [1e-07, 1]"},
    {"faults[0].type", "faults:\n  - joint: 0\n    type: @\n", "nan", "[1]", "gremlin", "one of torque_gain"},
    {"faults[0].joint", "faults:\n  - type: nan\n    joint: @\n", "4", "x", "5", "an integer in [0, 4]"},
    {"faults[0].t_start", "faults:\n  - type: nan\n    t_start: @\n", "1", "x", "-1", "a number in [0, 1e+06] [s]"},
    {"faults[0].value", "faults:\n  - type: stale\n    value: @\n", "15", "x", "16", "an integer in [1, 15]"},
    {"faults[0].duration", "faults:\n  - type: nan\n    duration: @\n", "1", "x", "0", "a number in (0, 1e+06] [s]"},
};

}  // namespace

TEST(BadInputs, EverySceneKeyRefusesWrongTypeWrongRangeAndDuplicate) {
  for (const KeyRow& k : kSceneKeys) check_row(k, scene_error);
}

TEST(BadInputs, DuplicateKeysAtAnyLevelAndInFlowMaps) {
  std::string e = scene_error("robot: {N: 6, N: 40}\n");
  EXPECT_EQ(e, "bad.yaml:1:15: robot.N = \"40\": expected each key once (duplicate key: 'N' is already "
               "given at line 1)");
  e = scene_error("ground: {k: 350}\nduration: 5\nground: {k: 10}\n");
  EXPECT_EQ(e.rfind("bad.yaml:3:1: ground = {map}: expected each key once", 0), 0u) << e;
  e = scene_error("ground: {}\nobstacles:\n  - {x_near: 0.2, width: 0.1, width: 0.2}\n");
  EXPECT_EQ(e.rfind("bad.yaml:3:31: obstacles[0].width = \"0.2\": expected each key once", 0), 0u) << e;
}

// Found by the YAML fuzzer (config/fuzz): a quoted key with a newline made a two-line message.
TEST(BadInputs, MessagesStayOnOneLineWhateverTheKeyHolds) {
  const std::string e = scene_error("\"durat\\nion\": 5\n");
  EXPECT_EQ(e.rfind("bad.yaml:1:1: unknown key 'durat\\nion': expected one of name", 0), 0u) << e;
  EXPECT_TRUE(one_line(e)) << e;
  EXPECT_EQ(config::one_line("a\tb\x01" "c"), "a\\tb\\x01c");
}

TEST(BadInputs, EmptyFileDirectoryAndDevicesAreRefused) {
  const auto dir = std::filesystem::temp_directory_path() / ("pw_bad_inputs_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string empty = (dir / "empty.yaml").string();
  { std::ofstream(empty) << "# nothing but a comment\n"; }
  std::string e = error_of([&] { config::load_scene(empty); });
  EXPECT_EQ(e, empty + ":1:1: (top level) = \"\": expected a YAML map of keys (the file is empty)");
  e = error_of([&] { config::load_daemon_config(empty); });
  EXPECT_EQ(e, empty + ":1:1: (top level) = \"\": expected a YAML map of keys (the file is empty)");
  e = error_of([&] { config::load_scene(dir.string()); });
  EXPECT_EQ(e, dir.string() + ": is a directory: expected a YAML file");
  e = error_of([&] { config::load_daemon_config("/dev/zero"); });
  EXPECT_EQ(e, "/dev/zero: is not a regular file (a device, a pipe or a socket): expected a YAML file");
  const std::string big = (dir / "big.yaml").string();
  { std::ofstream(big) << "name: x\n" << std::string(config::kMaxFileBytes, '#') << '\n'; }
  e = error_of([&] { config::load_scene(big); });
  EXPECT_NE(e.find(big + ": is "), std::string::npos) << e;
  EXPECT_NE(e.find("expected a YAML file of at most 1048576 bytes"), std::string::npos) << e;
  std::filesystem::remove_all(dir);
}

TEST(BadInputs, SceneContradictionsAreRefused) {
  std::string e = scene_error("robot:\n  rigid_variant: paper\n");
  EXPECT_EQ(e.rfind("bad.yaml:2:18: robot.rigid_variant = \"paper\": expected joints: rigid beside it", 0), 0u) << e;
  // A link's size goes with its shape: required with it, refused with another one.
  e = scene_error("robot:\n  link_radius: 0.01\n");
  EXPECT_EQ(e.rfind("bad.yaml:2:16: robot.link_radius = \"0.01\": expected link_shape: capsule beside it", 0), 0u) << e;
  e = scene_error("robot:\n  link_shape: capsule\n  link_height: 0.03\n");
  EXPECT_NE(e.find("robot.link_radius: expected the capsule's radius [m] with link_shape: capsule"), std::string::npos) << e;
  e = scene_error("robot:\n  link_shape: box\n  link_height: 0.03\n  link_radius: 0.01\n");
  EXPECT_NE(e.find("robot.link_radius = \"0.01\": expected link_shape: capsule beside it (the radius of a capsule "
                   "link; the shape is box)"), std::string::npos) << e;
  e = scene_error("robot:\n  link_shape: box\n");
  EXPECT_NE(e.find("robot.link_height: expected the module's height [m] with link_shape: box"), std::string::npos) << e;
  // Effects a thick link does not have are refused, naming the key.
  e = scene_error("robot: {link_shape: capsule, link_radius: 0.01}\nground: {friction: stick_slip}\n");
  EXPECT_NE(e.find("ground.friction = \"stick_slip\": expected coulomb, regularized or tanh with robot.link_shape: "
                   "capsule"), std::string::npos) << e;
  e = scene_error("robot: {link_shape: box, link_height: 0.03}\nground: {friction_at_com: true}\n");
  EXPECT_NE(e.find("ground.friction_at_com = \"true\": expected false with robot.link_shape: box"), std::string::npos) << e;
  e = scene_error("integrator:\n  method: rk4\n  rtol: 1e-6\n");
  EXPECT_EQ(e.rfind("bad.yaml:3:9: integrator.rtol = \"1e-6\": expected integrator.method: dopri45 beside it", 0), 0u)
      << e;
  e = scene_error("integrator:\n  rtol: 1e-6\n");  // the default method is implicit_velocity
  EXPECT_NE(e.find("integrator.rtol = \"1e-6\": expected integrator.method: dopri45 beside it (rtol is the "
                   "adaptive method's; method is implicit_velocity)"), std::string::npos) << e;
  e = scene_error("robot:\n  N: 4\n  K: [1, 2]\n");
  EXPECT_EQ(e.rfind("bad.yaml:3:6: robot.K = [list]: expected one stiffness for every joint or N-1 = 3", 0), 0u) << e;
  e = scene_error("faults:\n  - {type: stale, value: 0}\n");
  EXPECT_NE(e.find("bad.yaml:2:26: faults[0].value = \"0\": expected an integer in [1, 15]"), std::string::npos) << e;
  // 2 cm into a k = 1e5 ground would launch the robot (10 × its weight 6.87 N allows 0.69 mm).
  e = scene_error("ground: {k: 1e5}\ninitial:\n  height: -0.02\n");
  EXPECT_EQ(e.rfind("bad.yaml:3:11: initial.height = \"-0.02\": expected a start at most 0.0006867", 0), 0u) << e;
  EXPECT_EQ(scene_error("ground: {k: 350}\ninitial:\n  height: -0.002\n"), "(no error)")
      << "a shallow start in a soft ground is a documented option";
  e = scene_error("faults:\n  - {type: spring_scale, value: 0}\n");
  EXPECT_NE(e.find("faults[0].value = \"0\": expected a number in (0, 1e+06]"), std::string::npos) << e;
}

// A tool that ignores the faults list refuses the scene instead of running it fault-free.
TEST(BadInputs, FaultsInASceneForAToolThatIgnoresThem) {
  const auto dir = std::filesystem::temp_directory_path() / ("pw_bad_faults_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string f = (dir / "faulty.yaml").string();
  { std::ofstream(f) << "name: faulty\nfaults:\n  - {type: nan, joint: 1}\n"; }
  const std::string e = error_of([&] { config::load_scene(f, {.faults = false, .consumer = "pedalwave_sim"}); });
  EXPECT_EQ(e.rfind(f + ":3:3: faults = [list]: expected no faults: list (pedalwave_sim does not inject them", 0), 0u) << e;
  EXPECT_EQ(config::load_scene(f).faults.size(), 1u) << "a program that injects them reads them";
  std::filesystem::remove_all(dir);
}

// ---- the daemon configuration ----

namespace {
const std::string kSimDriver = "driver:\n  type: sim\n  scene: ../scenes/flat_high_friction.yaml\n";
const std::string kCan = "rate_hz: 100\ndriver: {type: socketcan, fd: true}\n";
const std::vector<KeyRow> kDaemonKeys = {
    {"name", "name: @\n" + kSimDriver, "walker", "[1]", std::string(64, 'w'), "a name of 1 … 63 characters"},
    {"description", "description: @\n" + kSimDriver, "a walk", "{a: 1}", "", ""},
    {"log_file", kSimDriver + "log_file: @\n", "/tmp/pedalwave.log", "[1]", "/tmp", "a file path (not a folder"},
    {"rate_hz", "rate_hz: @\n" + kSimDriver, "500", "fast", "1e9", "a rate in (0, 20000] Hz"},
    {"duration", "duration: @\n" + kSimDriver, "2", "long", "1e300", "a number in [0, 1e+07] [s]"},
    {"driver.type", "rate_hz: 250\ndriver:\n  type: @\n", "socketcan", "[1]", "usb", "one of sim, socketcan, serial"},
    {"driver.scene", "driver:\n  type: sim\n  scene: @\n", "../scenes/stair.yaml", "[1]", "no_such_scene.yaml",
     "an existing scene file (there is no "},
    {"driver.clock", kSimDriver + "  clock: @\n", "free_running", "[1]", "sundial", "one of lockstep, free_running"},
    {"driver.command_timeout", kSimDriver + "  command_timeout: @\n", "0.1", "x", "1e9", "a number in (0, 10] [s]"},
    {"driver.ifname", "rate_hz: 250\ndriver:\n  type: socketcan\n  ifname: @\n", "can1", "[1]", "a/b", "a network interface name"},
    {"driver.bitrate", "rate_hz: 100\ndriver:\n  type: socketcan\n  bitrate: @\n", "500000", "x", "1e300", "a number in (0, 1e+06]"},
    {"driver.fd", "rate_hz: 100\ndriver:\n  type: socketcan\n  fd: @\n", "true", "sometimes", "", ""},
    {"driver.data_bitrate", "rate_hz: 100\ndriver:\n  type: socketcan\n  fd: true\n  data_bitrate: @\n", "2e6", "x",
     "1e8", "a number in (0, 1.2e+07] [bit/s]"},
    {"driver.max_load", "rate_hz: 100\ndriver:\n  type: socketcan\n  max_load: @\n", "0.5", "x", "2", "a number in (0, 1]"},
    {"driver.protocol", "rate_hz: 100\ndriver:\n  type: socketcan\n  protocol: @\n", "pedalwave", "[1]", "j1939",
     "one of pedalwave, canopen"},
    {"driver.nodes", "rate_hz: 100\nrobot: {N: 2}\ndriver:\n  type: socketcan\n  protocol: canopen\n  drive_mode: csp\n  nodes: @\n",
     "[7]", "x", "[0]", "a node id, an integer in 1 … 127"},
    {"driver.drive_mode", "rate_hz: 100\ndriver:\n  type: socketcan\n  protocol: canopen\n  drive_mode: @\n", "csp", "[1]",
     "cyclic", "one of cst, csp"},
    {"driver.heartbeat", "rate_hz: 100\ndriver:\n  type: socketcan\n  protocol: canopen\n  drive_mode: csp\n  heartbeat: @\n",
     "0.02", "x", "100", "a number in [0.001, 65.535] [s]"},
    {"driver.heartbeat_timeout",
     "rate_hz: 100\ndriver:\n  type: socketcan\n  protocol: canopen\n  drive_mode: csp\n  heartbeat_timeout: @\n", "0.5", "x",
     "0", "a number in (0, 100] [s]"},
    {"driver.sync_window",
     "rate_hz: 100\ndriver:\n  type: socketcan\n  protocol: canopen\n  drive_mode: csp\n  sync_window: @\n", "0.5", "x",
     "1", "a number in [0, 0.95] [of the SYNC period]"},
    // 3500000 was in [9600, 4e6] and loaded; opening the port refused it (the driver's kSerialBauds).
    {"driver.baud", "rate_hz: 250\ndriver:\n  type: serial\n  baud: @\n", "1000000", "x", "3500000",
     "one of the standard rates 9600, 19200, 38400, 57600, 115200, 230400, 460800, 500000, 921600, 1000000, "
     "1500000, 2000000, 3000000, 4000000 [bit/s]"},
    {"driver.return_delay", "rate_hz: 250\ndriver:\n  type: serial\n  return_delay: @\n", "1e-5", "x", "5", "a number in [0, 0.1] [s]"},
    {"driver.device", "rate_hz: 250\ndriver:\n  type: serial\n  device: @\n", "/dev/ttyS1", "[1]", "ttyUSB0",
     "an absolute device path"},
    {"driver.turnaround", "rate_hz: 250\ndriver:\n  type: serial\n  turnaround: @\n", "1e-5", "x", "1", "a number in [0, 0.1] [s]"},
    {"driver.devices", "rate_hz: 250\ndriver:\n  type: serial\n  devices: @\ncontroller: {pd_placement: host, K_D: 0.5}\n",
     "x_series", "[1]", "stock", "one of pedalwave, x_series"},
    {"driver.torque_constant",
     "rate_hz: 250\ndriver:\n  type: serial\n  devices: x_series\n  torque_constant: @\ncontroller: {pd_placement: host, K_D: 0.5}\n",
     "1.5", "x", "1000", "a number in (0, 100] [N·m/A]"},
    {"driver.sensor_id_offset",
     "rate_hz: 250\ndriver:\n  type: serial\n  devices: x_series\n  sensor_id_offset: @\ncontroller: {pd_placement: host, K_D: 0.5}\n",
     "50", "x", "250", "an integer in [5, 247]"},
    {"driver.set_operating_mode",
     "rate_hz: 250\ndriver:\n  type: serial\n  devices: x_series\n  set_operating_mode: @\ncontroller: {pd_placement: host, K_D: 0.5}\n",
     "false", "sometimes", "", ""},
    {"driver.max_stale_cycles",
     "rate_hz: 250\ndriver:\n  type: serial\n  devices: x_series\n  max_stale_cycles: @\ncontroller: {pd_placement: host, K_D: 0.5}\n",
     "8", "x", "0", "an integer in [1, 1000]"},
    {"controller.k_c", kSimDriver + "controller:\n  k_c: @\n", "5", "x", "1e300", "a number in [-1000, 1000]"},
    {"controller.K_p", kSimDriver + "controller:\n  K_p: @\n", "30", "{a: 1}", "-1", "a number in [0, 1e+06]"},
    {"controller.pd_placement", kSimDriver + "controller:\n  pd_placement: @\n", "module", "[1]", "cloud", "one of module, host"},
    {"controller.K_D", kSimDriver + "controller:\n  K_D: @\n", "15", "{a: 1}", "[-1]", "a number in [0, 1e+06] [N·m·s/rad]"},
    {"controller.tau_max", kSimDriver + "controller:\n  tau_max: @\n", "1.5", "{a: 1}", "-1", "a number in (0, 10000] [N·m]"},
    {"controller.tau_rate_max", kSimDriver + "controller:\n  tau_rate_max: @\n", "[100, 100, 100, 100, 100]", "{a: 1}", "0",
     "a number in (0, 1e+09] [N·m/s]"},
    {"controller.M_d", kSimDriver + "controller:\n  M_d: @\n", "2", "x", "0", "a number in (0, 1e+06] [N·m·s²/rad]"},
    {"controller.D_d", kSimDriver + "controller:\n  D_d: @\n", "5", "x", "-5", "a number in (0, 1e+06] [N·m·s/rad]"},
    {"controller.K_d", kSimDriver + "controller:\n  K_d: @\n", "10", "x", "1e7", "a number in (0, 1e+06] [N·m/rad]"},
    {"controller.eta_min", kSimDriver + "controller:\n  eta_max: 0\n  eta_min: @\n", "-2", "x", "1",
     "a number <= controller.eta_max = 0"},
    {"controller.eta_max", kSimDriver + "controller:\n  eta_max: @\n", "2", "x", "7", "a number in [-6.28319, 6.28319] [rad]"},
    // The controller's amplitude is a magnitude: -0.5 loaded, and the controller refused it
    // afterwards without a line.
    {"controller.gait.A_p", kSimDriver + "controller:\n  gait:\n    A_p: @\n", "0.5", "x", "-0.5",
     "a number in [0, 3.14159] [rad]"},
    {"controller.gait.omega", kSimDriver + "controller:\n  gait:\n    omega: @\n", "pi", "x", "200",
     "a number in [-100, 100] [rad/s]"},
    {"controller.gait.eta", kSimDriver + "controller:\n  gait:\n    eta: @\n", "-2*pi/5", "x", "-7",
     "a number in [-6.28319, 6.28319] [rad]"},
    {"realtime.priority", kSimDriver + "realtime:\n  priority: @\n", "10", "x", "100", "an integer in [0, 99]"},
    {"realtime.cpu", kSimDriver + "realtime:\n  cpu: @\n", "0", "x", "-2", "an integer in [-1, 1023]"},
    {"realtime.lock_memory", kSimDriver + "realtime:\n  lock_memory: @\n", "true", "x", "", ""},
    {"realtime.prefault_stack", kSimDriver + "realtime:\n  prefault_stack: @\n", "65536", "[1]", "-1",
     "an integer in [0, 4194304]"},
    {"realtime.require", kSimDriver + "realtime:\n  require: @\n", "false", "x", "", ""},
    {"realtime.clock", kSimDriver + "realtime:\n  clock: @\n", "lockstep", "[1]", "monotonic", "one of realtime, lockstep"},
    {"realtime.overrun_fault_after", kSimDriver + "realtime:\n  overrun_fault_after: @\n", "10", "x", "-1",
     "an integer in [0, 1073741824]"},
    {"realtime.stale_timeout", kSimDriver + "realtime:\n  stale_timeout: @\n", "0.02", "x", "1e9", "a number in (0, 10] [s]"},
    {"realtime.read_budget", kSimDriver + "realtime:\n  read_budget: @\n", "0.6", "x", "2", "a number in (0, 1]"},
    {"realtime.auto_start", kSimDriver + "realtime:\n  auto_start: @\n", "false", "perhaps", "", ""},
    {"calibration.duration", kSimDriver + "calibration:\n  duration: @\n", "0.2", "x", "61", "a number in [0, 60] [s]"},
    {"calibration.timeout", kSimDriver + "calibration:\n  timeout: @\n", "5", "x", "601", "a number in [0, 600] [s]"},
    {"calibration.max_offset", kSimDriver + "calibration:\n  max_offset: @\n", "0.1", "x", "0", "a number in (0, 1] [rad]"},
    {"calibration.max_rate", kSimDriver + "calibration:\n  max_rate: @\n", "0.1", "x", "11", "a number in (0, 10] [rad/s]"},
    {"calibration.max_spread", kSimDriver + "calibration:\n  max_spread: @\n", "0.01", "x", "-1", "a number in (0, 1] [rad]"},
    {"observer.enabled", kSimDriver + "observer:\n  enabled: @\n", "false", "x", "", ""},
    {"telemetry.enabled", kSimDriver + "telemetry:\n  enabled: @\n", "false", "x", "", ""},
    {"telemetry.peers", kSimDriver + "telemetry:\n  peers: @\n", "[127.0.0.1]", "x", "[a b]", "an IPv4 address or host name"},
    {"telemetry.decimation_state", kSimDriver + "telemetry:\n  decimation_state: @\n", "5", "x", "0",
     "an integer in [1, 100000]"},
    {"telemetry.decimation_timing", kSimDriver + "telemetry:\n  decimation_timing: @\n", "5", "x", "0",
     "an integer in [1, 100000]"},
    {"telemetry.commands", kSimDriver + "telemetry:\n  commands: @\n", "false", "x", "", ""},
    {"telemetry.amplitude_max", kSimDriver + "telemetry:\n  amplitude_max: @\n", "1", "x", "4", "a number in (0, 3.14159] [rad]"},
    {"telemetry.eta_min", kSimDriver + "telemetry:\n  eta_min: @\n", "-3", "x", "3.5", "a number <= telemetry.eta_max = 3.2"},
    {"telemetry.eta_max", kSimDriver + "telemetry:\n  eta_max: @\n", "3", "x", "-3.5", "a number >= telemetry.eta_min = -3.2"},
    {"telemetry.domain_id", kSimDriver + "telemetry:\n  domain_id: @\n", "3", "x", "233", "an integer in [0, 232]"},
    {"telemetry.interface", kSimDriver + "telemetry:\n  interface: @\n", "eth0", "[1]", "a b", "a network interface name"},
    {"telemetry.namespace", kSimDriver + "telemetry:\n  namespace: @\n", "/lab/snake_1", "snake1", "/a//b", "a ROS 2 namespace"},
    {"telemetry.stamp_clock", kSimDriver + "telemetry:\n  stamp_clock: @\n", "monotonic", "utc", "7", "one of realtime, monotonic"},
    {"telemetry.localhost_only", kSimDriver + "telemetry:\n  localhost_only: @\n", "true", "x", "", ""},
    {"telemetry.record", kSimDriver + "telemetry:\n  record: @\n", "/tmp/run-{time}.mcap", "[1]", "out.txt",
     "a file name ending in .mcap"},
    {"telemetry.standard_topics", kSimDriver + "telemetry:\n  standard_topics: @\n", "false", "x", "", ""},
    {"telemetry.omega_max", kSimDriver + "telemetry:\n  omega_max: @\n", "6", "x", "1e300", "a number in (0, 100] [rad/s]"},
    {"security.enable", kSimDriver + "security:\n  enable: @\n", "false", "x", "", ""},
    {"security.keystore", kSimDriver + "security:\n  keystore: @\n", "/etc/pedalwave/keystore", "[1]", "",
     ""},
    {"security.enclave", kSimDriver + "security:\n  enclave: @\n", "/pedalwave/snake1", "[1]", "pedalwave//x",
     "an enclave path"},
    {"security.strategy", kSimDriver + "security:\n  strategy: @\n", "permissive", "[1]", "lenient",
     "one of enforce, permissive"},
    // The robot a bus drives (beside a simulated plant it must be the scene's: DaemonContradictions).
    {"robot.N", kCan + "robot:\n  N: @\n", "8", "six", "65", "an integer in [2, 64]"},
    {"robot.m_l", kCan + "robot:\n  m_l: @\n", "0.2", "x", "0", "a number in (0, 1000] [kg]"},
    {"robot.link_length", kCan + "robot:\n  link_length: @\n", "0.08", "x", "11", "a number in (0, 10] [m]"},
    {"robot.I_l", kCan + "robot:\n  I_l: @\n", "1e-4", "x", "0", "a number in (0, 1000] [kg·m²]"},
    {"robot.m_r", kCan + "robot:\n  m_r: @\n", "0.03", "x", "-1", "a number in [0, 1000] [kg]"},
    {"robot.I_r", kCan + "robot:\n  I_r: @\n", "1e-7", "x", "2", "a number in [0, 1] [kg·m²]"},
    {"robot.n", kCan + "robot:\n  n: @\n", "100", "x", "-100", "a number in (0, 100000] [-]"},
    {"robot.K", kCan + "robot:\n  K: @\n", "[3, 3, 3, 3, 3]", "{a: 1}", "[0]", "a number in (0, 1e+06] [N·m/rad]"},
    {"robot.g", kCan + "robot:\n  g: @\n", "9.81", "x", "1000", "a number in [0, 100] [m/s²]"},
    {"robot.joints", kCan + "robot:\n  joints: @\n", "rigid", "[1]", "elastic", "one of flexible, rigid"},
    {"robot.rigid_variant", kCan + "robot:\n  joints: rigid\n  rigid_variant: @\n", "paper", "[1]", "printed",
     "one of exact_limit, paper"},
};
}  // namespace

TEST(BadInputs, EveryDaemonKeyRefusesWrongTypeWrongRangeAndDuplicate) {
  for (const KeyRow& k : kDaemonKeys) check_row(k, daemon_error);
}

TEST(BadInputs, DaemonContradictionsAreRefused) {
  // The robot beside a simulated plant is the scene's robot (N = 6 there).
  std::string e = daemon_error("robot: {N: 12}\n" + kSimDriver);
  EXPECT_EQ(e.rfind("bad.yaml:1:12: robot.N = \"12\": expected the simulated robot's value 6 (driver.scene: ", 0), 0u) << e;
  e = daemon_error("robot: {N: 6, K: 5}\n" + kSimDriver);
  EXPECT_NE(e.find("robot.K = \"5\": expected the simulated robot's value K[0] = 3"), std::string::npos) << e;
  EXPECT_EQ(daemon_error("robot: {N: 6, K: 3}\n" + kSimDriver), "(no error)") << "the same robot is fine";
  // Less than one period rounds to 0 cycles, which would mean "run forever".
  e = daemon_error("duration: 0.0004\n" + kSimDriver);
  EXPECT_EQ(e, "bad.yaml:1:11: duration = \"0.0004\": expected 0 (until a signal) or at least one control period "
               "1/rate_hz = 0.001 s");
  e = daemon_error("duration: 0.0007\n" + kSimDriver);
  EXPECT_EQ(e, "bad.yaml:1:11: duration = \"0.0007\": expected 0 (until a signal) or at least one control period "
               "1/rate_hz = 0.001 s");
  e = daemon_error("calibration: {duration: 0.0004}\n" + kSimDriver);
  EXPECT_EQ(e, "bad.yaml:1:25: calibration.duration = \"0.0004\": expected 0 (no calibration) or at least one "
               "control period 1/rate_hz = 0.001 s");
  // A scene whose gait drives the controller has an amplitude ≥ 0 (the model takes any sign):
  // refused at the scene's own line, unless the daemon gives its own controller.gait.
  const auto dir = std::filesystem::temp_directory_path() / ("pw_neg_gait_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string neg = (dir / "neg.yaml").string();
  std::ofstream(neg) << "ground: {k: 350}\ngait: {A_p: -0.5}\n";
  e = daemon_error("driver:\n  type: sim\n  scene: " + neg + "\n");
  EXPECT_EQ(e.rfind(neg + ":2:13: gait.A_p = \"-0.5\": expected a number in [0, 3.14159] [rad]: this scene's gait "
                    "drives the runtime's controller", 0), 0u) << e;
  EXPECT_EQ(daemon_error("driver:\n  type: sim\n  scene: " + neg + "\ncontroller:\n  gait: {A_p: 0.5}\n"),
            "(no error)") << "the daemon's own gait replaces the scene's";
  std::filesystem::remove_all(dir);
  // A data-phase bit rate belongs to CAN FD: beside fd: false it is refused, not ignored.
  e = daemon_error("driver:\n  type: socketcan\n  data_bitrate: 2e6\n");
  EXPECT_EQ(e.rfind("bad.yaml:3:17: driver.data_bitrate = \"2e6\": expected no data_bitrate without fd: true", 0), 0u) << e;
  // The scene's own errors keep the scene's file and line.
  e = daemon_error("driver:\n  type: sim\n  scene: /dev/null\n");
  EXPECT_NE(e.find("driver.scene: /dev/null: is not a regular file"), std::string::npos) << e;
}

// A driver key belongs to its types (README "driver", the type column); beside another type it is
// refused at its line, naming the key and the type, not ignored unchecked ({type: sim, ifname: a/b,
// baud: 1, device: rel} loaded). Every driver row's key is here, and the README's column says the
// same.
namespace {
// Markdown helpers of the README guards (no std::regex: GCC 12 warns inside it under -O2 with the
// sanitizers, -Wmaybe-uninitialized, and -Werror makes that an error).
// The `quoted` names in s made of `allowed` characters, in order.
std::vector<std::string> backticked(const std::string& s, const std::string& allowed) {
  std::vector<std::string> v;
  for (std::size_t a = s.find('`'); a != std::string::npos; a = s.find('`', a + 1)) {
    const std::size_t b = s.find('`', a + 1);
    if (b == std::string::npos) break;
    const std::string n = s.substr(a + 1, b - a - 1);
    if (!n.empty() && n.find_first_not_of(allowed) == std::string::npos) v.push_back(n);
    a = b;
  }
  return v;
}
const std::string kLower = "abcdefghijklmnopqrstuvwxyz_";
const std::string kKeyChars = kLower + "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789.";
// `word` in s, not as a part of a longer name.
bool names_word(const std::string& s, const std::string& word) {
  const auto name_char = [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; };
  for (std::size_t i = s.find(word); i != std::string::npos; i = s.find(word, i + 1))
    if ((i == 0 || !name_char(s[i - 1])) && (i + word.size() == s.size() || !name_char(s[i + word.size()])))
      return true;
  return false;
}
}  // namespace

namespace {
const std::map<std::string, std::set<std::string>> kDriverKeyTypes = {
    {"scene", {"sim"}},          {"clock", {"sim"}},         {"command_timeout", {"sim", "serial"}},
    {"ifname", {"socketcan"}},   {"fd", {"socketcan"}},      {"bitrate", {"socketcan"}},
    {"data_bitrate", {"socketcan"}}, {"max_load", {"socketcan", "serial"}},
    {"device", {"serial"}},      {"baud", {"serial"}},       {"return_delay", {"serial"}},
    {"turnaround", {"serial"}},  {"devices", {"serial"}},    {"torque_constant", {"serial"}},
    {"sensor_id_offset", {"serial"}}, {"set_operating_mode", {"serial"}},
    {"protocol", {"socketcan"}},  {"nodes", {"socketcan"}},    {"drive_mode", {"socketcan"}},
    {"heartbeat", {"socketcan"}}, {"heartbeat_timeout", {"socketcan"}}, {"sync_window", {"socketcan"}},
    {"max_stale_cycles", {"serial"}},
};
}  // namespace

TEST(BadInputs, DriverKeysOfAnotherTypeAreRefused) {
  const std::map<std::string, std::string> base = {
      {"sim", "driver:\n  type: sim\n  scene: ../scenes/flat_high_friction.yaml\n"},
      {"socketcan", "rate_hz: 100\ndriver:\n  type: socketcan\n"},
      {"serial", "rate_hz: 250\ndriver:\n  type: serial\n"},
  };
  std::set<std::string> rows;
  for (const KeyRow& k : kDaemonKeys) {
    if (k.path.rfind("driver.", 0) != 0 || k.path == "driver.type") continue;
    const std::string key = k.path.substr(7);
    rows.insert(key);
    ASSERT_TRUE(kDriverKeyTypes.count(key)) << key << ": which driver types is it for?";
    const std::set<std::string>& types = kDriverKeyTypes.at(key);
    std::string owner;
    for (const char* t : {"sim", "socketcan", "serial"})  // the order of `type`'s choices
      if (types.count(t)) owner += (owner.empty() ? "" : " and ") + std::string(t);
    owner += types.size() > 1 ? " drivers'" : " driver's";
    for (const auto& [type, yaml] : base) {
      if (types.count(type) || key == "scene") continue;  // a sim base gives its scene already
      SCOPED_TRACE(key + " with type: " + type);
      const std::string e = daemon_error(yaml + "  " + key + ": " + k.good + "\n");
      EXPECT_EQ(e, "bad.yaml:4:" + std::to_string(5 + key.size()) + ": " + k.path + " = " + shown(k.good) +
                       ": expected no " + key + " with type: " + type + " (" + key + " is the " + owner + ")");
    }
    if (types.count("sim") || (!types.count("socketcan") && !types.count("serial"))) continue;
    // The default type is sim: said so.
    const std::string e = daemon_error("driver:\n  scene: ../scenes/flat_high_friction.yaml\n  " + key + ": " +
                                       k.good + "\n");
    EXPECT_NE(e.find("expected no " + key + " with type: sim (" + key + " is the " + owner +
                     "; type: sim is the default)"), std::string::npos) << e;
  }
  std::set<std::string> table;
  for (const auto& [key, types] : kDriverKeyTypes) table.insert(key);
  EXPECT_EQ(table, rows) << "the driver keys here and the driver rows";
  // The audit's file, and a key of the right type with a value of the wrong type still says so.
  std::string e = daemon_error("driver: {type: sim, scene: ../scenes/flat_high_friction.yaml, ifname: 'a/b', "
                               "baud: 1, device: rel}\n");
  EXPECT_NE(e.find("driver.ifname = \"a/b\": expected no ifname with type: sim (ifname is the socketcan "
                   "driver's)"), std::string::npos) << e;
  e = daemon_error("rate_hz: 250\ndriver: {type: serial, fd: maybe}\n");
  EXPECT_EQ(e, "bad.yaml:2:28: driver.fd = \"maybe\": expected no fd with type: serial (fd is the socketcan "
               "driver's)");
  // The README's driver table says the same in its type column.
  std::ifstream in(PEDALWAVE_CONFIG_DIR "/runtime/README.md");
  ASSERT_TRUE(in);
  bool in_driver = false;
  std::map<std::string, std::set<std::string>> readme;
  for (std::string line; std::getline(in, line);) {
    if (line.rfind('#', 0) == 0) in_driver = line == "## `driver`";
    // "| `key` | type, type | …": the first cell one name, the second the types.
    if (!in_driver || line.rfind("| `", 0) != 0) continue;
    const std::size_t c1 = line.find(" | ", 2), c2 = c1 == std::string::npos ? c1 : line.find(" |", c1 + 3);
    if (c2 == std::string::npos) continue;
    const std::vector<std::string> key = backticked(line.substr(0, c1), kLower);
    const std::string types = line.substr(c1 + 3, c2 - c1 - 3);
    if (key.size() != 1 || key[0] == "type" || types.find_first_not_of("abcdefghijklmnopqrstuvwxyz, ") != std::string::npos)
      continue;
    std::stringstream list(types);
    for (std::string t; std::getline(list, t, ',');) readme[key[0]].insert(t.substr(t.find_first_not_of(' ')));
  }
  EXPECT_EQ(readme, kDriverKeyTypes) << "config/runtime/README.md's driver table, its type column";
}

// The file is machine-independent: a robot's `cpu: 1` loads on a 1-CPU packaging machine
// (--check-config), and whether this machine has the CPU is --check's and the start's question.
TEST(BadInputs, RealtimeCpuIsCheckedWithoutThisMachine) {
  const long n = sysconf(_SC_NPROCESSORS_ONLN);
  EXPECT_EQ(daemon_error(kSimDriver + "realtime:\n  cpu: " + std::to_string(n) + "\n"), "(no error)")
      << "CPU " << n << " does not exist here (" << n << " online CPUs)";
  EXPECT_EQ(daemon_error(kSimDriver + "realtime:\n  cpu: 1023\n"), "(no error)");
  EXPECT_EQ(daemon_error(kSimDriver + "realtime:\n  cpu: 1024\n"),
            "bad.yaml:5:8: realtime.cpu = \"1024\": expected an integer in [-1, 1023]");
}

// As config/runtime/README.md's `telemetry` table says: no section is off, an empty one is on.
TEST(BadInputs, TelemetryIsOffWithoutTheSectionAndOnWithAnEmptyOne) {
  auto enabled = [](const std::string& yaml) {
    return config::parse_daemon_config(yaml, "t.yaml", PEDALWAVE_CONFIG_DIR "/runtime").telemetry.enabled;
  };
  EXPECT_FALSE(enabled(kSimDriver));
  EXPECT_TRUE(enabled(kSimDriver + "telemetry: {}\n"));
  EXPECT_TRUE(enabled(kSimDriver + "telemetry: {domain_id: 3}\n"));
  EXPECT_FALSE(enabled(kSimDriver + "telemetry: {enabled: false}\n"));
}

TEST(BadInputs, DurationProblem) {
  EXPECT_EQ(config::duration_problem(0, 1000), "");
  EXPECT_EQ(config::duration_problem(5, 1000), "");
  EXPECT_EQ(config::duration_problem(0.001, 1000), "");
  EXPECT_NE(config::duration_problem(0.0004, 1000), "");
  // At least one period, as the message says (half a period was accepted: it rounds to 1 cycle),
  // within float rounding of it.
  EXPECT_NE(config::duration_problem(0.0007, 1000), "");
  EXPECT_NE(config::duration_problem(0.0005, 1000), "");
  EXPECT_NE(config::duration_problem(0.999e-3, 1000), "");
  EXPECT_EQ(config::duration_problem(1.0 / 3.0, 3), "");
  EXPECT_EQ(config::duration_problem(0.0019, 1 / 0.0019), "") << "0.0019 · (1 / 0.0019) is 0.9999999999999999";
  EXPECT_NE(config::duration_problem(-1, 1000), "");
  EXPECT_NE(config::duration_problem(std::nan(""), 1000), "");
  EXPECT_NE(config::duration_problem(HUGE_VAL, 1000), "");
  EXPECT_NE(config::duration_problem(1e308, 1000), "");
}

// A key written with no value (`ground:` alone, `duration:`, `K: ~`) is an error at the key's line,
// not the default: an empty `ground:` would otherwise run the robot in vacuum. An empty flow list
// or map is a value.
TEST(BadInputs, AKeyWithNoValueIsAnErrorNotTheDefault) {
  const std::string none = " (the key has no value; remove it for the default)";
  const std::string required = " (the key has no value; it is required)";
  const std::vector<std::pair<std::string, std::string>> scene = {
      {"ground:\nduration: 5\n", "bad.yaml:1:1: ground = \"\": expected a map of ground keys" + none},
      {"duration: 5\ngait: ~\n", "bad.yaml:2:1: gait = \"\": expected a map of gait keys" + none},
      {"name: x\nduration:\n", "bad.yaml:2:1: duration = \"\": expected a number in (0, 1e+06] [s]" + none},
      {"ground:\n  k:\n  mu: 0.5\n", "bad.yaml:2:3: ground.k = \"\": expected a number in (0, 1e+07] [N/m]" + none},
      {"robot:\n  K: null\n", "bad.yaml:2:3: robot.K = \"\": expected a number or a list of numbers" + none},
      {"robot: {N: 6, joints: }\n", "bad.yaml:1:15: robot.joints = \"\": expected one of flexible, rigid" + none},
      {"integrator:\n  method: rk4\n  rtol:\n", "bad.yaml:3:3: integrator.rtol = \"\": expected a number in (0, 1] [-]" + none},
      {"ground: {}\nobstacles:\n  - x_near:\n    width: 0.1\n",
       "bad.yaml:3:5: obstacles[0].x_near = \"\": expected a number in [-10000, 10000] [m]" + none},
      {"faults:\n  - type: nan\n    joint:\n", "bad.yaml:3:5: faults[0].joint = \"\": expected an integer in [0, 4]" + none},
      {"faults:\n  - type:\n    joint: 1\n", "bad.yaml:2:5: faults[0].type = \"\": expected a fault type" + required},
      {"ground:\n  patches:\n    - x_begin:\n", "bad.yaml:3:7: ground.patches[0].x_begin = \"\": expected a number" + required},
      {"ground: {}\nobstacles:\n  - {x_near: 0.2}\n  -   # nothing\n\nduration: 1\n",
       "bad.yaml:4:3: obstacles[1] = \"\": expected a value (the list element is empty: give it one or remove the '-')"},
      {"robot:\n  K: [1, ~, 1, 1, 1]\n", "bad.yaml:2:10: robot.K[1] = \"\": expected a value (the list element is empty"},
  };
  for (const auto& [yaml, expected] : scene) {
    SCOPED_TRACE(yaml);
    const std::string e = scene_error(yaml);
    EXPECT_EQ(e.rfind(expected, 0), 0u) << e;
    EXPECT_TRUE(one_line(e)) << e;
  }
  const std::vector<std::pair<std::string, std::string>> daemon = {
      {"rate_hz: 500\ndriver:\n", "bad.yaml:2:1: driver = \"\": expected a driver section (type: sim | socketcan | serial)" + required},
      {"driver:\n  type: sim\n  scene:\n", "bad.yaml:3:3: driver.scene = \"\": expected the scene file the simulated plant runs" },
      {kSimDriver + "telemetry:\n", "bad.yaml:4:1: telemetry = \"\": expected a map of telemetry keys" + none},
      {"rate_hz:\n" + kSimDriver, "bad.yaml:1:1: rate_hz = \"\": expected a number" },
      {kSimDriver + "controller:\n  K_p:\n", "bad.yaml:5:3: controller.K_p = \"\": expected a number or a list of numbers" + none},
      {kSimDriver + "realtime: {priority: 10, clock: }\n",
       "bad.yaml:4:26: realtime.clock = \"\": expected one of realtime, lockstep" + none},
      {kSimDriver + "controller:\n  gait:\n    omega:\n", "bad.yaml:6:5: controller.gait.omega = \"\": expected a number in [-100, 100] [rad/s]" + none},
      {kSimDriver + "telemetry:\n  peers:\n    - 127.0.0.1\n    -\n",
       "bad.yaml:7:5: telemetry.peers[1] = \"\": expected a value (the list element is empty"},
  };
  for (const auto& [yaml, expected] : daemon) {
    SCOPED_TRACE(yaml);
    const std::string e = daemon_error(yaml);
    EXPECT_EQ(e.rfind(expected, 0), 0u) << e;
    EXPECT_TRUE(one_line(e)) << e;
  }
  // Empty flow lists and maps are values: no faults, no obstacles, the defaults of a section.
  EXPECT_EQ(scene_error("ground: {}\nobstacles: []\nfaults: []\nrobot: {}\n"), "(no error)");
  EXPECT_EQ(daemon_error(kSimDriver + "telemetry: {peers: []}\nobserver: {}\n"), "(no error)");
  EXPECT_EQ(config::parse_scene("ground: {}\n", "ok.yaml").ground_on, true);
}

// ---- every key has a row ----

namespace {

// The leaf keys a reader accepts, read off its unknown-key messages ("unknown key 'robot.zz_unknown':
// expected one of N, m_l, …") in every map of the file; `maps` gives each map's path and a file with
// `@` where a key goes. A key that is itself one of the maps, or a list of them (`obstacles` for
// `obstacles[0]`), is no leaf: a new section shows up as a leaf without a row until it is probed.
template <class E>
std::set<std::string> accepted_leaf_keys(const std::vector<std::pair<std::string, std::string>>& maps, E&& error) {
  std::set<std::string> keys;
  for (const auto& [path, yaml] : maps) {
    const std::string prefix = path.empty() ? "" : path + ".";
    const std::string e = error(with(yaml, "zz_unknown"));
    const std::string marker = "unknown key '" + prefix + "zz_unknown': expected one of ";
    const std::size_t at = e.find(marker);
    EXPECT_NE(at, std::string::npos) << path << ": " << e;
    if (at == std::string::npos) continue;
    std::stringstream list(e.substr(at + marker.size()));
    for (std::string k; std::getline(list, k, ',');) keys.insert(prefix + k.substr(k.find_first_not_of(' ')));
  }
  std::erase_if(keys, [&](const std::string& k) {
    return std::any_of(maps.begin(), maps.end(),
                       [&](const auto& m) { return m.first == k || m.first.rfind(k + "[", 0) == 0; });
  });
  return keys;
}

// The keys of `a` that `b` lacks, for a message.
std::string missing(const std::set<std::string>& a, const std::set<std::string>& b) {
  std::string out;
  for (const std::string& k : a)
    if (!b.count(k)) out += (out.empty() ? "" : ", ") + k;
  return out;
}

void expect_a_row_per_key(const std::set<std::string>& accepted, const std::vector<KeyRow>& rows) {
  std::set<std::string> paths;
  for (const KeyRow& k : rows) paths.insert(k.path);
  EXPECT_EQ(missing(accepted, paths), "") << "keys the reader accepts without a row";
  EXPECT_EQ(missing(paths, accepted), "") << "rows for keys the reader does not accept";
}

}  // namespace

TEST(BadInputs, EveryKeyTheReadersAcceptHasARow) {
  std::vector<std::pair<std::string, std::string>> scene = {
      {"", "@: 1\n"},
      {"ground.patches[0]", "ground:\n  patches:\n    - {x_begin: 0, @: 1}\n"},
      {"obstacles[0]", "ground: {}\nobstacles:\n  - {x_near: 0.2, @: 1}\n"},
      {"faults[0]", "faults:\n  - {type: nan, @: 1}\n"},
  };
  for (const char* m : {"robot", "ground", "joint_friction", "torque_limit", "sensor_noise", "initial", "gait",
                        "integrator"})
    scene.push_back({m, std::string(m) + ":\n  @: 1\n"});
  expect_a_row_per_key(accepted_leaf_keys(scene, scene_error), kSceneKeys);

  std::vector<std::pair<std::string, std::string>> daemon = {
      {"", "@: 1\n" + kSimDriver},
      {"driver", "driver:\n  type: sim\n  @: 1\n"},
      {"controller.gait", kSimDriver + "controller:\n  gait:\n    @: 1\n"},
  };
  for (const char* m : {"robot", "controller", "realtime", "calibration", "observer", "telemetry", "security"})
    daemon.push_back({m, kSimDriver + m + ":\n  @: 1\n"});
  expect_a_row_per_key(accepted_leaf_keys(daemon, daemon_error), kDaemonKeys);
}

// The scene's keys are documented (config/scenes/README.md's table): every row's key is named in
// the table row of its section, and the table lists exactly the sections that have rows.
TEST(BadInputs, EverySceneKeyWithARowIsInTheReadmeTable) {
  std::ifstream in(PEDALWAVE_CONFIG_DIR "/scenes/README.md");
  ASSERT_TRUE(in) << "config/scenes/README.md";
  std::map<std::string, std::string> table;  // section → its table row
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("| `", 0) != 0) continue;
    for (const std::string& n : backticked(line.substr(0, line.find('|', 1)), kLower)) table[n] = line;
  }
  std::set<std::string> sections;
  for (const KeyRow& k : kSceneKeys) {
    SCOPED_TRACE(k.path);
    const std::string section = k.path.substr(0, k.path.find_first_of(".["));
    const std::string key = k.path.substr(k.path.find_last_of('.') == std::string::npos ? 0 : k.path.find_last_of('.') + 1);
    sections.insert(section);
    ASSERT_TRUE(table.count(section)) << "no table row for " << section;
    EXPECT_TRUE(names_word(table[section], key))
        << key << " is not named in the row of " << section;
  }
  std::set<std::string> documented;
  for (const auto& [s, row] : table) documented.insert(s);
  EXPECT_EQ(missing(documented, sections), "") << "sections in the table without rows";
}

// The daemon configuration's keys are documented (config/runtime/README.md: a table per section,
// under a heading naming it, "## Top level", "## `driver`", …): every row's key, its path below the
// section (`ifname`, `gait.A_p`), is named in the first cell of a row of its section's table, and
// every key those cells name has a row (the top level's table also names the sections).
TEST(BadInputs, EveryDaemonKeyWithARowIsInTheReadmeTable) {
  std::ifstream in(PEDALWAVE_CONFIG_DIR "/runtime/README.md");
  ASSERT_TRUE(in) << "config/runtime/README.md";
  std::map<std::string, std::set<std::string>> table;  // section ("" = top level) → the keys its table names
  std::optional<std::string> section;  // none: a heading that names no section
  for (std::string line; std::getline(in, line);) {
    if (line.rfind('#', 0) == 0) {
      // "## Top level" or "## `name`" (trailing blanks allowed); any other heading names none.
      section.reset();
      std::string h = line.substr(line.find_first_not_of('#'));
      h.erase(0, h.find_first_not_of(' '));
      h.erase(h.find_last_not_of(" \t") + 1);
      if (h == "Top level") section = std::string();
      else if (h.size() > 2 && h.front() == '`' && h.back() == '`' && backticked(h, kLower).size() == 1)
        section = backticked(h, kLower)[0];
      continue;
    }
    if (!section || line.rfind("| `", 0) != 0) continue;
    for (const std::string& n : backticked(line.substr(0, line.find('|', 1)), kKeyChars))
      if (std::isalpha(static_cast<unsigned char>(n[0])) || n[0] == '_') table[*section].insert(n);
  }
  std::set<std::string> paths;
  for (const KeyRow& k : kDaemonKeys) {
    SCOPED_TRACE(k.path);
    paths.insert(k.path);
    const std::size_t dot = k.path.find('.');
    const std::string sec = dot == std::string::npos ? "" : k.path.substr(0, dot);
    const std::string key = dot == std::string::npos ? k.path : k.path.substr(dot + 1);
    ASSERT_TRUE(table.count(sec)) << "no table for " << (sec.empty() ? "the top level" : sec);
    EXPECT_TRUE(table[sec].count(key)) << key << " is not named in the table of "
                                       << (sec.empty() ? "the top level" : sec);
  }
  std::set<std::string> documented;
  for (const auto& [sec, keys] : table)
    for (const std::string& k : keys)
      if (!(sec.empty() && table.count(k))) documented.insert(sec.empty() ? k : sec + "." + k);
  EXPECT_EQ(missing(documented, paths), "") << "keys in the README's tables without a row";
}

// Stock X-series servos (driver.devices: x_series) run no module PD: the PD goes to the host,
// where its stability check applies; their keys are refused on a bus of pedalwave modules.
// CANopen (driver.protocol: canopen): its keys need it, CST needs the host PD, classic frames only,
// the bus budget counts the CANopen frame set, node ids are distinct.
TEST(BadInputs, CanOpenKeysAndContradictions) {
  std::string e = daemon_error("rate_hz: 100\ndriver: {type: socketcan, drive_mode: csp}\n");
  EXPECT_NE(e.find("driver.drive_mode = \"csp\": expected no drive_mode without protocol: canopen"), std::string::npos) << e;
  e = daemon_error("rate_hz: 100\ndriver: {type: socketcan, protocol: canopen}\n");
  EXPECT_NE(e.find("driver.protocol = \"canopen\": expected pd_placement: host with driver.drive_mode: cst"),
            std::string::npos) << e;
  e = daemon_error("rate_hz: 100\ndriver: {type: socketcan, protocol: canopen, drive_mode: cst}\ncontroller: {pd_placement: module}\n");
  EXPECT_NE(e.find("controller.pd_placement = \"module\": expected pd_placement: host"), std::string::npos) << e;
  EXPECT_EQ(daemon_error("rate_hz: 100\ndriver: {type: socketcan, protocol: canopen}\ncontroller: {pd_placement: host, K_D: 0.5}\n"),
            "(no error)");
  e = daemon_error("rate_hz: 100\ndriver: {type: socketcan, protocol: canopen, drive_mode: csp, fd: true}\n");
  EXPECT_NE(e.find("driver.fd = \"true\": expected fd: false with protocol: canopen"), std::string::npos) << e;
  e = daemon_error("rate_hz: 100\nrobot: {N: 3}\ndriver: {type: socketcan, protocol: canopen, drive_mode: csp, nodes: [4, 4]}\n");
  EXPECT_NE(e.find("driver.nodes[1] = \"4\": expected a node id not given to another joint"), std::string::npos) << e;
  e = daemon_error("rate_hz: 100\nrobot: {N: 3}\ndriver: {type: socketcan, protocol: canopen, drive_mode: csp, nodes: [4]}\n");
  EXPECT_NE(e.find("driver.nodes = [list]: expected a list of 2 distinct CANopen node ids"), std::string::npos) << e;
  e = daemon_error("rate_hz: 100\ndriver: {type: socketcan, protocol: canopen, drive_mode: csp, heartbeat: 0.2, "
                   "heartbeat_timeout: 0.1}\n");
  EXPECT_NE(e.find("driver.heartbeat_timeout = \"0.1\": expected a number > driver.heartbeat = 0.2"), std::string::npos) << e;
  // 5 CSP nodes at 1 kHz do not fit 1 Mbit/s (the own protocol on CAN FD does).
  e = daemon_error("rate_hz: 1000\ndriver: {type: socketcan, protocol: canopen, drive_mode: csp}\n");
  EXPECT_NE(e.find("driver: CAN bus budget exceeded: CANopen (CSP) with 5 nodes at 1000 Hz"), std::string::npos) << e;
  EXPECT_EQ(daemon_error("rate_hz: 1000\ndriver: {type: socketcan, fd: true}\n"), "(no error)");
}

TEST(BadInputs, XSeriesServosNeedTheHostPdAndTheirKeysNeedThem) {
  std::string e = daemon_error("rate_hz: 250\ndriver: {type: serial, devices: x_series}\n");
  EXPECT_NE(e.find("driver.devices = \"x_series\": expected pd_placement: host with driver.devices: "
                   "x_series"), std::string::npos) << e;
  e = daemon_error("rate_hz: 250\ndriver: {type: serial, devices: x_series}\ncontroller: {pd_placement: module}\n");
  EXPECT_NE(e.find("controller.pd_placement = \"module\": expected pd_placement: host"), std::string::npos) << e;
  // The paper's K_D = 15 is unstable as a sampled PD at 250 Hz: the controller's check says so.
  e = daemon_error("rate_hz: 250\ndriver: {type: serial, devices: x_series}\ncontroller: {pd_placement: host}\n");
  EXPECT_NE(e.find("pd.placement = host is discretely unstable"), std::string::npos) << e;
  EXPECT_EQ(daemon_error("rate_hz: 250\ndriver: {type: serial, devices: x_series}\n"
                         "controller: {pd_placement: host, K_D: 0.5}\n"),
            "(no error)");
  e = daemon_error("rate_hz: 250\ndriver: {type: serial, torque_constant: 1.5}\n");
  EXPECT_NE(e.find("driver.torque_constant = \"1.5\": expected no torque_constant without devices: "
                   "x_series"), std::string::npos) << e;
  // Their command_timeout is the servos' Bus Watchdog: 1 … 127 × 20 ms.
  e = daemon_error("rate_hz: 250\ndriver: {type: serial, devices: x_series, command_timeout: 5}\n"
                   "controller: {pd_placement: host, K_D: 0.5}\n");
  EXPECT_NE(e.find("driver.command_timeout = \"5\": expected a number in [0.02, 2.54] [s]"),
            std::string::npos) << e;
}
