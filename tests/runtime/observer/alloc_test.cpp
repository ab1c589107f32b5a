// observe() (with the body model) and the fault injector's read/write allocate nothing per cycle.
#include <gtest/gtest.h>

#include "alloc_counter.hpp"
#include "harness.hpp"

namespace pw = pedalwave;

TEST(NoAllocation, ObserverAndInjectorInTheCycle) {
  pw::faultbench::LoopOptions o;
  pw::faultbench::FaultLoop loop(pw::faultbench::shipped_scene("stair"), o);
  // Faults of every path active during the measured cycles.
  for (auto type : {pw::model::FaultType::kEncoderNoise, pw::model::FaultType::kStale,
                    pw::model::FaultType::kTorqueGain, pw::model::FaultType::kDeflectionStuck}) {
    pw::model::FaultSpec f;
    f.type = type;
    f.joint = type == pw::model::FaultType::kStale ? 1 : 3;
    f.t_start = 0.5;
    f.value = type == pw::model::FaultType::kStale ? 2 : 0.5;
    loop.injector().add(f);
  }
  for (int i = 0; i < 200; ++i) loop.step();  // warm up
  pw::drivers::Feedback fb{};
  pw::runtime::CycleSample sample{};
  pw::drivers::Command cmd = loop.command();
  std::uint64_t observe_allocs = 0, read_allocs = 0;
  for (int i = 0; i < 3000; ++i) {
    {
      pw::test::AllocationScope scope;
      loop.injector().read(0, 0, fb);
      read_allocs += scope.count();
    }
    {
      pw::test::AllocationScope scope;
      (void)loop.observer().observe(fb, cmd, i * 1e-3, 1e-3, sample);
      observe_allocs += scope.count();
    }
    loop.injector().write(cmd);
  }
  EXPECT_EQ(read_allocs, 0u);
  EXPECT_EQ(observe_allocs, 0u);
  EXPECT_GT(loop.observer().core().fault_count(), 0);  // the fault paths ran
}
