// The rules of a plant stepped by a control loop, written once for every tool that runs one
// (pedalwave_sim, the daemon's simulated plant `driver: sim`, …):
//   - step_problem: the plant advances one control period per cycle (the driver's write), so a
//     fixed integrator step longer than the period is never taken — refused as bad input;
//   - stability_advice: after a run that went numerically wrong, the scene's stability limit of
//     the integrator and a step that would work (model/stability).
#pragma once

#include <string>
#include <string_view>

#include "pedalwave/model/integrators.hpp"
#include "pedalwave/model/scene.hpp"
#include "pedalwave/model/stability.hpp"

namespace pedalwave::simloop {

// "" when `integ` fits a control period of 1/rate_hz (an adaptive method's h is only its first
// step: always fits); else "expected a step ≤ the control period <period_name> = 0.001 s" — the
// caller names the step first ("--h 0.005: …", "<scene>: integrator.h = 0.05: …").
std::string step_problem(const model::IntegratorOptions& integ, double rate_hz,
                         std::string_view period_name = "1/rate");

// One line: the stability limit of `integ` on `scene` under module-side PD gains `gains`
// (K_p = K_D = 0: a passive robot, or a host-side PD whose torque the plant sees held) over
// `duration` [s], and the step to use (model::stability_message), e.g. "h = 0.01 s is above
// explicit Euler's stability limit … : use h ≤ 4e-4 s, or implicit_velocity". When no prediction
// can be made: "no stability prediction: <why>". Never throws.
std::string stability_advice(const model::Scene& scene, const model::ControlGains& gains,
                             const model::IntegratorOptions& integ, double duration) noexcept;

}  // namespace pedalwave::simloop
