// pedalwave_workprec's runs as campaign lines: encode → run_line → decode gives run_once's results
// bit for bit (trajectory, counters, status), for a closed-loop walk, an open-loop fall and a
// fidelity variant; a bad line is a clear error.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <sstream>

#include "pedalwave/config/scene.hpp"
#include "pedalwave/config/shipped.hpp"
#include "study.hpp"

using namespace pedalwave;
using namespace pedalwave::workprec;

namespace {

std::string read(const std::string& path) {
  std::ifstream f(path);
  std::ostringstream os;
  os << f.rdbuf();
  return os.str();
}

bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0);
}

void check(const std::string& scene_file, int variant, bool closed, const model::IntegratorOptions& integ) {
  const std::string path = config::shipped_dir() + "/scenes/" + scene_file;
  const std::string text = read(path);
  RunSpec s;
  s.scene = config::parse_scene(text, path);
  fidelity_variants()[static_cast<std::size_t>(variant)].apply(s.scene);
  s.closed_loop = closed;
  s.rate_hz = closed ? 1000.0 : 500.0;
  s.duration = 0.3;
  s.integ = integ;
  const RunResult direct = run_once(s, true);
  const RunResult viaLine = decode_result(run_line(encode_spec(s, path, text, variant, true, 1)));
  EXPECT_EQ(viaLine.status, direct.status);
  EXPECT_EQ(viaLine.evaluations, direct.evaluations);
  EXPECT_EQ(viaLine.steps, direct.steps);
  EXPECT_EQ(viaLine.rejected, direct.rejected);
  EXPECT_EQ(viaLine.traj.joints, direct.traj.joints);
  EXPECT_GT(direct.traj.t.size(), 100u);
  EXPECT_TRUE(same_bits(viaLine.traj.t, direct.traj.t));
  EXPECT_TRUE(same_bits(viaLine.traj.com_x, direct.traj.com_x));
  EXPECT_TRUE(same_bits(viaLine.traj.com_z, direct.traj.com_z));
  EXPECT_TRUE(same_bits(viaLine.traj.alpha, direct.traj.alpha));
}

}  // namespace

TEST(WorkprecCampaign, ClosedLoopWalkThroughItsLineIsTheDirectRun) {
  check("flat_high_friction.yaml", 0, true, {.method = model::Method::kImplicitVelocity, .h = 5e-4});
}

// implicit_contact's jacobian_age travels in the line (a non-default age; --jacobian-age).
TEST(WorkprecCampaign, ImplicitContactsJacobianAgeThroughItsLine) {
  model::IntegratorOptions o{.method = model::Method::kImplicitContact, .h = 1e-3};
  o.jacobian_age = 0;
  check("stair.yaml", 0, true, o);
  o.jacobian_age = 2;
  check("stair.yaml", 0, true, o);
}

TEST(WorkprecCampaign, OpenLoopFallAndAdaptiveStepThroughTheirLines) {
  check("free_fall.yaml", 0, false,
        {.method = model::Method::kDormandPrince45, .h = 1e-5, .rtol = 1e-6, .atol = 1e-8, .h_min = 1e-15, .h_max = 1e-3});
}

TEST(WorkprecCampaign, FidelityVariantIsAppliedByTheWorker) {
  check("flat_high_friction.yaml", 1, true, {.method = model::Method::kSemiImplicitEuler, .h = 2.5e-4});  // rigid
  const std::string path = config::shipped_dir() + "/scenes/flat_high_friction.yaml";
  RunSpec s;
  s.scene = config::parse_scene(read(path), path);
  s.duration = 0.1;
  s.integ = {.method = model::Method::kSemiImplicitEuler, .h = 2.5e-4};
  // Variant 1 (rigid joints) changes the run: the line carries the variant, not the scene struct.
  const RunResult flex = decode_result(run_line(encode_spec(s, path, read(path), 0, true, 1)));
  const RunResult rigid = decode_result(run_line(encode_spec(s, path, read(path), 1, true, 1)));
  EXPECT_FALSE(same_bits(flex.traj.alpha, rigid.traj.alpha));
}

TEST(WorkprecCampaign, BadLinesAreClearErrors) {
  try {
    (void)run_line("kind=paper.run");
    FAIL() << "expected an error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("expected workprec.run"), std::string::npos) << e.what();
  }
  const std::string path = config::shipped_dir() + "/scenes/free_fall.yaml";
  RunSpec s;
  s.scene = config::parse_scene(read(path), path);
  std::string line = encode_spec(s, path, read(path), 0, false, 1);
  line.replace(line.find("variant=0"), 9, "variant=99");
  try {
    (void)run_line(line);
    FAIL() << "expected an error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("variant = 99"), std::string::npos) << e.what();
  }
}
