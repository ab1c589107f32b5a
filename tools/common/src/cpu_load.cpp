#include "pedalwave/toolkit/cpu_load.hpp"

#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <cerrno>
#include <cstdint>
#include <fstream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <system_error>

#include "pedalwave/interface/clock.hpp"

namespace pedalwave::toolkit {

namespace {

constexpr std::int64_t kPeriodNs = 10'000'000;  // duty-cycle period [ns]
volatile double g_sink = 0.0;  // the arithmetic's result, so the compiler keeps it

// The child's whole life: async-signal-safe calls only (it was forked, maybe from a threaded
// process). SIGINT/SIGTERM back to their default action (end the child), not the parent's
// handlers; busy on arithmetic the compiler cannot drop, then asleep the rest of the period.
[[noreturn]] void spin(std::int64_t busy_ns, pid_t parent) {
  if (::prctl(PR_SET_PDEATHSIG, SIGKILL) != 0 || ::getppid() != parent) ::_exit(0);
  struct sigaction dfl {};
  dfl.sa_handler = SIG_DFL;
  ::sigaction(SIGINT, &dfl, nullptr);
  ::sigaction(SIGTERM, &dfl, nullptr);
  double x = 1.0;
  for (;;) {
    const std::int64_t t0 = pedalwave::monotonic_ns();
    while (pedalwave::monotonic_ns() - t0 < busy_ns) {
      for (int k = 0; k < 1000; ++k) x = x * 1.0000001 + 1e-9;
      if (x > 1e300) x = 1.0;
      g_sink = x;
    }
    const std::int64_t rest = kPeriodNs - busy_ns;
    if (rest > 0) {
      timespec ts{0, static_cast<long>(rest)};
      ::nanosleep(&ts, nullptr);
    }
  }
}

// utime + stime of a running process [s], 0 if it cannot be read.
double proc_cpu_seconds(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string text;
  if (!std::getline(in, text)) return 0.0;
  // Fields after the command name (which is in parentheses and may contain spaces).
  const auto close = text.rfind(')');
  if (close == std::string::npos) return 0.0;
  std::istringstream fields(text.substr(close + 2));
  std::string f;
  unsigned long long utime = 0, stime = 0;
  for (int k = 3; k <= 15 && (fields >> f); ++k) {
    if (k == 14) utime = std::stoull(f);
    if (k == 15) stime = std::stoull(f);
  }
  return static_cast<double>(utime + stime) / static_cast<double>(::sysconf(_SC_CLK_TCK));
}

}  // namespace

void CpuLoad::start(int children, double duty) {
  if (children < 0) throw std::invalid_argument("CpuLoad: children = " + std::to_string(children) + ", expected ≥ 0");
  if (!(duty > 0.0 && duty <= 1.0))
    throw std::invalid_argument("CpuLoad: duty = " + std::to_string(duty) + ", expected a fraction in (0, 1]");
  duty_ = duty;
  const auto busy_ns = static_cast<std::int64_t>(duty * static_cast<double>(kPeriodNs));
  const pid_t parent = ::getpid();
  for (int k = 0; k < children; ++k) {
    const pid_t pid = ::fork();
    if (pid < 0) {
      const int err = errno;
      stop();
      throw std::system_error(err, std::generic_category(), "CpuLoad: fork");
    }
    if (pid == 0) spin(busy_ns, parent);
    pids_.push_back(pid);
  }
}

void CpuLoad::stop() {
  for (const pid_t pid : pids_) ::kill(pid, SIGKILL);
  for (const pid_t pid : pids_) {
    int status = 0;
    rusage ru{};
    while (::wait4(pid, &status, 0, &ru) < 0 && errno == EINTR) {
    }
    reaped_cpu_s_ += static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
                     1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
  }
  pids_.clear();
}

double CpuLoad::cpu_seconds() const {
  double s = reaped_cpu_s_;
  for (const pid_t pid : pids_) s += proc_cpu_seconds(pid);
  return s;
}

bool process_alive(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string text;
  if (!std::getline(in, text)) return false;
  const auto close = text.rfind(')');
  return close != std::string::npos && close + 2 < text.size() && text[close + 2] != 'Z' &&
         text[close + 2] != 'X';
}

}  // namespace pedalwave::toolkit
