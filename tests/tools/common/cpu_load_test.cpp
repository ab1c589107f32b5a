// The CPU load generator (tools/common/src/cpu_load.cpp): its children exist and spin while it
// runs, consume CPU time, and are all gone (killed and reaped) after stop() or destruction.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>

#include <chrono>
#include <stdexcept>
#include <thread>
#include <vector>

#include "pedalwave/toolkit/cpu_load.hpp"

namespace tk = pedalwave::toolkit;

namespace {
double children_cpu_seconds() {
  rusage ru{};
  ::getrusage(RUSAGE_CHILDREN, &ru);
  return static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}
}  // namespace

TEST(CpuLoad, ChildrenRunConsumeCpuAndAreGoneAfterStop) {
  const double before = children_cpu_seconds();
  tk::CpuLoad load;
  load.start(2);
  ASSERT_EQ(load.pids().size(), 2u);
  const std::vector<pid_t> pids = load.pids();
  for (const pid_t p : pids) EXPECT_TRUE(tk::process_alive(p)) << p;
  std::this_thread::sleep_for(std::chrono::milliseconds(600));
  EXPECT_GT(load.cpu_seconds(), 0.0) << "from /proc/<pid>/stat while running";
  load.stop();
  EXPECT_FALSE(load.running());
  for (const pid_t p : pids) {
    EXPECT_FALSE(tk::process_alive(p)) << p;
    errno = 0;
    EXPECT_EQ(::waitpid(p, nullptr, WNOHANG), -1) << "already reaped";
  }
  // Two spinning children for 0.6 s on a shared machine: well above zero, at most 2 × 0.6 s + slack.
  EXPECT_GT(load.cpu_seconds(), 0.05);
  EXPECT_LT(load.cpu_seconds(), 2.0);
  EXPECT_GT(children_cpu_seconds() - before, 0.05) << "getrusage(RUSAGE_CHILDREN) agrees";
  load.stop();  // idempotent
}

TEST(CpuLoad, DutyCycleUsesLessCpuAndDestructorStops) {
  std::vector<pid_t> pids;
  double cpu = 0.0;
  {
    tk::CpuLoad load;
    load.start(1, 0.2);
    EXPECT_DOUBLE_EQ(load.duty(), 0.2);
    pids = load.pids();
    std::this_thread::sleep_for(std::chrono::milliseconds(1000));
    cpu = load.cpu_seconds();
  }
  for (const pid_t p : pids) EXPECT_FALSE(tk::process_alive(p)) << p;
  // Busy 2 ms of every 10 ms for 1 s: ≈ 0.2 s; clock ticks (10 ms) and scheduling make it rough.
  EXPECT_GT(cpu, 0.0);
  EXPECT_LT(cpu, 0.6);
}

TEST(CpuLoad, RefusesBadArguments) {
  tk::CpuLoad load;
  EXPECT_THROW(load.start(1, 0.0), std::invalid_argument);
  EXPECT_THROW(load.start(1, 1.5), std::invalid_argument);
  EXPECT_THROW(load.start(-1), std::invalid_argument);
  load.start(0);
  EXPECT_FALSE(load.running());
  EXPECT_FALSE(tk::process_alive(0x3fffffff));
}

TEST(CpuLoad, ChildrenEndOnSigintAndAreStillReaped) {
  // A terminal's Ctrl-C reaches the children too (same process group): they end at once instead of
  // running the parent's handler, and stop() still reaps them.
  tk::CpuLoad load;
  load.start(1);
  const pid_t pid = load.pids().at(0);
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  ASSERT_EQ(::kill(pid, SIGINT), 0);
  for (int k = 0; k < 200 && tk::process_alive(pid); ++k) std::this_thread::sleep_for(std::chrono::milliseconds(10));
  EXPECT_FALSE(tk::process_alive(pid));
  load.stop();
  EXPECT_EQ(::waitpid(pid, nullptr, WNOHANG), -1) << "reaped";
}
