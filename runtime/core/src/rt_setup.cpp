#include "pedalwave/runtime/rt_setup.hpp"

#include <alloca.h>
#include <pthread.h>
#include <sched.h>
#include <sys/mman.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>
#include <sstream>
#include <stdexcept>

namespace pedalwave::runtime {
namespace {

std::string errno_text(int err) {
  std::ostringstream os;
  os << strerrorname_np(err) << " (" << std::strerror(err) << ")";
  return os.str();
}

std::string limit_text(int resource) {
  rlimit lim{};
  if (getrlimit(resource, &lim) != 0) return "unknown";
  auto one = [](rlim_t v) { return v == RLIM_INFINITY ? std::string("unlimited") : std::to_string(v); };
  return "soft " + one(lim.rlim_cur) + ", hard " + one(lim.rlim_max);
}

// Touches `bytes` of stack below the current frame so that later deep calls in the cycle do not
// page-fault. noinline so the alloca'd area really is a fresh frame.
__attribute__((noinline)) void prefault_stack(std::size_t bytes) {
  auto* p = static_cast<volatile unsigned char*>(alloca(bytes));
  const long page = sysconf(_SC_PAGESIZE) > 0 ? sysconf(_SC_PAGESIZE) : 4096;
  for (std::size_t i = 0; i < bytes; i += static_cast<std::size_t>(page)) p[i] = 0;
  if (bytes > 0) p[bytes - 1] = 0;
}

}  // namespace

int online_cpus() {
  const long n = sysconf(_SC_NPROCESSORS_ONLN);
  return n > 0 ? static_cast<int>(n) : 0;
}

std::string cpu_problem(int cpu) {
  const int n = online_cpus();
  if (cpu < 0 || n == 0 || cpu < n) return "";
  return "-1 (no pinning) or a CPU of this machine, 0 … " + std::to_string(n - 1) + " (it has " +
         std::to_string(n) + " online CPUs)";
}

void validate(const RtConfig& cfg, ValidateScope scope) {
  auto fail = [](const std::string& item, const std::string& value, const std::string& expected) {
    throw std::invalid_argument("rt config: " + item + " = " + value + ", expected " + expected);
  };
  if (!std::isfinite(cfg.rate_hz) || cfg.rate_hz <= 0.0 || cfg.rate_hz > kMaxRateHz) {
    std::ostringstream v;
    v << cfg.rate_hz;
    fail("rate_hz", v.str(), "a rate in (0, 20000] Hz");
  }
  if (cfg.priority < 0 || cfg.priority > 99) {
    fail("priority", std::to_string(cfg.priority), "0 (no SCHED_FIFO) or a SCHED_FIFO priority 1..99");
  }
  if (cfg.cpu < -1 || cfg.cpu > kMaxCpu)
    fail("cpu", std::to_string(cfg.cpu), "-1 (no pinning) or a CPU index 0.." + std::to_string(kMaxCpu));
  if (scope == ValidateScope::kThisMachine)
    if (const std::string why = cpu_problem(cfg.cpu); !why.empty()) fail("cpu", std::to_string(cfg.cpu), why);
  if (cfg.prefault_stack_bytes > kMaxPrefaultStack) {
    fail("prefault_stack_bytes", std::to_string(cfg.prefault_stack_bytes),
         "at most " + std::to_string(kMaxPrefaultStack) + " bytes (4 MiB)");
  }
}

bool RtReport::all_granted() const noexcept {
  return (!priority_requested || priority_granted) && (!affinity_requested || affinity_granted) &&
         (!lock_requested || memory_locked);
}

std::string RtReport::describe() const {
  std::ostringstream os;
  os << "scheduling: "
     << (priority_requested ? (priority_granted ? "SCHED_FIFO " + std::to_string(priority) + " granted"
                                                : std::string("SCHED_FIFO refused, running SCHED_OTHER"))
                            : std::string("SCHED_OTHER (not requested)"))
     << "; affinity: "
     << (affinity_requested ? (affinity_granted ? "CPU " + std::to_string(cpu) : std::string("refused"))
                            : std::string("none"))
     << "; mlockall: "
     << (lock_requested ? (memory_locked ? "locked" : "refused") : "not requested")
     << "; stack prefaulted: " << stack_prefaulted << " B";
  return os.str();
}

RtReport apply_rt(const RtConfig& cfg) {
  validate(cfg);
  RtReport rep;

  // 1. Memory first: locking after the stack is prefaulted would also be fine (MCL_CURRENT),
  //    but with MCL_FUTURE every later allocation and stack page is locked as it appears.
  rep.lock_requested = cfg.lock_memory;
  if (cfg.lock_memory) {
    if (mlockall(MCL_CURRENT | MCL_FUTURE) == 0) {
      rep.memory_locked = true;
    } else {
      const int err = errno;
      rep.warnings.push_back(
          "mlockall(MCL_CURRENT|MCL_FUTURE) failed: " + errno_text(err) +
          ". Pages of the loop may be swapped or faulted in during a cycle. Grant it: raise the "
          "memlock limit (RLIMIT_MEMLOCK now " + limit_text(RLIMIT_MEMLOCK) +
          "; /etc/security/limits.d/pedalwave.conf: '<user> - memlock unlimited', or systemd "
          "LimitMEMLOCK=infinity) or give the binary CAP_IPC_LOCK (setcap cap_ipc_lock+ep).");
    }
  }

  // 2. Scheduling class and priority of this thread.
  rep.priority_requested = cfg.priority > 0;
  if (cfg.priority > 0) {
    sched_param sp{};
    sp.sched_priority = cfg.priority;
    const int err = pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp);
    if (err == 0) {
      rep.priority_granted = true;
      rep.priority = cfg.priority;
    } else {
      rep.warnings.push_back(
          "pthread_setschedparam(SCHED_FIFO, " + std::to_string(cfg.priority) + ") failed: " +
          errno_text(err) + ". The loop runs SCHED_OTHER and its wake-up latency is not bounded. "
          "Grant it: raise the rtprio limit to >= " + std::to_string(cfg.priority) +
          " (RLIMIT_RTPRIO now " + limit_text(RLIMIT_RTPRIO) +
          "; /etc/security/limits.d/pedalwave.conf: '<user> - rtprio 99', or systemd "
          "LimitRTPRIO=99) or give the binary CAP_SYS_NICE (setcap cap_sys_nice+ep). In a "
          "container, also allow CAP_SYS_NICE and an RT runtime budget (cpu.rt_runtime_us).");
    }
  }

