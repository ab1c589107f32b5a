// Real-time setup: validation messages, the "refused" path (warning text, or exception with
// require_rt) in a child process whose privileges were dropped, and the "granted" path when the
// test machine allows it (skipped loudly otherwise).
#include <gtest/gtest.h>

#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "pedalwave/runtime/rt_setup.hpp"

namespace {

// ASan/TSan replace mlockall() with a no-op that returns 0 (locking the shadow memory would be
// absurd), so in sanitizer builds "locked" cannot be observed either way.
#if defined(PEDALWAVE_SANITIZED)
constexpr bool kMlockObservable = false;
#else
constexpr bool kMlockObservable = true;
#endif

using pedalwave::runtime::apply_rt;
using pedalwave::runtime::RtConfig;
using pedalwave::runtime::RtReport;

std::string validation_error(const RtConfig& c) {
  try {
    pedalwave::runtime::validate(c);
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return {};
}

TEST(RtConfig, DefaultsAreValid) {
  RtConfig c;
  EXPECT_EQ(c.rate_hz, 1000.0);
  EXPECT_NO_THROW(pedalwave::runtime::validate(c));
}

TEST(RtConfig, ValidationNamesItemValueAndRange) {
  RtConfig c;
  c.rate_hz = 25000;
  std::string e = validation_error(c);
  EXPECT_NE(e.find("rate_hz"), std::string::npos) << e;
  EXPECT_NE(e.find("25000"), std::string::npos) << e;
  EXPECT_NE(e.find("(0, 20000]"), std::string::npos) << e;
  c.rate_hz = 0.0;
  EXPECT_NE(validation_error(c).find("rate_hz = 0"), std::string::npos);
  c.rate_hz = -1.0;
  EXPECT_FALSE(validation_error(c).empty());
  c.rate_hz = 20000.0;
  EXPECT_TRUE(validation_error(c).empty()) << "20 kHz is inside the range";

  c = RtConfig{};
  c.priority = 100;
  e = validation_error(c);
  EXPECT_NE(e.find("priority = 100"), std::string::npos) << e;
  EXPECT_NE(e.find("1..99"), std::string::npos) << e;
  c.priority = -3;
  EXPECT_NE(validation_error(c).find("priority = -3"), std::string::npos);

  c = RtConfig{};
  const long n = sysconf(_SC_NPROCESSORS_ONLN);
  c.cpu = static_cast<int>(n);
  e = validation_error(c);
  EXPECT_NE(e.find("cpu = " + std::to_string(n)), std::string::npos) << e;
  EXPECT_NE(e.find(std::to_string(n) + " online CPUs"), std::string::npos) << e;
  c.cpu = static_cast<int>(n) - 1;
  EXPECT_TRUE(validation_error(c).empty());
  c.cpu = -2;
  EXPECT_FALSE(validation_error(c).empty());
  // The values alone (a configuration read on another machine than the robot's): any CPU index.
  using pedalwave::runtime::ValidateScope;
  c.cpu = static_cast<int>(n);
  EXPECT_NO_THROW(pedalwave::runtime::validate(c, ValidateScope::kValues));
  EXPECT_NE(pedalwave::runtime::cpu_problem(c.cpu), "");
  EXPECT_EQ(pedalwave::runtime::cpu_problem(-1), "");
  EXPECT_EQ(pedalwave::runtime::cpu_problem(0), "");
  c.cpu = pedalwave::runtime::kMaxCpu + 1;
  EXPECT_THROW(pedalwave::runtime::validate(c, ValidateScope::kValues), std::invalid_argument);

  c = RtConfig{};
  c.prefault_stack_bytes = pedalwave::runtime::kMaxPrefaultStack + 1;
  EXPECT_NE(validation_error(c).find("prefault_stack_bytes"), std::string::npos);
  EXPECT_THROW(apply_rt(c), std::invalid_argument) << "apply_rt validates first";
}

TEST(RtSetup, NothingRequestedIsAllGranted) {
  RtConfig c;
  c.prefault_stack_bytes = 64 * 1024;
  const RtReport r = apply_rt(c);
  EXPECT_TRUE(r.all_granted());
  EXPECT_TRUE(r.warnings.empty());
  EXPECT_EQ(r.stack_prefaulted, 64u * 1024u);
  EXPECT_NE(r.describe().find("SCHED_OTHER"), std::string::npos);
}

// Exit codes of the child in RefusedPrivilegesWarnOrThrow.
enum ChildCode : int {
  kChildOk = 0,
  kChildNotRefused = 10,
  kChildReportWrong = 11,
  kChildWarningText = 12,
  kChildNoThrow = 13,
  kChildThrowText = 14,
  kChildCannotDrop = 77,
};

bool contains(const std::string& s, const char* what) { return s.find(what) != std::string::npos; }

int refused_child() {
  // Drop what could grant SCHED_FIFO and mlock: limits to 0, then leave root (clears all caps).
  rlimit zero{0, 0};
  if (setrlimit(RLIMIT_RTPRIO, &zero) != 0 || setrlimit(RLIMIT_MEMLOCK, &zero) != 0) return kChildCannotDrop;
  if (geteuid() == 0 && (setgid(65534) != 0 || setuid(65534) != 0)) return kChildCannotDrop;
  sched_param sp{};
  sp.sched_priority = 1;
  if (pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0) return kChildCannotDrop;

  RtConfig c;
  c.priority = 80;
  c.lock_memory = kMlockObservable;
  RtReport r = apply_rt(c);
  if (r.all_granted() || r.priority_granted || r.memory_locked) return kChildNotRefused;
  const std::size_t want = kMlockObservable ? 2 : 1;
  if (!r.priority_requested || r.lock_requested != kMlockObservable || r.warnings.size() != want)
    return kChildReportWrong;
  std::string all;
  for (const auto& w : r.warnings) all += w + "\n";
  std::vector<const char*> needs = {"SCHED_FIFO", "EPERM", "rtprio", "CAP_SYS_NICE", "LimitRTPRIO",
                                    "RLIMIT_RTPRIO now soft 0"};
  if (kMlockObservable) needs.insert(needs.end(), {"mlockall", "memlock", "LimitMEMLOCK"});
  for (const char* need : needs) {
    if (!contains(all, need)) {
      std::fprintf(stderr, "warning lacks '%s':\n%s\n", need, all.c_str());
      return kChildWarningText;
    }
  }
  c.require_rt = true;
  try {
    apply_rt(c);
    return kChildNoThrow;
  } catch (const std::runtime_error& e) {
    const std::string w = e.what();
    if (!contains(w, "require_rt") || !contains(w, "CAP_SYS_NICE") ||
        (kMlockObservable && !contains(w, "memlock"))) {
      std::fprintf(stderr, "exception text: %s\n", w.c_str());
      return kChildThrowText;
    }
  }
  return kChildOk;
}

TEST(RtSetup, RefusedPrivilegesWarnOrThrowWithHowToGrant) {
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) _exit(refused_child());
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status)) << "child crashed";
  const int code = WEXITSTATUS(status);
  if (code == kChildCannotDrop) {
    GTEST_SKIP() << "*** SKIPPED: could not drop RT privileges in a child process (setuid/rlimit "
                    "refused or SCHED_FIFO still granted), so the refusal path cannot be exercised here";
  }
  EXPECT_EQ(code, kChildOk) << "10 not refused, 11 report wrong, 12 warning text, 13 no throw, 14 throw text";
}

