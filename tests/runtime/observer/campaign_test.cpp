// Every fault of issue 7, injected at a random time (2…8 s) and joint in a closed-loop run (gait
// controller, module-side PD, sensor noise on) on the flat and the stair scenes: detected,
// isolated to the right joint and class, within the latency the README states for its check.
#include <gtest/gtest.h>

#include <random>

#include "harness.hpp"

namespace pw = pedalwave;
using pw::model::FaultType;

namespace {

// Latency bound per check [s] (README table: worst case over the campaign, rounded up).
double latency_bound(FaultType f) {
  switch (f) {
    case FaultType::kTorqueGain:
    case FaultType::kMotorFriction:
    case FaultType::kSpringScale:
    case FaultType::kDeflectionBias:
    case FaultType::kDeflectionScale: return 4.0;  // residual crossing + 0.3 s + 2 s window
    case FaultType::kEncoderStuck: return 0.2;     // hold_cycles + motion gate
    case FaultType::kDeflectionStuck: return 0.3;  // hold_cycles_deflection
    case FaultType::kEncoderOffset:
    case FaultType::kEncoderNoise: return 0.03;    // jump_window
    case FaultType::kJointLoad: return 0.5;        // saturation low-pass
    default: return 0.02;                          // data checks: a few cycles
  }
}

class Campaign : public ::testing::TestWithParam<FaultType> {};

TEST_P(Campaign, DetectedAndIsolatedOnFlatAndStair) {
  const FaultType type = GetParam();
  // Seeded from the fault type: random joint/time/magnitude, reproducible.
  std::mt19937_64 rng(0xfa017 + static_cast<std::uint64_t>(type));
  for (const char* scene_name : {"flat_high_friction", "stair"}) {
    const pw::model::FaultSpec f = pw::faultbench::random_fault(type, 5, 2.0, 8.0, rng);
    pw::faultbench::LoopOptions o;
    o.seed = rng();
    const auto res = pw::faultbench::run_fault(pw::faultbench::shipped_scene(scene_name), o, f,
                                               f.t_start + latency_bound(type) + 0.5);
    SCOPED_TRACE(std::string(scene_name) + ": " + std::string(pw::model::to_string(type)) +
                 " joint " + std::to_string(f.joint) + " value " + std::to_string(f.value) +
                 " at " + std::to_string(f.t_start) + " s");
    ASSERT_EQ(res.status, pw::model::StepStatus::kOk);
    ASSERT_TRUE(res.detected) << "not detected";
    EXPECT_FALSE(res.false_alarm) << "alarm before the onset: "
                                  << pw::faultbench::class_name(res.fault) << " at " << res.t_detect;
    EXPECT_STREQ(pw::faultbench::class_name(res.fault),
                 pw::faultbench::class_name(pw::faultbench::expected_class(type)));
    EXPECT_EQ(res.joint, pw::faultbench::expected_joint(f));
    EXPECT_LE(res.latency, latency_bound(type));
    EXPECT_GE(res.latency, 0.0);
  }
}

std::string name_of(const ::testing::TestParamInfo<FaultType>& info) {
  return std::string(pw::model::to_string(info.param));
}

INSTANTIATE_TEST_SUITE_P(
    EveryFault, Campaign,
    ::testing::Values(FaultType::kTorqueGain, FaultType::kMotorFriction, FaultType::kSpringScale,
                      FaultType::kJointLoad, FaultType::kEncoderStuck, FaultType::kEncoderOffset,
                      FaultType::kEncoderNoise, FaultType::kDeflectionStuck,
                      FaultType::kDeflectionBias, FaultType::kDeflectionScale, FaultType::kNaN,
                      FaultType::kImplausible, FaultType::kModuleSilent, FaultType::kStale,
                      FaultType::kOutOfOrder, FaultType::kRepeatedFrame),
    name_of);

// The residual-classified faults also estimate their size (the fitted signature).
TEST(Campaign, ResidualEstimatesTheFaultSize) {
  struct Case { FaultType type; double value; double estimate_tol; };
  for (const Case c : {Case{FaultType::kTorqueGain, 0.5, 0.05}, Case{FaultType::kMotorFriction, 0.06, 0.01},
                       Case{FaultType::kSpringScale, 0.25, 0.05}, Case{FaultType::kDeflectionBias, 0.05, 0.01},
                       Case{FaultType::kDeflectionScale, 1.5, 0.2}}) {
    pw::model::FaultSpec f;
    f.type = c.type;
    f.joint = 2;
    f.t_start = 4.0;
    f.value = c.value;
    pw::faultbench::LoopOptions o;
    const auto res = pw::faultbench::run_fault(pw::faultbench::shipped_scene("flat_low_friction"),
                                               o, f, 9.0);
    SCOPED_TRACE(std::string(pw::model::to_string(c.type)));
    ASSERT_TRUE(res.detected);
    EXPECT_EQ(res.fault, pw::faultbench::expected_class(c.type));
    EXPECT_NEAR(res.estimate, c.value, c.estimate_tol);
  }
}

// The residual's detectability limit the README states: a deflection scale error adds
// (1 − 1/s)·K·deflection to the motor rows. The head joint (joint 4) carries only the head link,
// its SEA torque peaks near 0.06 N·m, so s = 1.44 stays under the 0.03 N·m threshold (the two
// misses of the benchmark campaign) — and is not misnamed as anything else — while the same
// error on joint 1 (torques ≈ 0.15 N·m) and s = 0.55 on the head joint (|1 − 1/s| = 0.8) are found.
TEST(Campaign, DeflectionScaleDetectabilityOnTheHeadJoint) {
  struct Case { int joint; double s; bool detectable; };
  for (const Case c : {Case{4, 1.44, false}, Case{1, 1.44, true}, Case{4, 0.55, true}}) {
    pw::model::FaultSpec f;
    f.type = FaultType::kDeflectionScale;
    f.joint = c.joint;
    f.t_start = 4.0;
    f.value = c.s;
    pw::faultbench::LoopOptions o;
    const auto res = pw::faultbench::run_fault(pw::faultbench::shipped_scene("flat_high_friction"), o, f, 12.0);
    SCOPED_TRACE("joint " + std::to_string(c.joint) + ", s = " + std::to_string(c.s));
    ASSERT_EQ(res.status, pw::model::StepStatus::kOk);
    EXPECT_EQ(res.detected, c.detectable);
    if (c.detectable) {
      EXPECT_EQ(res.fault, pw::faultbench::expected_class(FaultType::kDeflectionScale));
      EXPECT_EQ(res.joint, c.joint);
    }
  }
}

}  // namespace
