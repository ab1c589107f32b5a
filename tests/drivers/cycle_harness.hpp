// Runs the host side of the cycle (read → command → write → sleep to the next period) for the
// driver integration tests and records what every cycle reported.
#pragma once

#include <time.h>

#include <cmath>
#include <cstdint>
#include <vector>

#include "pedalwave/interface/io.hpp"

namespace pedalwave::test {

struct CycleLog {
  std::vector<drivers::IoStatus> io;
  std::vector<std::array<std::uint16_t, drivers::kMaxJoints>> status;
  std::vector<drivers::Feedback> fb;
  std::vector<std::int64_t> wake;  // the cycle's start (the read's now) [ns, CLOCK_MONOTONIC]
};

inline std::int64_t now_ns() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec * 1'000'000'000LL + ts.tv_nsec;
}

inline void sleep_until(std::int64_t t) {
  timespec ts{static_cast<time_t>(t / 1'000'000'000LL), static_cast<long>(t % 1'000'000'000LL)};
  clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, nullptr);
}

// Waits (polling every ms) until pred() holds or timeout_ns passed; returns pred().
template <class Pred>
bool wait_for(Pred pred, std::int64_t timeout_ns) {
  const std::int64_t give_up = now_ns() + timeout_ns;
  while (!pred() && now_ns() < give_up) sleep_until(now_ns() + 1'000'000);
  return pred();
}

// A smooth command: β_ref_j = 0.3 sin(2π·2 Hz·t + j), module PD kp = 2, kd = 0.05.
inline void make_command(drivers::Command& c, int joints, std::int64_t t_ns) {
  c.joints = joints;
  const double t = 1e-9 * static_cast<double>(t_ns);
  for (int j = 0; j < joints; ++j) {
    c.tau[j] = 0.01;
    c.beta_ref[j] = 0.3 * std::sin(2 * M_PI * 2.0 * t + j);
    c.beta_dot_ref[j] = 0.3 * 2 * M_PI * 2.0 * std::cos(2 * M_PI * 2.0 * t + j);
    c.kp[j] = 2.0;
    c.kd[j] = 0.05;
  }
}

// `cycles` cycles of period `period_ns`, read deadline `deadline_ns` after the cycle start.
// write_commands = false leaves the modules without commands (lifetime test).
inline CycleLog run_cycles(drivers::Driver& drv, int cycles, std::int64_t period_ns,
                           std::int64_t deadline_ns, bool write_commands = true) {
  CycleLog log;
  log.io.reserve(static_cast<std::size_t>(cycles));
  log.status.reserve(static_cast<std::size_t>(cycles));
  log.fb.reserve(static_cast<std::size_t>(cycles));
  log.wake.reserve(static_cast<std::size_t>(cycles));
  drivers::Feedback fb{};
  drivers::Command cmd{};
  std::int64_t t0 = now_ns();
  for (int i = 0; i < cycles; ++i) {
    const drivers::IoStatus s = drv.read(t0, t0 + deadline_ns, fb);
    log.io.push_back(s);
    std::array<std::uint16_t, drivers::kMaxJoints> st{};
    for (int j = 0; j < drv.joints(); ++j) st[j] = fb.status[j];
    log.status.push_back(st);
    log.fb.push_back(fb);
    log.wake.push_back(t0);
    if (write_commands) {
      make_command(cmd, drv.joints(), t0);
      drv.write(cmd);
    }
    t0 += period_ns;
    if (t0 < now_ns()) t0 = now_ns();  // never try to catch up: a slow machine gets longer cycles
    sleep_until(t0);
  }
  return log;
}

// Every late answer used as a sample (kStatusLate without kStatusMissing) carries the sample time
// of the SYNC it answered: after the start of one of the last 8 cycles (less the clock estimate's
// slack; a hiccup delays an answer by more than a cycle) and before the end of this cycle's read (an emulator thread that stalled samples late, and says so);
// the sample times handed out for a joint increase. Returns how many joint-cycles were late
// answers used.
inline int check_late_samples(const CycleLog& log, int joints, std::int64_t read_end_ns) {
  int used = 0;
  for (int j = 0; j < joints; ++j) {
    std::int64_t prev = 0;
    for (std::size_t i = 0; i < log.fb.size(); ++i) {
      const drivers::Feedback& fb = log.fb[i];
      const std::uint16_t st = fb.status[j];
      if (st & drivers::kStatusMissing) continue;
      const std::int64_t s = fb.sample_ns[j];
      EXPECT_GT(s, prev) << "cycle " << i << " joint " << j << ": sample times increase";
      prev = s;
      if ((st & drivers::kStatusLate) == 0 || i == 0) continue;
      ++used;
      EXPECT_LT(s, log.wake[i] + read_end_ns) << "cycle " << i << " joint " << j;
      EXPECT_GT(s, log.wake[i < 8 ? 0 : i - 8] - 1'000'000) << "cycle " << i << " joint " << j;
    }
  }
  return used;
}

}  // namespace pedalwave::test
