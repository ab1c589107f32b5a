// SilenceTracker transitions with synthetic times.
#include <gtest/gtest.h>

#include "pedalwave/telemetry/liveness.hpp"

namespace pedalwave::telemetry {
namespace {

using T = SilenceTracker::Transition;
constexpr std::int64_t kMs = 1'000'000;

TEST(SilenceTracker, ReportsEachTransitionOnce) {
  SilenceTracker s(500 * kMs);
  EXPECT_EQ(s.check(10'000 * kMs), T::kNone) << "never heard: not 'silent'";
  EXPECT_FALSE(s.heard());
  EXPECT_EQ(s.on_sample(0), T::kFirstContact);
  EXPECT_EQ(s.on_sample(1 * kMs), T::kNone);
  EXPECT_EQ(s.check(501 * kMs), T::kNone) << "exactly at the timeout is not yet silent";
  EXPECT_EQ(s.check(502 * kMs), T::kWentSilent);
  EXPECT_TRUE(s.silent());
  EXPECT_EQ(s.check(5000 * kMs), T::kNone) << "silence reported once";
  EXPECT_EQ(s.on_sample(5001 * kMs), T::kCameBack);
  EXPECT_FALSE(s.silent());
  EXPECT_EQ(s.on_sample(5002 * kMs), T::kNone);
  EXPECT_EQ(s.check(5600 * kMs), T::kWentSilent);
  EXPECT_EQ(s.silences(), 2u);
}

TEST(SilenceTracker, RejectsNonPositiveTimeout) {
  EXPECT_THROW(SilenceTracker(0), std::invalid_argument);
  EXPECT_THROW(SilenceTracker(-5), std::invalid_argument);
}

}  // namespace
}  // namespace pedalwave::telemetry
