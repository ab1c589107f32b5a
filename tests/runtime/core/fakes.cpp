#include "fakes.hpp"

#include <csignal>

#include "alloc_counter.hpp"

namespace pedalwave::test {

void Probe::start() {
  alloc0 = thread_allocations();
  lock0 = lock_counter ? lock_counter() : 0;
  started = true;
}

void Probe::sample() {
  if (!started) return;
  ++samples;
  allocs = thread_allocations() - alloc0;
  locks = lock_counter ? lock_counter() - lock0 : 0;
}

void FakeController::maybe_act(std::uint64_t k) {
  if (probe) {
    if (k == probe_from) probe->start();
    probe->sample();
  }
  if (runtime) {
    if (k == advance_at || k >= advance_every_from) runtime->lockstep_advance(advance_ns);
    if (k == stop_at) runtime->request_stop();
    if (k == post_at) runtime->post(post_cmd);
  }
  if (k == raise_at) std::raise(SIGTERM);
}

}  // namespace pedalwave::test
