#include "pedalwave/control/joint_pd.hpp"

namespace pedalwave::control {

void fill_command(PdPlacement placement, int joints, std::span<const double> K_p,
                  std::span<const double> K_D, std::span<const double> u,
                  std::span<const double> tau_ff, std::span<const double> alpha_d,
                  std::span<const double> alpha_d_dot, drivers::Command& cmd) noexcept {
  cmd.joints = joints;
  const bool host = placement == PdPlacement::kHost;
  for (int j = 0; j < joints; ++j) {
    const auto i = static_cast<std::size_t>(j);
    cmd.beta_ref[i] = alpha_d[i];
    cmd.beta_dot_ref[i] = alpha_d_dot[i];
    if (host) {
      cmd.tau[i] = u[i];  // pure torque command, held by the module until the next cycle
      cmd.kp[i] = 0.0;
      cmd.kd[i] = 0.0;
    } else {
      cmd.tau[i] = tau_ff[i];  // the module adds its own PD at its internal rate
      cmd.kp[i] = K_p[i];
      cmd.kd[i] = K_D[i];
    }
  }
}

}  // namespace pedalwave::control
