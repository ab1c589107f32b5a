// The observer's flight recorder (input_log.hpp): the CSV round trip is exact, the ring keeps the
// newest cycles, recording allocates nothing, and a replay of a closed-loop run with a fault
// reproduces the live observer bit for bit — and differs when the replayed observer does.
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>

#include "alloc_counter.hpp"
#include "harness.hpp"
#include "pedalwave/observer/input_log.hpp"
#include "pedalwave/runtime/runtime.hpp"

namespace pw = pedalwave;
using pw::observer::InputLog;

namespace {

std::filesystem::path temp_file(const char* name) {
  const char* dir = std::getenv("TEST_TMPDIR");
  return std::filesystem::path(dir ? dir : ::testing::TempDir()) / name;
}

// Random inputs in every field, including the sequence sentinels and extreme stamps.
void random_cycle(std::mt19937_64& rng, int J, pw::drivers::Feedback& fb, pw::drivers::Command& c,
                  pw::runtime::CycleSample& s, pw::runtime::Verdict& v) {
  std::uniform_real_distribution<double> u(-3.0, 3.0);
  std::uniform_int_distribution<std::int64_t> ns(0, std::numeric_limits<std::int64_t>::max());
  fb.joints = c.joints = J;
  fb.seq = rng();
  fb.stamp_ns = ns(rng);
  fb.timing = rng() % 2 ? pw::drivers::FeedbackTiming::kModule : pw::drivers::FeedbackTiming::kNominal;
  c.seq = rng() % 3 == 0 ? pw::drivers::kNoCommandSeq : rng() >> 1;
  c.torque_off = rng() % 2;
  for (std::size_t k = 0; k < static_cast<std::size_t>(J); ++k) {
    fb.set_joint(k, {u(rng) * 1e-7, u(rng) * 1e5, u(rng) / 3.0, static_cast<std::uint16_t>(rng())});
    fb.sample_ns[k] = ns(rng);
    fb.applied_seq[k] = rng() % 4 == 0 ? pw::drivers::kUnknownSeq : rng();
    fb.applied_ns[k] = ns(rng);
    fb.late_applied_seq[k] = rng();
    fb.late_applied_ns[k] = -ns(rng);
    c.tau[k] = u(rng), c.beta_ref[k] = u(rng), c.beta_dot_ref[k] = u(rng), c.kp[k] = u(rng), c.kd[k] = u(rng);
    s.residual[k] = u(rng) * 1e-300;
  }
  v.fault = static_cast<pw::runtime::FaultClass>(rng() % static_cast<int>(pw::runtime::FaultClass::kCount));
  v.flags = static_cast<std::uint32_t>(rng());
  v.joint = static_cast<std::int16_t>(static_cast<int>(rng() % 12) - 1);
}

}  // namespace

TEST(InputLog, TheReplayRebuildsTheRuntimesCommandHistory) {
  // replay() rebuilds a history as deep as the runtime's (input_log.cpp's kHistory).
  EXPECT_EQ(pw::runtime::Runtime::kCommandHistory, 16);
}

TEST(InputLog, ACsvRoundTripIsExactInEveryField) {
  constexpr int J = 11;
  InputLog log(J, 40);
  std::mt19937_64 rng(7);
  pw::drivers::Feedback fb;
  pw::drivers::Command c;
  pw::runtime::CycleSample s;
  pw::runtime::Verdict v;
  for (int i = 0; i < 40; ++i) {
    random_cycle(rng, J, fb, c, s, v);
    log.record(fb, c, 1e-3 * i + 1e-17, 1e-3 + 1e-19 * i, v, s);
  }
  const pw::drivers::FeedbackSpec spec{.beta_lsb = 1.0 / 4096, .beta_dot_lsb = 0.0229 * 0.10471975511965977,
                                       .deflection_lsb = 3e-5, .torque_lsb = 1e-3,
                                       .sample_time_uncertainty = 2.5e-4, .stale_limit = 7};
  const auto path = temp_file("input_log_roundtrip.csv");
  log.write_csv(path, spec);
  pw::drivers::FeedbackSpec back_spec;
  const InputLog back = InputLog::read_csv(path, &back_spec);
  EXPECT_EQ(back_spec.beta_lsb, spec.beta_lsb);
  EXPECT_EQ(back_spec.beta_dot_lsb, spec.beta_dot_lsb);
  EXPECT_EQ(back_spec.deflection_lsb, spec.deflection_lsb);
  EXPECT_EQ(back_spec.torque_lsb, spec.torque_lsb);
  EXPECT_EQ(back_spec.sample_time_uncertainty, spec.sample_time_uncertainty);
  EXPECT_EQ(back_spec.stale_limit, spec.stale_limit);
  ASSERT_EQ(back.joints(), J);
  ASSERT_EQ(back.size(), log.size());
  pw::drivers::Feedback f0, f1;
  pw::drivers::Command c0, c1;
  for (std::size_t i = 0; i < log.size(); ++i) {
    const InputLog::Cycle &a = log.cycle(i), &b = back.cycle(i);
    EXPECT_EQ(a.cycle, b.cycle);
    EXPECT_EQ(a.t, b.t);
    EXPECT_EQ(a.dt, b.dt);
    EXPECT_EQ(a.fault, b.fault);
    EXPECT_EQ(a.flags, b.flags);
    EXPECT_EQ(a.fault_joint, b.fault_joint);
    log.feedback(i, f0), back.feedback(i, f1);
    log.command(i, c0), back.command(i, c1);
    // Every byte observe() gets: the structs compared as memory (both zero-initialized first).
    EXPECT_EQ(std::memcmp(&f0, &f1, sizeof f0), 0) << "cycle " << i;
    EXPECT_EQ(std::memcmp(&c0, &c1, sizeof c0), 0) << "cycle " << i;
    for (int j = 0; j < J; ++j) EXPECT_EQ(log.joint(i, j).residual, back.joint(i, j).residual);
  }
  EXPECT_EQ(back.cycle(3).cmd_seq == pw::drivers::kNoCommandSeq, log.cycle(3).cmd_seq == pw::drivers::kNoCommandSeq);
}

