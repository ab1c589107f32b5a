// The runtime's Controller stage backed by the control layer's GaitController (gait + adaptive
// admittance + PD, limits last). Allocation-free per cycle; state sized at construction.
#pragma once

#include "pedalwave/control/gait_controller.hpp"
#include "pedalwave/interface/stages.hpp"

namespace pedalwave::app {

class GaitStage final : public runtime::Controller {
 public:
  explicit GaitStage(const control::GaitControllerParams& p);

  void start(const drivers::Feedback& fb) override;
  void control(const runtime::CycleIo& io) override;
  void hold(const runtime::CycleIo& io) override;
  void resume(const drivers::Feedback& fb) override;
  bool set_gait(const runtime::OperatorCommand& cmd) override;

  const control::ControlOutput& last() const { return out_; }
  const control::GaitController& controller() const { return ctl_; }

 private:
  void run(const runtime::CycleIo& io);
  control::GaitController ctl_;
  control::GaitControllerState state_;
  control::ControlOutput out_{};
};

}  // namespace pedalwave::app
