// The simulated robot: the dynamics of a Model plus exactly the effects its Scene switches on
// (model-spec.md §6, DESIGN.md "Simulation"). A System for the integrators:
//   effects (actuators, joint friction, ground, boxes)  →  dynamics  →  integrate.
// Sized once at construction; acceleration()/implicit_terms() allocate nothing.
#pragma once

#include <random>

#include "pedalwave/model/dynamics.hpp"
#include "pedalwave/model/integrators.hpp"
#include "pedalwave/model/scene.hpp"

namespace pedalwave::model {

// What the motor modules apply (the drivers::Command, in model terms), each (N-1):
//   u_j = tau_j + kp_j (beta_ref_j − β_j) + kd_j (beta_dot_ref_j − β̇_j), then limits.
struct ActuatorInput {
  VectorXd tau;           // feed-forward torque [N·m]
  VectorXd beta_ref;      // [rad]
  VectorXd beta_dot_ref;  // [rad/s]
  VectorXd kp;            // [N·m/rad]
  VectorXd kd;            // [N·m·s/rad]
  bool torque_off = false;
};

// What the sensors give (motor side only), each (N-1).
struct Measurement {
  VectorXd beta;        // motor output angle [rad]
  VectorXd beta_dot;    // [rad/s]
  VectorXd deflection;  // β − α [rad]
};

// Physical faults injected into the simulated actuators (fault-injection studies, the observer's
// proof). Sized (N-1) by the Plant; the defaults are the healthy robot and leave every result
// bit-identical. Applied in motor_torques() and as extra generalized forces in acceleration() and
// implicit_terms():
//   u_j = torque_gain_j · (module law, limited) − (b_m + motor_friction_j) β̇_j   (motor rows)
//   spring: extra −(spring_scale_j − 1) K_j (β_j − α_j) on the β_j row, + the same on the α_j row
//   joint_load: extra generalized force +joint_load_j on the α_j row (a link-side torque between
//               links j and j+1: a jam, a snag, a payload)
// Change them between plant steps only (the integrators assume a smooth right-hand side).
struct PlantFaults {
  VectorXd torque_gain;     // actuator output gain [-], (N-1); 1 = healthy, 0 = torque loss
  VectorXd motor_friction;  // extra viscous friction on the motor [N·m·s/rad], (N-1); 0 = healthy
  VectorXd spring_scale;    // SEA stiffness factor [-], (N-1); 1 = healthy, 0.2 = broken spring
  VectorXd joint_load;      // extra link-side torque on α_j [N·m], (N-1); 0 = healthy
  // Back to the healthy robot (keeps the sizes).
  void clear() {
    torque_gain.setOnes();
    motor_friction.setZero();
    spring_scale.setOnes();
    joint_load.setZero();
  }
};

// Contact state of one evaluation, for output and plots.
struct ContactReport {
  VectorXd f_normal;      // normal force per body point [N], (2N+1)
  VectorXd f_tangent;     // tangential force per body point [N], (2N+1)
  double max_penetration = 0.0;  // deepest penetration of any point/corner [m]
  int active = 0;               // contacts carrying force
  double elastic_energy = 0.0;  // Σ ½ k δ² over every contact's penetration δ [J]
};

class Plant final : public System {
 public:
  // Validates the scene (throws std::invalid_argument) and sizes everything.
  explicit Plant(const Scene& scene);

  const Model& model() const { return model_; }
  const Scene& scene() const { return scene_; }
  int nq() const override { return model_.nq(); }

  // The scene's initial state (q, v sized nq).
  void initial_state(VectorXd& q, VectorXd& v) const;

  ActuatorInput& input() { return input_; }
  const ActuatorInput& input() const { return input_; }
  // Injected physical faults (healthy by default; see PlantFaults).
  PlantFaults& faults() { return faults_; }
  const PlantFaults& faults() const { return faults_; }

  bool acceleration(double t, const VectorXd& q, const VectorXd& v, VectorXd& a) override;
  // ∂F/∂q and ∂F/∂v of the stiff terms (implicit_velocity, implicit_contact): SEA springs, module
  // PD and motor friction (zero slope where the torque limit saturates), and for each contact
  // carrying force at (q, v), with J_n = nᵀ J_p, J_t = tᵀ J_p the contact point's Jacobian rows
  // (analytic, point_jacobian), r = f_T / f_N:
  //   ∂F/∂q = −k (J_nᵀ J_n + r J_tᵀ J_n),  ∂F/∂v = −d (J_nᵀ J_n + r J_tᵀ J_n) + (∂f_T/∂v_t) J_tᵀ J_t.
  // Neglected (non-stiff, or second order in the penetration): ∂J_p/∂q · f (the contact force's
  // turn with the links — f ≤ the robot's weight against the stiffness k), the turn of a corner
  // contact's normal and the slide of its material point s, ∂M/∂q, the Coriolis and gravity
  // derivatives. implicit_contact's Newton corrections re-evaluate these Jacobians at the end of
  // the step, so the neglected terms only slow its convergence; they never change its solution.
  // With out.v_start (a Newton iterate), a regularized-friction contact sliding at (q, v) whose
  // tangential velocity at v_start was inside the stick band or of the other sign gets the band's
  // slope −μ f_N / v_s instead of 0 (ImplicitTerms::v_start).
  bool implicit_terms(double t, const VectorXd& q, const VectorXd& v, ImplicitTerms& out) override;

