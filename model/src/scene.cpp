#include "pedalwave/model/scene.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace pedalwave::model {

namespace {
[[noreturn]] void reject(const Scene& s, const std::string& key, double value, const char* expected) {
  std::ostringstream os;
  os << (s.source.empty() ? "scene '" + s.name + "'" : s.source) << ": " << key << " = " << value
     << ": " << expected;
  throw std::invalid_argument(os.str());
}
void positive(const Scene& s, const std::string& key, double v) {
  if (!std::isfinite(v) || !(v > 0)) reject(s, key, v, "expected a finite number > 0");
}
void non_negative(const Scene& s, const std::string& key, double v) {
  if (!std::isfinite(v) || v < 0) reject(s, key, v, "expected a finite number >= 0");
}
}  // namespace

void validate(const Scene& s) {
  try {
    validate(s.robot);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument((s.source.empty() ? "scene '" + s.name + "'" : s.source) +
                                ": robot: " + e.what());
  }
  try {
    validate(s.integrator);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument((s.source.empty() ? "scene '" + s.name + "'" : s.source) +
                                ": integrator: " + e.what());
  }
  positive(s, "duration", s.duration);
  if (s.ground_on) {
    const Ground& g = s.ground;
    // Thick links (README "Link shapes") keep no stick-slip anchors (those belong to the segment's
    // body points), and a box link has no contact at its COM for friction_at_com to use.
    const LinkShape shape = s.robot.link_shape;
    const std::string where = s.source.empty() ? "scene '" + s.name + "'" : s.source;
    if (shape != LinkShape::kSegment && g.law == FrictionLaw::kStickSlip)
      throw std::invalid_argument(where + ": ground.friction = stick_slip: not available with robot.link_shape = " +
                                  to_string(shape) + " (expected coulomb, regularized or tanh, or link_shape segment)");
    if (shape == LinkShape::kBox && g.friction_at_com)
      throw std::invalid_argument(where + ": ground.friction_at_com = true: not available with robot.link_shape = box "
                                  "(a box link touches with its corners, never at its COM)");
    if (!std::isfinite(g.z)) reject(s, "ground.z", g.z, "expected a finite height [m]");
    positive(s, "ground.k", g.k);
    non_negative(s, "ground.d", g.d);
    non_negative(s, "ground.mu", g.mu);
    positive(s, "ground.v_s", g.v_s);
    positive(s, "ground.k_t", g.k_t);
    double prev = -1e300;
    for (size_t i = 0; i < g.patches.size(); ++i) {
      const std::string key = "ground.patches[" + std::to_string(i) + "]";
      if (!std::isfinite(g.patches[i].x_begin) || g.patches[i].x_begin < prev)
        reject(s, key + ".x_begin", g.patches[i].x_begin,
               "expected finite and not below the previous patch's x_begin (sorted along X)");
      prev = g.patches[i].x_begin;
      non_negative(s, key + ".mu", g.patches[i].mu);
    }
  }
  for (size_t i = 0; i < s.boxes.size(); ++i) {
    const std::string key = "obstacles[" + std::to_string(i) + "]";
    if (!s.ground_on) reject(s, key, 0, "boxes stand on the ground: switch ground on");
    if (!std::isfinite(s.boxes[i].x_near) && !std::isfinite(s.boxes[i].ahead_of_head))
      reject(s, key + ".x_near", s.boxes[i].x_near, "expected finite [m] (or ahead_of_head)");
    positive(s, key + ".width", s.boxes[i].width);
    positive(s, key + ".height", s.boxes[i].height);
    non_negative(s, key + ".mu", s.boxes[i].mu);
    if (!std::isnan(s.boxes[i].edge_mu)) non_negative(s, key + ".edge_mu", s.boxes[i].edge_mu);
  }
  if (s.joint_friction_on) non_negative(s, "joint_friction.motor_viscous", s.joint_friction.motor_viscous);
  if (s.torque_limit_on) positive(s, "torque_limit.u_max", s.torque_limit.u_max);
  if (s.sensor_noise_on) {
    const SensorNoise& n = s.sensor_noise;
    non_negative(s, "sensor_noise.beta_sigma", n.beta_sigma);
    non_negative(s, "sensor_noise.beta_dot_sigma", n.beta_dot_sigma);
    non_negative(s, "sensor_noise.deflection_sigma", n.deflection_sigma);
    non_negative(s, "sensor_noise.encoder_resolution", n.encoder_resolution);
    non_negative(s, "sensor_noise.deflection_resolution", n.deflection_resolution);
  }
  const int nq = s.robot.joints == JointModel::kFlexible ? 2 * s.robot.N + 1 : s.robot.N + 2;
  if (s.initial.pose == InitialPose::kExplicit) {
    if (static_cast<int>(s.initial.q.size()) != nq)
      reject(s, "initial.q (entries)", static_cast<double>(s.initial.q.size()),
             "expected nq entries: 2N+1 for flexible joints, N+2 for rigid");
    if (!s.initial.v.empty() && static_cast<int>(s.initial.v.size()) != nq)
      reject(s, "initial.v (entries)", static_cast<double>(s.initial.v.size()),
             "expected nq entries or none (at rest)");
    for (size_t i = 0; i < s.initial.q.size(); ++i)
      if (!std::isfinite(s.initial.q[i])) reject(s, "initial.q[" + std::to_string(i) + "]", s.initial.q[i], "expected finite");
  }
  if (!std::isfinite(s.initial.x)) reject(s, "initial.x", s.initial.x, "expected finite [m]");
  if (!std::isfinite(s.initial.height)) reject(s, "initial.height", s.initial.height, "expected finite [m]");
}

}  // namespace pedalwave::model
