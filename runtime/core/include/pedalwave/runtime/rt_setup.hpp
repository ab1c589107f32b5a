// Real-time setup of the calling thread and process: scheduling policy and priority, CPU
// affinity, memory locking, stack prefaulting. Called once before the loop starts (it may
// allocate, log into its report and throw); never from inside the cycle.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

namespace pedalwave::runtime {

struct RtConfig {
  double rate_hz = 1000.0;                // loop rate [Hz], in (0, 20000]
  int priority = 0;                       // SCHED_FIFO priority 1..99; 0 = keep SCHED_OTHER [-]
  int cpu = -1;                           // pin the loop thread to this CPU; -1 = no pinning [-]
  bool lock_memory = false;               // mlockall(MCL_CURRENT | MCL_FUTURE)
  std::size_t prefault_stack_bytes = 0;   // touch this much stack up front [B], ≤ kMaxPrefaultStack
  bool require_rt = false;                // a refused privilege throws instead of warning
};

inline constexpr double kMaxRateHz = 20000.0;                   // [Hz]
inline constexpr std::size_t kMaxPrefaultStack = 4u << 20;      // 4 MiB [B]
inline constexpr int kMaxCpu = 1023;                            // CPU_SETSIZE - 1 [-]

// What validate() checks: the values alone (kValues: a configuration read on a machine that need
// not be the robot's, e.g. pedalwave_runtime --check-config on a packaging machine), or also this
// machine (kThisMachine: the CPU to pin to is online here; apply_rt, Runtime).
enum class ValidateScope { kValues, kThisMachine };

// Throws std::invalid_argument naming the item, the value and the expected range:
//   rate_hz ∈ (0, 20000], priority ∈ [0, 99], cpu ∈ [-1, kMaxCpu] and (kThisMachine) one of this
//   machine's online CPUs (cpu_problem), prefault_stack_bytes ≤ 4 MiB.
void validate(const RtConfig& cfg, ValidateScope scope = ValidateScope::kThisMachine);

// This machine's online CPUs (sysconf(_SC_NPROCESSORS_ONLN); 0 when unknown).
int online_cpus();
// Why the loop cannot be pinned to `cpu` on this machine, as the "expected …" of a message
// ("" = it can, or cpu = -1, or the CPU count is unknown):
//   "-1 (no pinning) or a CPU of this machine, 0 … 1 (it has 2 online CPUs)".
std::string cpu_problem(int cpu);

// What apply_rt() asked for and what the kernel granted.
struct RtReport {
  bool priority_requested = false;  // cfg.priority > 0
  bool priority_granted = false;    // SCHED_FIFO at cfg.priority is in force on this thread
  int priority = 0;                 // priority in force after the call [-]
  bool affinity_requested = false;  // cfg.cpu >= 0
  bool affinity_granted = false;    // thread pinned to cfg.cpu
  int cpu = -1;                     // CPU pinned to, -1 none [-]
  bool lock_requested = false;      // cfg.lock_memory
  bool memory_locked = false;       // mlockall succeeded
  std::size_t stack_prefaulted = 0; // bytes of stack touched [B]
  std::vector<std::string> warnings;  // one line per refused request: what, errno, how to grant

  // True when everything requested was granted.
  bool all_granted() const noexcept;
  // One line per item, e.g. "SCHED_FIFO 80: granted; affinity: none; mlockall: refused".
  std::string describe() const;
};

// Validates cfg, then applies it to the CALLING thread (priority, affinity) and the process
// (mlockall), and prefaults the calling thread's stack. A refused request adds a warning that
// names what failed, the errno and how to grant it (RLIMIT_RTPRIO / RLIMIT_MEMLOCK limits,
// CAP_SYS_NICE / CAP_IPC_LOCK, systemd LimitRTPRIO= / LimitMEMLOCK=). With cfg.require_rt the
// first refusal throws std::runtime_error carrying the same text instead.
RtReport apply_rt(const RtConfig& cfg);

}  // namespace pedalwave::runtime