TEST(InputLog, TheRingKeepsTheNewestCycles) {
  InputLog log(2, 5);
  pw::drivers::Feedback fb;
  pw::drivers::Command c;
  pw::runtime::CycleSample s;
  for (int i = 0; i < 12; ++i) {
    fb.seq = static_cast<std::uint64_t>(100 + i);
    log.record(fb, c, i * 0.01, 0.01, {}, s);
  }
  EXPECT_EQ(log.recorded(), 12u);
  ASSERT_EQ(log.size(), 5u);
  for (std::size_t i = 0; i < 5; ++i) {
    EXPECT_EQ(log.cycle(i).cycle, 7 + i);
    EXPECT_EQ(log.cycle(i).fb_seq, 107 + i);
  }
}

TEST(InputLog, BadFilesAreNamed) {
  const auto path = temp_file("input_log_bad.csv");
  std::ofstream(path) << "a,b\n1,2\n";
  try {
    (void)InputLog::read_csv(path);
    FAIL() << "no error";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("expected an observer input log"), std::string::npos) << e.what();
  }
  EXPECT_THROW(InputLog(0, 10), std::invalid_argument);
  EXPECT_THROW(InputLog(3, 0), std::invalid_argument);
}

// A closed loop on flat ground with an actuator fault: the recording observer in front of the
// loop's observer; recording allocates nothing; the replay of the log on a fresh observer gives
// the live residuals bit for bit and the same first fault in the same cycle; an observer with a
// higher threshold replayed on the same log does not.
TEST(InputLog, AReplayReproducesTheLiveObserverBitForBit) {
  pw::faultbench::LoopOptions o;
  pw::faultbench::FaultLoop loop(pw::faultbench::shipped_scene("flat_high_friction"), o);
  pw::model::FaultSpec f;
  f.type = pw::model::FaultType::kTorqueGain;
  f.joint = 4;
  f.t_start = 3.0;
  f.value = 0.5;
  loop.injector().add(f);
  const int J = loop.observer().core().joints();
  constexpr int kCycles = 7000;
  InputLog log(J, kCycles);
  pw::observer::RecordingObserver rec(loop.observer(), log);
  loop.observe_through(rec);
  for (int i = 0; i < kCycles; ++i) ASSERT_EQ(loop.step(), pw::model::StepStatus::kOk);
  ASSERT_EQ(log.size(), static_cast<std::size_t>(kCycles));

  // The recording observer in the cycle allocates nothing (the ring full and wrapping too).
  InputLog small(J, 100);
  pw::observer::RecordingObserver rec2(loop.observer(), small);
  pw::runtime::CycleSample sample{};
  std::uint64_t allocs = 0;
  for (int i = 0; i < 300; ++i) {
    pw::test::AllocationScope scope;
    (void)rec2.observe(loop.feedback(), loop.command(), loop.t() + i * 1e-3, 1e-3, sample);
    allocs += scope.count();
  }
  EXPECT_EQ(allocs, 0u);
  EXPECT_EQ(small.recorded(), 300u);

  const auto path = temp_file("input_log_replay.csv");
  log.write_csv(path, {});
  const InputLog back = InputLog::read_csv(path);
  pw::observer::RuntimeObserver fresh(loop.observer().core().params());
  const pw::observer::ReplayResult r = pw::observer::replay(back, fresh);
  EXPECT_EQ(r.cycles, static_cast<std::size_t>(kCycles));
  ASSERT_NE(r.live_fault_at, SIZE_MAX) << "the injected torque loss was not found live";
  EXPECT_EQ(r.live_fault, pw::runtime::FaultClass::kActuatorTorque);
  EXPECT_EQ(r.live_joint, 4);
  EXPECT_EQ(r.replay_fault_at, r.live_fault_at);
  EXPECT_EQ(r.replay_fault, r.live_fault);
  EXPECT_EQ(r.replay_joint, r.live_joint);
  EXPECT_EQ(r.max_residual_difference, 0.0);
  EXPECT_EQ(r.verdicts_differing, 0u);

  pw::observer::ObserverParams blunt = loop.observer().core().params();
  blunt.r_threshold *= 100;
  pw::observer::RuntimeObserver other(blunt);
  const pw::observer::ReplayResult r2 = pw::observer::replay(back, other);
  EXPECT_EQ(r2.replay_fault_at, SIZE_MAX);
  EXPECT_GT(r2.verdicts_differing, 0u);
}
