// A scene: which effects exist and their parameters (DESIGN.md "Simulation", model-spec.md §6).
// Plain data; the config layer fills it from YAML, the Plant evaluates only what is switched on.
#pragma once

#include <cstdint>
#include <iterator>
#include <limits>
#include <string>
#include <string_view>
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
  double edge_mu = std::numeric_limits<double>::quiet_NaN();  // friction of those corner-vs-link
                         // contacts [-] (NaN: mu)
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
  // θ_N at the start [rad] (not kExplicit). NaN (the default): the base angle that levels the
  // chain's chord, both end points at one height, so a gait_start pose is as high as its wave,
  // whatever N (≤ A_p / sin²(η/2) link lengths, tested for N = 2…64); 0 lays link N flat (the
  // shipped 6-link scenes' start).
  double theta = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> q;  // kExplicit: full q (nq)
  std::vector<double> v;  // kExplicit: full q̇ (nq), empty = rest
};

// Nominal gait (model-spec.md §7), used for the kGaitStart pose and by the controllers.
struct GaitParams {
  double A_p = 0.7853981633974483;   // amplitude [rad] (π/4)
  double omega = 3.141592653589793;  // temporal frequency [rad/s] (π)
  double eta = -1.2566370614359172;  // spatial frequency [rad] (−2π/5)
};

// An injected fault (scene `faults:` list; config/scenes/README.md). The physical ones act on the
// Plant (PlantFaults), the others on the driver's Feedback; both are applied (drivers::FaultInjector)
// by drivers::FaultInjectingDriver from t_start on (a plain SimDriver ignores the list) and, except
// the host-side stale/out_of_order/repeated_frame, inside the virtual robot's modules
// (vrobot::SimulationPlant).
enum class FaultType : std::uint8_t {
  // Physical (model::PlantFaults)
  kTorqueGain,       // actuator output gain := value [-] (0 = torque loss)
  kMotorFriction,    // extra viscous motor friction := value [N·m·s/rad]
  kSpringScale,      // SEA stiffness factor := value [-] (0.2 = broken spring)
  kJointLoad,        // link-side torque on α_j := value [N·m] (a jam/snag: torque saturation)
  // Sensors and communication (drivers::Feedback)
  kEncoderStuck,     // β_j frozen at its last value, β̇_j reported 0
  kEncoderOffset,    // β_j += value [rad] (offset jump)
  kEncoderNoise,     // β_j += N(0, value²) [rad] for `duration` (noise burst)
  kDeflectionStuck,  // deflection_j frozen at its last value
  kDeflectionBias,   // deflection_j += value [rad]
  kDeflectionScale,  // deflection_j *= value [-]
  kNaN,              // deflection_j = NaN
  kImplausible,      // β_j := value [rad] (out of range)
  kModuleSilent,     // joint j: kStatusMissing, values frozen (the module stopped answering)
  kStale,            // joint j: the values of `value` cycles ago (1…15), kStatusStale
  kOutOfOrder,       // joint j: every other cycle the values of 2 cycles ago, kStatusOutOfOrder
  kRepeatedFrame,    // every other cycle the whole previous frame again, same seq (joint ignored)
  kCount
};

inline constexpr std::string_view kFaultTypeNames[] = {
    "torque_gain",     "motor_friction",   "spring_scale",     "joint_load",
    "encoder_stuck",   "encoder_offset",   "encoder_noise",    "deflection_stuck",
    "deflection_bias", "deflection_scale", "nan",              "implausible",
    "module_silent",   "stale",            "out_of_order",     "repeated_frame"};
static_assert(std::size(kFaultTypeNames) == static_cast<std::size_t>(FaultType::kCount));

inline std::string_view to_string(FaultType f) {
  const auto i = static_cast<std::size_t>(f);
  return i < std::size(kFaultTypeNames) ? kFaultTypeNames[i] : "?";
}
// false if `name` is not one of kFaultTypeNames.
inline bool parse_fault_type(std::string_view name, FaultType& out) {
  for (std::size_t i = 0; i < std::size(kFaultTypeNames); ++i)
    if (kFaultTypeNames[i] == name) {
      out = static_cast<FaultType>(i);
      return true;
    }
  return false;
}
inline bool is_physical(FaultType f) { return f <= FaultType::kJointLoad; }

struct FaultSpec {
  FaultType type = FaultType::kTorqueGain;
  int joint = 0;          // 0-based joint j, 0 … N-2 (kRepeatedFrame: ignored) [-]
  double t_start = 0.0;   // onset, time since the run started [s]
  double value = 0.0;     // magnitude, unit per type (FaultType) [-, rad, N·m, N·m·s/rad]
  double duration = std::numeric_limits<double>::infinity();  // active for this long [s]
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
  std::vector<FaultSpec> faults;  // injected faults (drivers::FaultInjector; see FaultType)
};

// Throws std::invalid_argument naming scene.<key>, its value and what was expected.
void validate(const Scene& s);

}  // namespace pedalwave::model
