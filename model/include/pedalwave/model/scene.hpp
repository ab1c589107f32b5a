// A scene: which effects exist and their parameters (DESIGN.md "Simulation", model-spec.md §6).
// Plain data; the config layer fills it from YAML, the Plant evaluates only what is switched on.
#pragma once

#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "pedalwave/model/integrators.hpp"
#include "pedalwave/model/params.hpp"

namespace pedalwave::model {

enum class FrictionLaw : std::uint8_t {
  kCoulomb,      // f_T = −μ f_N sign(v_t), exactly as the paper (sign(0) = 0)
  kRegularized,  // f_T = −μ f_N v_t / max(|v_t|, v_s)  (default)
  kTanh,         // f_T = −μ f_N tanh(v_t / v_s)
  kStickSlip,    // anchored stick spring, slips when it would exceed μ f_N (Karnopp/bristle family)
};
const char* to_string(FrictionLaw f);

// Friction coefficient along X: μ = mu_default, or the μ of the last patch with x >= x_begin.
struct SurfacePatch {
  double x_begin = 0.0;  // patch starts here and runs to the next patch [m]
  double mu = 0.4;       // Coulomb coefficient on it [-]
};

struct Ground {
  double z = 0.0;           // ground height [m]
  double k = 350.0;         // normal stiffness [N/m]
  double d = 15.0;          // normal damping [N·s/m]
  double mu = 0.82;         // Coulomb coefficient where no patch applies [-]
  std::vector<SurfacePatch> patches;  // sorted by x_begin
  FrictionLaw law = FrictionLaw::kRegularized;
  double v_s = 1e-3;        // stiction / regularization velocity [m/s]
  double k_t = 2000.0;      // stick-slip: tangential anchor stiffness [N/m]
  bool friction_at_com = false;  // paper option: friction only at the link COMs
};

// A stair-type box on the ground: [x_near, x_near + width] × [ground.z, ground.z + height].
struct Box {
  double x_near = 0.0;   // near edge [m] (absolute X), unless ahead_of_head is given
  double ahead_of_head = std::numeric_limits<double>::quiet_NaN();  // near edge this far ahead of
                         // the head tip (the leading tip, +X) in the initial state [m]
  double width = 0.11;   // [m]
  double height = 0.06;  // [m]
  double mu = 0.82;      // friction on its faces [-]
  bool corner_contact = true;  // test its top corners against the link segments
};

struct JointFriction {
  double motor_viscous = 0.0;  // b_m on the β rows (rigid: α rows) [N·m·s/rad]
};

struct TorqueLimit {
  double u_max = 0.0;  // |u_j| ≤ u_max [N·m]; 0 = no limit
};

struct SensorNoise {
  double beta_sigma = 0.0;        // motor encoder noise σ [rad]
  double beta_dot_sigma = 0.0;    // motor rate noise σ [rad/s]
  double deflection_sigma = 0.0;  // deflection sensor noise σ [rad]
  double encoder_resolution = 0.0;     // β quantization step [rad]; 0 = none
  double deflection_resolution = 0.0;  // deflection quantization step [rad]; 0 = none
  std::uint64_t seed = 1;
};

enum class InitialPose : std::uint8_t {
  kFlat,       // straight on the ground (z = ground.z), at rest
  kGaitStart,  // joint angles of the nominal gait at t = 0, on the ground, at rest
  kAir,        // straight, at rest, `height` above the ground
  kExplicit,   // q and v given in full
};

struct InitialState {
  InitialPose pose = InitialPose::kFlat;
  double x = 0.0;        // p_x [m]
  double height = 0.0;   // p_z above the ground [m] (kAir); negative = starts in penetration
  std::vector<double> q;  // kExplicit: full q (nq)
  std::vector<double> v;  // kExplicit: full q̇ (nq), empty = rest
};

// Nominal gait (model-spec.md §7), used for the kGaitStart pose and by the controllers.
struct GaitParams {
  double A_p = 0.7853981633974483;   // amplitude [rad] (π/4)
  double omega = 3.141592653589793;  // temporal frequency [rad/s] (π)
  double eta = -1.2566370614359172;  // spatial frequency [rad] (−2π/5)
};

struct Scene {
  std::string name = "unnamed";
  std::string source;  // file it came from (for messages)
  Params robot = paper_params();
  bool ground_on = true;
  Ground ground;
  std::vector<Box> boxes;
  bool joint_friction_on = false;
  JointFriction joint_friction;
  bool torque_limit_on = false;
  TorqueLimit torque_limit;
  bool sensor_noise_on = false;
  SensorNoise sensor_noise;
  InitialState initial;
  GaitParams gait;
  double duration = 10.0;  // [s]
  IntegratorOptions integrator{.method = Method::kImplicitVelocity, .h = 1e-4};
};

// Throws std::invalid_argument naming scene.<key>, its value and what was expected.
void validate(const Scene& s);

}  // namespace pedalwave::model
