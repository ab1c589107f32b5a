// "Nothing allocates, nothing locks" on the real-time thread, measured, not hoped for.
//
// Allocations: tests/support/alloc_counter counts every malloc/operator new per thread.
// Locks: this executable interposes pthread_mutex_lock/trylock, pthread_rwlock_rdlock/wrlock,
// pthread_spin_lock, pthread_cond_wait/timedwait and sem_wait/timedwait (the definitions below
// win over libc's for every caller in the process: std::mutex, spdlog, the runtime library) and
// counts them per thread before forwarding to the real ones. The positive controls show that a
// std::mutex and a `new` are seen, so a zero is a real zero. The design side of the argument:
// the cycle touches only SpscRing (lock-free atomics, static_assert'ed is_always_lock_free),
// the stop flags (lock-free atomics) and clock_nanosleep/clock_gettime.
//
// Probe window: from call 500 of the controller (after warm-up) to the safe stop at the end, on
// the loop's own thread; it spans every stage (read, observe, control, write, publish, sleep),
// events (warning verdict, operator commands), an overrun and the safe-stop path.
#include <gtest/gtest.h>

#include <dlfcn.h>
#include <pthread.h>
#include <semaphore.h>

#include <memory>
#include <mutex>
#include <thread>

#include "alloc_counter.hpp"
#include "fakes.hpp"
#include "pedalwave/runtime/consumer.hpp"

namespace {
thread_local std::uint64_t g_locks = 0;  // static TLS: no allocation to reach it

template <typename F>
F real(const char* name) {
  return reinterpret_cast<F>(dlsym(RTLD_NEXT, name));
}
using MutexFn = int (*)(pthread_mutex_t*);
using RwFn = int (*)(pthread_rwlock_t*);
using SpinFn = int (*)(pthread_spinlock_t*);
using CondFn = int (*)(pthread_cond_t*, pthread_mutex_t*);
using CondTFn = int (*)(pthread_cond_t*, pthread_mutex_t*, const timespec*);
using SemFn = int (*)(sem_t*);
using SemTFn = int (*)(sem_t*, const timespec*);
MutexFn real_mutex_lock, real_mutex_trylock;
RwFn real_rd, real_wr;
SpinFn real_spin;
CondFn real_cond_wait;
CondTFn real_cond_timedwait;
SemFn real_sem_wait;
SemTFn real_sem_timedwait;

// Resolved before main (and before any thread exists), so the wrappers never race on it.
__attribute__((constructor)) void resolve_real_locks() {
  real_mutex_lock = real<MutexFn>("pthread_mutex_lock");
  real_mutex_trylock = real<MutexFn>("pthread_mutex_trylock");
  real_rd = real<RwFn>("pthread_rwlock_rdlock");
  real_wr = real<RwFn>("pthread_rwlock_wrlock");
  real_spin = real<SpinFn>("pthread_spin_lock");
  real_cond_wait = real<CondFn>("pthread_cond_wait");
  real_cond_timedwait = real<CondTFn>("pthread_cond_timedwait");
  real_sem_wait = real<SemFn>("sem_wait");
  real_sem_timedwait = real<SemTFn>("sem_timedwait");
}

std::uint64_t thread_locks() { return g_locks; }
}  // namespace

extern "C" {
int pthread_mutex_lock(pthread_mutex_t* m) {
  ++g_locks;
  return real_mutex_lock(m);
}
int pthread_mutex_trylock(pthread_mutex_t* m) {
  ++g_locks;
  return real_mutex_trylock(m);
}
int pthread_rwlock_rdlock(pthread_rwlock_t* l) {
  ++g_locks;
  return real_rd(l);
}
int pthread_rwlock_wrlock(pthread_rwlock_t* l) {
  ++g_locks;
  return real_wr(l);
}
int pthread_spin_lock(pthread_spinlock_t* l) {
  ++g_locks;
  return real_spin(l);
}
int pthread_cond_wait(pthread_cond_t* c, pthread_mutex_t* m) {
  ++g_locks;
  return real_cond_wait(c, m);
}
int pthread_cond_timedwait(pthread_cond_t* c, pthread_mutex_t* m, const timespec* t) {
  ++g_locks;
  return real_cond_timedwait(c, m, t);
}
int sem_wait(sem_t* s) {
  ++g_locks;
  return real_sem_wait(s);
}
int sem_timedwait(sem_t* s, const timespec* t) {
  ++g_locks;
  return real_sem_timedwait(s, t);
}
}

