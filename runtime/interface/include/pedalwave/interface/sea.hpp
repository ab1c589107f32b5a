// The series elastic actuator's relations and the module's PD law, in one place for every layer
// (model-spec.md's notation; the model's plant, the runtime, the controller, the observer and the
// drivers that run the PD on the host all call these).
//
//   deflection δ_j = β_j − α_j            (β motor angle after the gear, α link joint angle)
//   spring torque τ_s,j = K_j (β_j − α_j) = K_j δ_j, acting on the link; the paper's generalized
//   force on the link coordinates is Q_e,j = −τ_s,j = K_j (α_j − β_j) (the admittance's input).
//   module law (P-33 with a feed-forward): u_j = τ_j + k_p,j (β_ref,j − β_j) + k_d,j (β̇_ref,j − β̇_j)
#pragma once

namespace pedalwave {

constexpr double link_angle(double beta, double deflection) noexcept { return beta - deflection; }
constexpr double spring_torque(double K, double deflection) noexcept { return K * deflection; }
constexpr double generalized_spring_force(double K, double deflection) noexcept {
  return -spring_torque(K, deflection);
}

constexpr double module_law(double tau, double kp, double beta_ref, double kd, double beta_dot_ref,
                            double beta, double beta_dot) noexcept {
  return tau + kp * (beta_ref - beta) + kd * (beta_dot_ref - beta_dot);
}

}  // namespace pedalwave
