// A CPU load generator: N child processes (fork) at the caller's scheduling policy and nice level,
// each spinning on floating-point arithmetic, optionally at a duty cycle (busy `duty` of every
// 10 ms, asleep the rest). For soak runs and for tests that run the bus or the loop under load.
//
//   CpuLoad load;
//   load.start(2, 1.0);    // two busy children
//   ... run the thing under test ...
//   load.stop();           // SIGKILL + wait4 of each child by its pid; load.cpu_seconds() > 0
//
// Children are never left behind: stop() kills and reaps every child it started (the destructor
// calls it), and each child asks the kernel for SIGKILL when the thread that started it exits
// (PR_SET_PDEATHSIG), so a parent killed with SIGKILL does not leave them spinning either. A child
// runs only async-signal-safe code after fork, so starting from a multi-threaded process is safe;
// its SIGINT and SIGTERM take their default action (a Ctrl-C ends it), not the parent's handlers.
// Not thread-safe itself; a process installs its own SIGINT/SIGTERM handling and calls stop().
#pragma once

#include <sys/types.h>

#include <vector>

namespace pedalwave::toolkit {

class CpuLoad {
 public:
  CpuLoad() = default;
  CpuLoad(const CpuLoad&) = delete;
  CpuLoad& operator=(const CpuLoad&) = delete;
  ~CpuLoad() { stop(); }

  // Starts `children` more children (0 = none) busy for `duty` ∈ (0, 1] of each 10 ms period.
  // Throws std::invalid_argument for a duty outside (0, 1] or children < 0, and
  // std::system_error when fork fails (the children already started are stopped first).
  void start(int children, double duty = 1.0);

  // Kills (SIGKILL) and reaps every child; adds their CPU time (user + system, from wait4) to
  // cpu_seconds(). Idempotent.
  void stop();

  // The children's process ids while running (empty after stop()).
  [[nodiscard]] const std::vector<pid_t>& pids() const { return pids_; }
  [[nodiscard]] bool running() const { return !pids_.empty(); }
  [[nodiscard]] double duty() const { return duty_; }

  // CPU time [s] the children consumed: reaped children's exact totals, plus for running ones
  // their utime + stime read from /proc/<pid>/stat.
  [[nodiscard]] double cpu_seconds() const;

 private:
  std::vector<pid_t> pids_;
  double duty_ = 1.0;
  double reaped_cpu_s_ = 0.0;  // CPU time of stopped children [s]
};

// Whether a process with this id exists and is not a zombie (reads /proc/<pid>/stat).
[[nodiscard]] bool process_alive(pid_t pid);

}  // namespace pedalwave::toolkit
