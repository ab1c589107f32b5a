#include "pedalwave/observer/runtime_observer.hpp"

namespace pedalwave::observer {

runtime::Verdict RuntimeObserver::observe(const drivers::Feedback& fb,
                                          const drivers::CommandHistory& cmds, double t, double dt,
                                          runtime::CycleSample& sample) {
  core_.observe(fb, cmds, t, dt);
  const int J = core_.joints();
  for (int j = 0; j < J; ++j) {
    const auto k = static_cast<std::size_t>(j);
    sample.residual[k] = core_.residual()[k];
    sample.tau_ext[k] = core_.tau_ext()[k];
  }
  sample.body = core_.body();
  sample.forward_speed = core_.forward_speed();
  runtime::Verdict v;
  v.flags = core_.flags();
  if (const FaultRecord* f = core_.primary()) {
    v.fault = f->fault;
    v.severity = f->severity;
    v.joint = f->joint;
    v.value = f->value;
    v.threshold = f->threshold;
    v.text = f->text;
  }
  return v;
}

}  // namespace pedalwave::observer
