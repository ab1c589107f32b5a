// No false alarms: 10 simulated minutes per run, closed loop with sensor noise on and the modules'
// torque limit on (u_max = 0.8 N·m, so the saturation check is live), on every shipped scene and
// with the adaptive controller at the k_c sweep's extremes (0 and 15). The stair's contact forces
// act on the body rows only: they must not show in the motor residuals. Label "slow".
#include <gtest/gtest.h>

#include <ostream>

#include "harness.hpp"

namespace pw = pedalwave;

namespace {

struct Case {
  const char* scene;
  double k_c;
};

void PrintTo(const Case& c, std::ostream* os) { *os << c.scene << " k_c=" << c.k_c; }

class Nominal : public ::testing::TestWithParam<Case> {};

TEST_P(Nominal, TenMinutesWithoutFalseAlarm) {
  const Case c = GetParam();
  pw::model::Scene s = pw::faultbench::shipped_scene(c.scene);
  s.torque_limit_on = true;
  s.torque_limit.u_max = 0.8;
  pw::faultbench::LoopOptions o;
  o.k_c = c.k_c;
  o.seed = 4242 + static_cast<std::uint64_t>(c.k_c);
  const auto st = pw::faultbench::run_nominal(s, o, 600.0);
  ASSERT_EQ(st.status, pw::model::StepStatus::kOk);
  EXPECT_GE(st.seconds, 599.9);
  EXPECT_EQ(st.alarms, 0) << "first: " << pw::faultbench::class_name(st.first) << " joint "
                          << st.first_joint << " at " << st.first_t << " s, value "
                          << st.first_value;
  // Margins of the thresholds over what 10 minutes produced (README).
  const auto p = pw::faultbench::campaign_params(s);
  EXPECT_LT(st.max_residual, 0.75 * p.r_threshold);
  EXPECT_LT(st.max_consistency, 0.5 * p.consistency_threshold);
  EXPECT_LT(st.max_hold_beta, p.hold_cycles / 2);
  EXPECT_LT(st.max_hold_defl, p.hold_cycles_deflection);
  EXPECT_LT(st.max_saturation, p.saturation_fraction);
  RecordProperty("max_residual", std::to_string(st.max_residual));
}

INSTANTIATE_TEST_SUITE_P(
    Scenes, Nominal,
    ::testing::Values(Case{"flat_high_friction", 0.0}, Case{"flat_low_friction", 0.0},
                      Case{"friction_change", 0.0}, Case{"stair", 0.0}, Case{"stair", 15.0},
                      Case{"friction_change", 15.0}, Case{"stair_grip", 0.0}, Case{"stair_grip", 15.0}),
    [](const ::testing::TestParamInfo<Case>& i) {
      return std::string(i.param.scene) + "_kc" + std::to_string(static_cast<int>(i.param.k_c));
    });

}  // namespace