  // Motor torques u (N-1) the actuators apply at (q, v): input law, limits, fault gain, joint
  // friction (nominal + injected).
  void motor_torques(const VectorXd& q, const VectorXd& v, Eigen::Ref<VectorXd> u) const;
  // Generalized contact force at (q, v) (needs update_kinematics on data()).
  void contact_forces(const VectorXd& q, const VectorXd& v, Eigen::Ref<VectorXd> Q,
                      ImplicitTerms* jac, ContactReport* report);

  // After an accepted step: updates stick–slip anchors. Call once per plant step.
  void after_step(const VectorXd& q, const VectorXd& v);
  // Sensor model (noise and quantization when the scene switches them on).
  void measure(const VectorXd& q, const VectorXd& v, Measurement& out);
  // Contact forces per point and max penetration at (q, v).
  void report(const VectorXd& q, const VectorXd& v, ContactReport& out);
  // Total mechanical energy (kinetic + gravity + spring) [J].
  double energy(const VectorXd& q, const VectorXd& v);

  Data& data() { return data_; }

  // The forward-dynamics solver acceleration() uses (dynamics.hpp): the O(N) recursive one by
  // default; kDense is the reference (bit-identical to the plant before the recursive solver).
  // The two agree to rounding. Set between steps only.
  ForwardSolver forward_solver() const { return solver_; }
  void set_forward_solver(ForwardSolver s) { solver_ = s; }

 private:
  double mu_at(double x) const;
  // Generalized forces of the injected spring and joint-load faults, added to Q (nq); with
  // jac, also their stiffness (spring) on dFdq. Nothing when the faults are healthy.
  void fault_forces(const VectorXd& q, Eigen::Ref<VectorXd> Q, ImplicitTerms* jac) const;
  // Friction force along the tangent for normal force fN, tangential velocity vt; dfdv its
  // derivative wrt vt (for implicit schemes). slot ≥ 0 selects a stick–slip anchor.
  double friction(double mu, double fN, double vt, double xt, int slot, double& dfdv) const;
  void add_contact(int k_a, int k_b, double s, const Vec2& n, double depth, double mu,
                   const VectorXd& v, double xt, int slot, Eigen::Ref<VectorXd> Q,
                   ImplicitTerms* jac, ContactReport* report);
  // Adds the contact (body points k_a, k_b, its friction branch) to jac->signature; without the
  // Jacobian (jac->with_jacobian false) returns true with fq the point force whose generalized
  // force is the contact's part of D_q v (NaN when jac does not ask for D_q v).
  bool add_signature(int k_a, int k_b, double dfdv, double fT, const Vec2& n, const Vec2& vel, double fN,
                     ImplicitTerms* jac, Vec2& fq) const;
  // The contact's stiff terms on jac from Ja_ (the contact point's Jacobian, 2×nq).
  void add_contact_jacobian(const Vec2& n, double fN, double fT, double dfdv, double vt, double mu,
                            bool with_friction, const VectorXd& v, ImplicitTerms* jac);

  // Thick links (scene robot.link_shape capsule or box; README "Link shapes"). A contact point is
  // the material point at (1 − s)·p_ka + s·p_kb + r: the body points k_a, k_b (both on link la,
  // or k_a = k_b a joint) and a lever r off the axis, carried by link la (weight 1 − w) and link
  // lb (weight w): its velocity uses the weighted θ̇, its force adds the moment r × f so split.
  struct ShapePoint {
    int ka = 0, kb = 0;
    double s = 0.0;
    Vec2 r = Vec2::Zero();
    int la = 0, lb = 0;
    double w = 0.0;
  };
  ShapePoint on_point(int k, const Vec2& r) const;  // a lever r off body point k (joints: ½ + ½)
  void add_shape_contact(const ShapePoint& c, const Vec2& n, double depth, double mu,
                         const VectorXd& v, Eigen::Ref<VectorXd> Q, ImplicitTerms* jac,
                         ContactReport* report);
  // Every contact of the capsule or box links (after pts_x_, pts_z_ are set).
  void shape_contacts(const VectorXd& v, Eigen::Ref<VectorXd> Q, ImplicitTerms* jac,
                      ContactReport* report);

  Scene scene_;
  Model model_;
  Data data_;
  ActuatorInput input_;
  PlantFaults faults_;
  VectorXd u_, Q_;
  MatrixXd Ja_, Jb_;
  Eigen::RowVectorXd jn_, jt_, jw_;
  VectorXd pts_x_, pts_z_; // body point positions of the current evaluation [m], (2N+1)
  VectorXd anchor_;        // stick–slip anchor x per ground point [m]
  std::vector<char> anchored_;
  std::mt19937_64 rng_;
  double x_min_ = 0.0, x_max_ = 0.0;  // robot's X extent at the last evaluation (broad phase)
  ForwardSolver solver_ = ForwardSolver::kRecursive;
};

// A plant with its integrator and state: the unit the CLI, tools and the sim driver step.
class Simulation {
 public:
  explicit Simulation(const Scene& scene);
  Simulation(const Scene& scene, const IntegratorOptions& integ);

  Plant& plant() { return plant_; }
  Integrator& integrator() { return integ_; }
  double t() const { return t_; }
  const VectorXd& q() const { return q_; }
  const VectorXd& v() const { return v_; }
  VectorXd& q() { return q_; }
  VectorXd& v() { return v_; }

  // Advance to t_end in plant steps (fixed-step: steps of h; adaptive: its own steps), calling
  // plant.after_step() after each. Returns the first failure.
  StepStatus advance_to(double t_end);

 private:
  Plant plant_;
  Integrator integ_;
  double t_ = 0.0;
  VectorXd q_, v_;
};

}  // namespace pedalwave::model