bool fifo_permitted() {
  bool ok = false;
  std::thread t([&] {
    sched_param sp{};
    sp.sched_priority = 1;
    ok = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0;
  });
  t.join();
  return ok;
}

TEST(RtSetup, GrantedPriorityAndAffinityAreInForce) {
  if (!fifo_permitted()) {
    GTEST_SKIP() << "*** SKIPPED: this machine refuses SCHED_FIFO to the test (no CAP_SYS_NICE, "
                    "RLIMIT_RTPRIO 0); the granted path is not exercised";
  }
  RtReport r;
  int policy = -1, prio = -1, cpu_after = -1;
  bool pinned_only = false;
  std::thread t([&] {  // a throwaway thread, so the test runner itself stays SCHED_OTHER
    RtConfig c;
    c.priority = 10;
    c.cpu = 0;
    c.require_rt = true;
    r = apply_rt(c);
    sched_param sp{};
    pthread_getschedparam(pthread_self(), &policy, &sp);
    prio = sp.sched_priority;
    cpu_set_t set;
    CPU_ZERO(&set);
    pthread_getaffinity_np(pthread_self(), sizeof set, &set);
    pinned_only = CPU_COUNT(&set) == 1 && CPU_ISSET(0, &set);
    cpu_after = sched_getcpu();
  });
  t.join();
  EXPECT_TRUE(r.all_granted());
  EXPECT_TRUE(r.warnings.empty());
  EXPECT_EQ(policy, SCHED_FIFO);
  EXPECT_EQ(prio, 10);
  EXPECT_EQ(r.priority, 10);
  EXPECT_TRUE(pinned_only);
  EXPECT_EQ(cpu_after, 0);
  EXPECT_EQ(r.cpu, 0);
}

TEST(RtSetup, LockMemoryGrantedLocksPages) {
  if (!kMlockObservable) {
    GTEST_SKIP() << "*** SKIPPED: sanitizer build — mlockall() is a no-op under ASan/TSan";
  }
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    RtConfig c;
    c.lock_memory = true;
    const RtReport r = apply_rt(c);
    if (!r.memory_locked) _exit(77);
    std::ifstream st("/proc/self/status");
    std::string line;
    long locked_kb = 0;
    while (std::getline(st, line))
      if (line.rfind("VmLck:", 0) == 0) locked_kb = std::stol(line.substr(6));
    _exit(locked_kb > 0 ? 0 : 1);
  }
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  if (WEXITSTATUS(status) == 77) {
    GTEST_SKIP() << "*** SKIPPED: mlockall refused on this machine (RLIMIT_MEMLOCK / CAP_IPC_LOCK)";
  }
  EXPECT_EQ(WEXITSTATUS(status), 0) << "mlockall reported success but VmLck is 0";
}

}  // namespace
