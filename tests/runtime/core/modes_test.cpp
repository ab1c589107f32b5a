#include <gtest/gtest.h>

#include <set>
#include <utility>

#include "pedalwave/runtime/modes.hpp"

namespace {

using pedalwave::runtime::Mode;
using pedalwave::runtime::ModeMachine;
using pedalwave::runtime::TransitionStatus;
using pedalwave::runtime::transition_allowed;

TEST(ModeMachine, TableIsExactlyTheDesignedOne) {
  using M = Mode;
  const std::set<std::pair<M, M>> legal = {
      {M::kUnconfigured, M::kConfigured}, {M::kConfigured, M::kCalibrating},
      {M::kConfigured, M::kReady},        {M::kConfigured, M::kSafeStop},
      {M::kCalibrating, M::kReady},       {M::kCalibrating, M::kFault},
      {M::kCalibrating, M::kSafeStop},    {M::kReady, M::kCalibrating},
      {M::kReady, M::kRunning},           {M::kReady, M::kFault},
      {M::kReady, M::kSafeStop},          {M::kRunning, M::kFault},
      {M::kRunning, M::kSafeStop},        {M::kFault, M::kSafeStop},
  };
  for (int a = 0; a <= static_cast<int>(M::kSafeStop); ++a) {
    for (int b = 0; b <= static_cast<int>(M::kSafeStop); ++b) {
      const auto from = static_cast<M>(a), to = static_cast<M>(b);
      EXPECT_EQ(transition_allowed(from, to), legal.count({from, to}) == 1)
          << to_string(from) << " -> " << to_string(to);
    }
  }
}

TEST(ModeMachine, EveryWayOutOfRunningPassesTheSafeStop) {
  // From RUNNING the only successors are FAULT and SAFE_STOP, and FAULT only leads to SAFE_STOP.
  for (int b = 0; b <= static_cast<int>(Mode::kSafeStop); ++b) {
    const auto to = static_cast<Mode>(b);
    if (transition_allowed(Mode::kRunning, to)) {
      EXPECT_TRUE(to == Mode::kFault || to == Mode::kSafeStop) << to_string(to);
    }
    if (transition_allowed(Mode::kFault, to)) {
      EXPECT_EQ(to, Mode::kSafeStop);
    }
    EXPECT_FALSE(transition_allowed(Mode::kSafeStop, to)) << "SAFE_STOP is terminal";
  }
}

TEST(ModeMachine, IllegalRequestIsRejectedAndLeavesTheModeAlone) {
  ModeMachine m;
  EXPECT_EQ(m.request(Mode::kRunning), TransitionStatus::kIllegal);
  EXPECT_EQ(m.mode(), Mode::kUnconfigured);
  EXPECT_EQ(m.request(Mode::kConfigured), TransitionStatus::kOk);
  EXPECT_EQ(m.request(Mode::kConfigured), TransitionStatus::kNoChange);
  EXPECT_EQ(m.request(Mode::kReady), TransitionStatus::kOk);
  EXPECT_EQ(m.request(Mode::kRunning), TransitionStatus::kOk);
  EXPECT_EQ(m.request(Mode::kReady), TransitionStatus::kIllegal);
  EXPECT_EQ(m.mode(), Mode::kRunning);
  EXPECT_EQ(m.request(Mode::kFault), TransitionStatus::kOk);
  EXPECT_EQ(m.request(Mode::kRunning), TransitionStatus::kIllegal);
  EXPECT_EQ(m.request(Mode::kSafeStop), TransitionStatus::kOk);
}

TEST(ModeNames, AreDistinct) {
  std::set<std::string> names;
  for (int a = 0; a <= static_cast<int>(Mode::kSafeStop); ++a) names.insert(to_string(static_cast<Mode>(a)));
  EXPECT_EQ(names.size(), 7u);
  std::set<std::string> faults;
  for (int f = 0; f < static_cast<int>(pedalwave::runtime::FaultClass::kCount); ++f)
    faults.insert(to_string(static_cast<pedalwave::runtime::FaultClass>(f)));
  EXPECT_EQ(faults.size(), static_cast<std::size_t>(pedalwave::runtime::FaultClass::kCount));
  EXPECT_EQ(faults.count("?"), 0u);
}

}  // namespace