  // 3. CPU affinity of this thread.
  rep.affinity_requested = cfg.cpu >= 0;
  if (cfg.cpu >= 0) {
    cpu_set_t set;
    CPU_ZERO(&set);
    CPU_SET(static_cast<unsigned>(cfg.cpu), &set);
    const int err = pthread_setaffinity_np(pthread_self(), sizeof(set), &set);
    if (err == 0) {
      rep.affinity_granted = true;
      rep.cpu = cfg.cpu;
    } else {
      rep.warnings.push_back(
          "pthread_setaffinity_np(cpu " + std::to_string(cfg.cpu) + ") failed: " + errno_text(err) +
          ". The loop may migrate between CPUs. Check that the CPU is in this process's cpuset "
          "(taskset -p $$, systemd CPUAffinity=, cgroup cpuset.cpus).");
    }
  }

  // 4. Stack: touch it now so that the cycle never takes a first-touch page fault.
  if (cfg.prefault_stack_bytes > 0) {
    prefault_stack(cfg.prefault_stack_bytes);
    rep.stack_prefaulted = cfg.prefault_stack_bytes;
  }

  if (cfg.require_rt && !rep.warnings.empty()) {
    std::string all = "real-time setup required (require_rt) but refused:";
    for (const auto& w : rep.warnings) all += "\n  - " + w;
    throw std::runtime_error(all);
  }
  return rep;
}

}  // namespace pedalwave::runtime