namespace {

using namespace pedalwave::test;
namespace prt = pedalwave::runtime;

TEST(NoAllocNoLock, PositiveControlsAreCounted) {
  ASSERT_NE(real_mutex_lock, nullptr);
  std::mutex m;
  const std::uint64_t l0 = thread_locks();
  {
    std::lock_guard<std::mutex> g(m);
  }
  EXPECT_GE(thread_locks() - l0, 1u) << "std::mutex must be seen by the interposer";
  AllocationScope scope;
  auto p = std::make_unique<int>(3);
  EXPECT_GE(scope.count(), 1u);
  EXPECT_EQ(*p, 3);
}

struct Exercise {
  std::uint64_t allocs = 0, locks = 0, samples = 0, cycles = 0, overruns = 0;
  prt::ExitReason reason = prt::ExitReason::kNone;
  bool last_safe = false;
  bool calibrated = false;
};

// Runs the real cycle with fakes that themselves neither allocate nor lock, a consumer thread
// draining the rings, a warning verdict, operator commands and (lockstep) an overrun.
// calibrate: CALIBRATING first (0.5 s at rest, then READY and the walk), the probe from the
// driver's write 100 on, inside CALIBRATING.
Exercise exercise(prt::ClockMode mode, std::uint64_t cycles, bool calibrate = false) {
  prt::RuntimeConfig cfg = lockstep_config(cycles);
  cfg.clock = mode;
  if (calibrate) cfg.calibration.duration = 0.5;
  auto driver = std::make_unique<FakeDriver>(12);
  if (calibrate) {
    driver->rest_until = 1000;
    driver->ripple = 1e-4;
    driver->deflection_offset.fill(0.01);
    driver->probe_from_write = 100;
  }
  auto controller = std::make_unique<FakeController>();
  auto observer = std::make_unique<FakeObserver>();
  observer->from = 1000;
  observer->span = 200;
  observer->verdict = {prt::FaultClass::kEncoderNoise, prt::Severity::kWarning, 3, 0.4, 0.2, 0, "noise"};
  auto runtime = std::make_unique<prt::Runtime>(cfg, *driver, *controller, observer.get());
  Probe probe;
  probe.lock_counter = &thread_locks;
  controller->runtime = runtime.get();
  controller->probe = &probe;
  controller->probe_from = 500;
  driver->probe = &probe;
  controller->advance_at = 1500;  // lockstep only: one overrun of 2.5 periods
  controller->advance_ns = 2'500'000;
  controller->post_at = 1600;     // a set-gait command through the mailbox (accepted → event)
  controller->post_cmd.kind = prt::OperatorCommandKind::kSetGait;
  controller->post_cmd.amplitude = 0.3;

  prt::ConsumerConfig ccfg;
  ccfg.log_events = false;
  prt::TelemetryConsumer consumer(*runtime, {}, ccfg);
  consumer.start();
  Exercise out;
  prt::RunResult r;
  std::thread loop([&] { r = runtime->run(); });  // the loop on its own thread, like the daemon
  loop.join();
  consumer.stop();
  out.allocs = probe.allocs;
  out.locks = probe.locks;
  out.samples = probe.samples;
  out.cycles = r.cycles;
  out.overruns = r.overruns;
  out.reason = r.reason;
  out.last_safe = driver->last_call == Call::kSafeStop;
  out.calibrated = r.calibrated;
  return out;
}

TEST(NoAllocNoLock, LockstepCycleAfterWarmUp) {
  const Exercise e = exercise(prt::ClockMode::kLockstep, 5000);
  EXPECT_EQ(e.cycles, 5000u);
  EXPECT_EQ(e.reason, prt::ExitReason::kCycleLimit);
  EXPECT_TRUE(e.last_safe);
  EXPECT_GT(e.samples, 4000u) << "the probe really covered the run";
  EXPECT_EQ(e.overruns, 1u) << "the overrun path was exercised";
  EXPECT_EQ(e.allocs, 0u) << "allocations on the real-time thread after warm-up";
  EXPECT_EQ(e.locks, 0u) << "lock acquisitions on the real-time thread after warm-up";
}

TEST(NoAllocNoLock, CalibratingThenWalking) {
  const Exercise e = exercise(prt::ClockMode::kLockstep, 3000, true);
  EXPECT_EQ(e.cycles, 3000u);
  EXPECT_EQ(e.reason, prt::ExitReason::kCycleLimit);
  EXPECT_TRUE(e.last_safe);
  EXPECT_TRUE(e.calibrated);
  EXPECT_GT(e.samples, 2800u) << "the probe covered CALIBRATING, READY and the walk";
  EXPECT_EQ(e.allocs, 0u) << "allocations on the real-time thread";
  EXPECT_EQ(e.locks, 0u) << "lock acquisitions on the real-time thread";
}

TEST(NoAllocNoLock, RealtimeCycleAfterWarmUp) {
  const Exercise e = exercise(prt::ClockMode::kRealtime, 2500);
  EXPECT_EQ(e.cycles, 2500u);
  EXPECT_TRUE(e.last_safe);
  EXPECT_GT(e.samples, 1500u);
  EXPECT_EQ(e.allocs, 0u) << "allocations on the real-time thread after warm-up";
  EXPECT_EQ(e.locks, 0u) << "lock acquisitions on the real-time thread after warm-up";
}

}  // namespace
