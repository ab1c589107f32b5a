// Enumeration names (they travel in the *_name fields) and the synthetic robot's determinism.
#include <gtest/gtest.h>

#include <set>

#include "pedalwave/telemetry/names.hpp"
#include "pedalwave/telemetry/synthetic.hpp"

namespace pedalwave::telemetry {
namespace {

using runtime::FaultClass;
using runtime::Mode;

TEST(Names, EveryEnumeratorHasADistinctName) {
  std::set<std::string> seen;
  for (int f = 0; f < static_cast<int>(FaultClass::kCount); ++f) {
    const std::string n = fault_class_name(static_cast<std::uint8_t>(f));
    EXPECT_EQ(n.find('?'), std::string::npos) << "fault class " << f << " has no name";
    EXPECT_TRUE(seen.insert(n).second) << "duplicate name " << n;
    EXPECT_EQ(n, fault_class_c_str(static_cast<std::uint8_t>(f)));
  }
  EXPECT_EQ(mode_name(static_cast<std::uint8_t>(Mode::kSafeStop)), "safe_stop");
  EXPECT_EQ(mode_name(static_cast<std::uint8_t>(Mode::kRunning)), "running");
  EXPECT_EQ(severity_name(3), "stop");
  EXPECT_EQ(command_kind_name(2), "emergency_stop");
}

TEST(Names, OutOfRangeValuesAreShownNotHidden) {
  EXPECT_EQ(mode_name(200), "mode?200");
  EXPECT_EQ(fault_class_name(99), "fault?99");
  EXPECT_EQ(command_kind_name(7), "command?7");
  EXPECT_STREQ(mode_c_str(200), "?");
}

TEST(Names, FaultFlagsListEveryBitSet) {
  EXPECT_EQ(fault_flags_names(0), "");
  const std::uint32_t flags = (1u << static_cast<unsigned>(FaultClass::kEncoderStuck)) |
                              (1u << static_cast<unsigned>(FaultClass::kSpringBroken));
  EXPECT_EQ(fault_flags_names(flags), "encoder_stuck,spring_broken");
  EXPECT_NE(fault_flags_names(1u << 31).find("unknown_bits=0x80000000"), std::string::npos);
}

TEST(Names, CopyBoundedTruncatesAndTerminates) {
  char buf[4];
  copy_bounded(buf, "abcdef");
  EXPECT_STREQ(buf, "abc");
  copy_bounded(buf, nullptr);
  EXPECT_STREQ(buf, "");
}

TEST(SyntheticRobot, IsDeterministicAndFieldsAreDistinct) {
  const SyntheticRobot r(6, 1000.0);
  const auto a = r.sample(1234);
  const auto b = r.sample(1234);
  // sample(seq) is a pure function of seq.
  EXPECT_EQ(a.t_ns, b.t_ns);
  EXPECT_EQ(a.beta, b.beta);
  EXPECT_EQ(a.u, b.u);
  EXPECT_EQ(a.residual, b.residual);
  EXPECT_EQ(a.body, b.body);
  EXPECT_NE(r.sample(1235).beta[0], a.beta[0]);
  // Per-joint fields differ from one another, so a swapped field in a codec is caught.
  EXPECT_NE(a.beta[1], a.alpha[1]);
  EXPECT_NE(a.alpha_d[1], a.beta[1]);
  EXPECT_NE(a.residual[1], a.tau_ext[1]);
  EXPECT_NE(a.t_read_ns, a.t_write_ns);
  EXPECT_THROW(SyntheticRobot(0, 1000.0), std::invalid_argument);
  EXPECT_THROW(SyntheticRobot(6, 0.0), std::invalid_argument);
  EXPECT_EQ(r.description().links, 7);
}

}  // namespace
}  // namespace pedalwave::telemetry
