#include "gait_stage.hpp"

namespace pedalwave::app {

GaitStage::GaitStage(const control::GaitControllerParams& p) : ctl_(p), state_(ctl_.make_state()) {}

void GaitStage::start(const drivers::Feedback&) { ctl_.reset(state_, 0.0); }

void GaitStage::run(const runtime::CycleIo& io) {
  const double dt = io.dt > 0 ? io.dt : ctl_.params().period;
  ctl_.update(io.t, dt, control::measurement_from(io.fb), state_, out_);
  ctl_.fill_command(out_, io.cmd);
  const int J = ctl_.joints();
  for (int j = 0; j < J; ++j) {
    const auto k = static_cast<std::size_t>(j);
    io.sample.alpha_d[k] = out_.alpha_d[k];
    io.sample.eta[k] = out_.eta[k];
    io.sample.u[k] = out_.u[k];
  }
}

void GaitStage::control(const runtime::CycleIo& io) { run(io); }

void GaitStage::hold(const runtime::CycleIo& io) {
  ctl_.freeze(state_);
  run(io);
}

void GaitStage::resume(const drivers::Feedback&) { ctl_.resume(state_); }

// Gait changes at run time would need a new controller (parameters are const once built, and
// nothing in the cycle may allocate): refused, and the refusal is published by the runtime.
bool GaitStage::set_gait(const runtime::OperatorCommand&) { return false; }

}  // namespace pedalwave::app
