#include "pedalwave/control/gait.hpp"

#include "validate.hpp"

namespace pedalwave::control {

void validate(const GaitParams& p) {
  detail::require_non_negative("gait.A_p", p.A_p, "[rad]");
  detail::require_finite("gait.omega", p.omega, "[rad/s]");
}

}  // namespace pedalwave::control
