// The standard ROS 2 view of a pedalwave robot: joint and link names, the URDF generated from the
// robot's parameters, the link poses for /tf, the /diagnostics statuses. Pure functions (no DDS);
// DdsTelemetry publishes their results on the telemetry thread, never in the real-time cycle.
//
// Frames (model-spec.md §1): link i's frame sits at its rear end (link 1's at the tail tip
// (x_0, z_0)), its X axis along the link towards link i+1, Z up in the robot's plane of motion.
// Joint j (1-based) joins link j's front end to link j+1: child origin at x = 2l, rotation about
// the parent's +Y axis by α_j (α_j = θ_j − θ_{j+1}: a positive α_j turns link j+1 from +X towards
// −Z relative to link j). The world frame is "<prefix>odom" with the robot's XZ plane as its XZ
// plane; odom → link 1 comes from the observer's body estimate (θ_N, p_x, p_z).
#pragma once

#include <array>
#include <cstdint>
#include <string>
#include <vector>

#include "pedalwave/interface/telemetry_sink.hpp"
#include "pedalwave/telemetry/messages.hpp"

namespace pedalwave::telemetry {

// "snake1/" for the namespace "/snake1", "" for the root namespace: what the URDF's link names
// and the /tf frames of one robot start with.
std::string frame_prefix(const std::string& ros_namespace);
std::string joint_name(int j);   // j 1-based: "joint_1"
std::string link_name(int i);    // i 1-based: "link_1" (tail) … "link_N" (head)

// The URDF of the chain: N box links of length 2l (mass m_l, inertia of a slender rod), N−1
// revolute joints about +Y with origin (2l, 0, 0), limits ±π/2, effort limit 0 (unknown), named
// prefix + link_name / joint_name. Throws std::invalid_argument if links < 2 or 2l <= 0.
std::string make_urdf(const runtime::RobotDescription& d, const std::string& prefix);

// A planar pose in the robot's XZ plane: translation (x, 0, z), rotation by `theta` from +X
// towards +Z (about −Y).
struct PlanarPose {
  double x = 0.0, z = 0.0;   // [m]
  double theta = 0.0;        // [rad]
};
// The quaternion (x, y, z, w) of a PlanarPose rotation.
std::array<double, 4> planar_quaternion(double theta) noexcept;

// out[0] = odom → link 1 (the tail tip and θ_1); out[j] = link j → link j+1 for j = 1..N−1
// (x = 2l, z = 0, theta = −α_j). θ_i = θ_N + Σ_{k≥i} α_k, and x_0, z_0 place the mean of the link
// centres at (p_x, p_z). `alpha` has links−1 entries; out must hold `links` poses. No allocation.
void chain_poses(const double* alpha, int links, double link_length, double theta_N, double p_x,
                 double p_z, PlanarPose* out) noexcept;

// The diagnostic level of a runtime state: mode (fault/safe_stop → ERROR), last fault severity
// (info → OK, warning/degrade → WARN, stop → ERROR). diagnostic_msgs/DiagnosticStatus levels.
std::uint8_t mode_level(std::uint8_t mode) noexcept;
std::uint8_t severity_level(std::uint8_t severity) noexcept;

}  // namespace pedalwave::telemetry
