// ModuleClock: the host's estimate of a module's free-running µs clock, from the SYNCs' send times
// (a lower bound of each sample's host time), against the truth of a simulated module clock with
// an offset, a drift, a wrap of its 32-bit counter and one-sided host delays (spikes included).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>

#include "pedalwave/drivers/late_sample.hpp"
#include "pedalwave/drivers/module_clock.hpp"

namespace pd = pedalwave::drivers;

namespace {

struct Truth {
  double drift_ppm;        // module clock rate error [ppm]
  std::uint32_t start_us;  // module clock at host time t0
  std::int64_t t0_ns;
  std::uint32_t module_us(std::int64_t host_ns) const {
    const double us = std::floor(static_cast<double>(host_ns - t0_ns) * (1.0 + drift_ppm * 1e-6) * 1e-3);
    return start_us + static_cast<std::uint32_t>(static_cast<std::int64_t>(us) & 0xFFFFFFFFll);
  }
};

}  // namespace

TEST(ModuleClock, OffsetAndDriftFromOneSidedDelays) {
  for (double drift : {-50.0, 0.0, 35.0}) {
    const Truth tr{drift, 4294967295u - 1'500'000u, 1'000'000'000'000};  // wraps after 1.5 s
    pd::ModuleClock clk;
    std::mt19937 rng(3);
    std::exponential_distribution<double> delay(1.0 / 40e3);  // 40 µs mean host delay [ns]
    std::uniform_real_distribution<double> u(0, 1);
    double worst_abs = 0, worst_step = 0;
    std::int64_t prev_est = 0, prev_true = 0;
    for (int k = 0; k < 60000; ++k) {  // 60 s at 1 kHz
      const std::int64_t sample = tr.t0_ns + 1'000'000ll * k + static_cast<std::int64_t>(200e3 * u(rng));  // jittered SYNCs
      // The host knows only a time before the sample: its send time (one-sided delay, spikes).
      const double d = delay(rng) + (u(rng) < 0.01 ? 5e6 : 0.0);
      const std::int64_t lower = sample - static_cast<std::int64_t>(d);
      const std::int64_t est = clk.update(tr.module_us(sample), lower);
      // Absolute times once converged (kSlew = 20 ppm: a 0.5 ms initial error takes 25 s).
      if (k >= 50000) worst_abs = std::max(worst_abs, std::abs(static_cast<double>(est - sample)));
      // Intervals from the first on: the clock's µs floor + kSlew · interval (≤ 1.02 µs here).
      if (k > 0)
        worst_step = std::max(worst_step, std::abs(static_cast<double>((est - prev_est) - (sample - prev_true))));
      prev_est = est;
      prev_true = sample;
    }
    ASSERT_TRUE(clk.locked());
    EXPECT_NEAR(clk.drift_ppm(), drift, 2.0) << "drift " << drift;
    EXPECT_LT(worst_abs, 20e3) << "sample times within 20 µs of the truth (drift " << drift << ")";
    EXPECT_LT(worst_step, 1e3 + pd::ModuleClock::kSlew * 1.2e6 + 100)
        << "intervals within the clock's µs resolution and the slew (drift " << drift << ")";
    // The applied-time mapping: a module time 300 µs before the last sample.
    const std::int64_t last = prev_true;
    const std::uint32_t m = tr.module_us(last - 300'000);
    EXPECT_NEAR(static_cast<double>(clk.to_host(m) - (last - 300'000)), 0.0, 20e3);
  }
}

TEST(ModuleClock, NeverEarlierThanAProvenBoundBeforeLock) {
  pd::ModuleClock clk;
  const Truth tr{20.0, 7, 5'000'000'000};
  for (int k = 0; k < 100; ++k) {
    const std::int64_t sample = tr.t0_ns + 1'000'000ll * k;
    const std::int64_t lower = sample - (k % 7 == 0 ? 0 : 30'000);
    const std::int64_t est = clk.update(tr.module_us(sample), lower);
    EXPECT_GE(est - lower, -1000) << "cycle " << k;  // the µs floor of the module's stamp
    EXPECT_LT(std::abs(est - sample), 3000) << "cycle " << k;
  }
  EXPECT_FALSE(clk.locked());
}

// The application time a driver hands out: the sample time minus the age, on the host clock;
// unknown (0) once the age saturated at kAgeMaxUs (applied 32.8 ms or more before the sample).
TEST(ModuleClock, ASaturatedApplicationAgeIsAnUnknownApplicationTime) {
  namespace wire = pd::wire;
  pd::ModuleClock clk;
  const std::int64_t host = 5'000'000'000;
  const std::int64_t at = clk.update(1'000'000u, host);
  wire::ModuleTiming t{1'000'000u, 1234, false, 0};
  EXPECT_EQ(pd::applied_host_ns(t, clk), at - 1'234'000);
  t.applied_age_us = wire::kAgeMaxUs - 1;
  EXPECT_EQ(pd::applied_host_ns(t, clk), at - 1000 * std::int64_t{wire::kAgeMaxUs - 1});
  t.applied_age_us = wire::kAgeMaxUs;
  EXPECT_EQ(pd::applied_host_ns(t, clk), 0);
  pd::Feedback out;
  pd::HandedOut handed;
  pd::CycleLog log;
  log.sync(256, host + 10'000'000);  // SYNC of cycle 256 (counter 0)
  log.command(256, 41);              // its command, tag 0
  log.sync(257, host + 10'000'000);
  pd::hand_out(t, log, 257, true, 256, clk, handed, out, 2);
  EXPECT_GT(out.sample_ns[2], 0);
  EXPECT_EQ(out.applied_ns[2], 0) << "the observer does not place the command at the saturated age";
  EXPECT_EQ(out.applied_seq[2], 41u);
}

// The least delay itself can change for seconds: in the VM under load the modules' thread ran
// every SYNC ≥ 58 ms late for a stretch (the emulated CPU it runs on was starved), then on time
// again. Every block maximum is still a valid lower bound, but those of the late stretch lie 58 ms
// below the line: fitted through them, the drift came out at 7000–19000 ppm and every interval
// handed out 0.7–1.9 ms long at 100 Hz — the VM's false encoder_jumps (|c| = ε·dt·β̇ ≈ 5e-4 …
// 2e-3 rad). A drift beyond any crystal's is an offset change of the bounds, not drift.
TEST(ModuleClock, AStretchOfLateSamplesIsNotDrift) {
  for (const bool late_first : {true, false}) {
    const char* what = late_first ? "late first" : "late stretch later";
    const double drift = 30.0;
    const Truth tr{drift, 123'456u, 2'000'000'000'000};
    pd::ModuleClock clk;
    std::mt19937 rng(5);
    std::exponential_distribution<double> delay(1.0 / 100e3);  // 100 µs mean [ns]
    std::uniform_real_distribution<double> u(0, 1);
    double worst_step = 0, worst_settled = 0;
    std::int64_t prev_est = 0, prev_true = 0;
    for (int k = 0; k < 3000; ++k) {  // 30 s at 100 Hz
      const std::int64_t sample = tr.t0_ns + 10'000'000ll * k + static_cast<std::int64_t>(2e6 * u(rng));
      // The late stretch: 0–4 s (late_first) or 6–10 s; a 58–100 ms floor on every delay.
      const double t = 0.01 * k;
      const bool late = late_first ? t < 4.0 : (t >= 6.0 && t < 10.0);
      const double d = delay(rng) + (late ? 58e6 + 42e6 * u(rng) : 0.0);
      const std::int64_t est = clk.update(tr.module_us(sample), sample - static_cast<std::int64_t>(d));
      if (k > 0) {
        const double step = std::abs(static_cast<double>((est - prev_est) - (sample - prev_true)));
        worst_step = std::max(worst_step, step);
        // Locked (three blocks in: until then no drift estimate, 30 ppm × 12 ms = 0.36 µs) and
        // not within three blocks after the late stretch: as tight as without it.
        const double lock = 3 * 1.28;
        if ((late_first && t >= 4.0 + lock) || (!late_first && ((t >= lock && t < 6.0) || t >= 10.0 + lock)))
          worst_settled = std::max(worst_settled, step);
      }
      prev_est = est;
      prev_true = sample;
    }
    ASSERT_TRUE(clk.locked());
    EXPECT_NEAR(clk.drift_ppm(), drift, 5.0) << what;
    // Everywhere: at most the largest drift a clock may have over the 12 ms interval (the late
    // stretch's own bounds scatter by the spread of its floor: its fit is that loose), and the
    // µs floor and the slew. Before the fix: 212 µs (late first), 92 µs.
    const double step_bound = 1e3 + pd::ModuleClock::kSlew * 12e6 + 100;
    EXPECT_LT(worst_step, step_bound + pd::ModuleClock::kMaxDrift * 12e6) << what << ": an interval off by " << worst_step << " ns";
    EXPECT_LT(worst_settled, step_bound) << what << ": an interval off by " << worst_settled << " ns";
  }
}
