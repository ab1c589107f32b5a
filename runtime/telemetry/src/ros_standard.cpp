#include "pedalwave/telemetry/ros_standard.hpp"

#include <cmath>
#include <cstring>
#include <sstream>
#include <stdexcept>

namespace pedalwave::telemetry {

std::string frame_prefix(const std::string& ros_namespace) {
  if (ros_namespace.empty() || ros_namespace == "/") return "";
  return ros_namespace.substr(1) + "/";
}

std::string joint_name(int j) { return "joint_" + std::to_string(j); }
std::string link_name(int i) { return "link_" + std::to_string(i); }

std::string make_urdf(const runtime::RobotDescription& d, const std::string& prefix) {
  if (d.links < 2 || d.links > runtime::kMaxJoints + 1) {
    throw std::invalid_argument("make_urdf: links = " + std::to_string(d.links) +
                                ": expected 2.." + std::to_string(runtime::kMaxJoints + 1));
  }
  if (!(d.link_length > 0.0)) {
    throw std::invalid_argument("make_urdf: link_length = " + std::to_string(d.link_length) +
                                ": expected > 0 [m]");
  }
  std::string name(d.name.data(), strnlen(d.name.data(), d.name.size()));
  if (name.empty()) name = "pedalwave";
  const double L = d.link_length;
  const double w = 0.25 * L;   // drawn width and height of a module [m] (display only)
  const double m = d.link_mass > 0.0 ? d.link_mass : 1e-3;
  // Slender rod about its centre: I = m L² / 12 (Y and Z), a thin one about X.
  const double i_yz = m * L * L / 12.0;
  const double i_x = m * w * w / 6.0;
  std::ostringstream u;
  u.precision(17);
  u << "<?xml version=\"1.0\"?>\n<robot name=\"" << name << "\">\n";
  for (int i = 1; i <= d.links; ++i) {
    u << "  <link name=\"" << prefix << link_name(i) << "\">\n"
      << "    <visual><origin xyz=\"" << L / 2 << " 0 0\" rpy=\"0 0 0\"/>"
      << "<geometry><box size=\"" << L << ' ' << w << ' ' << w << "\"/></geometry></visual>\n"
      << "    <inertial><origin xyz=\"" << L / 2 << " 0 0\" rpy=\"0 0 0\"/><mass value=\"" << m
      << "\"/><inertia ixx=\"" << i_x << "\" ixy=\"0\" ixz=\"0\" iyy=\"" << i_yz
      << "\" iyz=\"0\" izz=\"" << i_yz << "\"/></inertial>\n"
      << "  </link>\n";
  }
  for (int j = 1; j < d.links; ++j) {
    u << "  <joint name=\"" << prefix << joint_name(j) << "\" type=\"revolute\">\n"
      << "    <parent link=\"" << prefix << link_name(j) << "\"/><child link=\"" << prefix
      << link_name(j + 1) << "\"/>\n"
      << "    <origin xyz=\"" << L << " 0 0\" rpy=\"0 0 0\"/><axis xyz=\"0 1 0\"/>\n"
      << "    <limit lower=\"" << -M_PI / 2 << "\" upper=\"" << M_PI / 2
      << "\" effort=\"0\" velocity=\"0\"/>\n"
      << "  </joint>\n";
  }
  u << "</robot>\n";
  return u.str();
}

std::array<double, 4> planar_quaternion(double theta) noexcept {
  // Rotation by theta about −Y (turns +X towards +Z).
  return {0.0, -std::sin(theta / 2), 0.0, std::cos(theta / 2)};
}

void chain_poses(const double* alpha, int links, double link_length, double theta_N, double p_x,
                 double p_z, PlanarPose* out) noexcept {
  if (links < 1) return;
  // θ_1 = θ_N + Σ_{k=1}^{N−1} α_k; the mean link centre relative to the tail tip.
  double theta_1 = theta_N;
  for (int k = 0; k < links - 1; ++k) theta_1 += alpha[k];
  double sx = 0.0, sz = 0.0;       // Σ_i (centre of link i − tail tip)
  double ex = 0.0, ez = 0.0;       // rear end of link i − tail tip
  double theta = theta_1;
  for (int i = 1; i <= links; ++i) {
    sx += ex + 0.5 * link_length * std::cos(theta);
    sz += ez + 0.5 * link_length * std::sin(theta);
    ex += link_length * std::cos(theta);
    ez += link_length * std::sin(theta);
    if (i < links) theta -= alpha[i - 1];   // θ_{i+1} = θ_i − α_i
  }
  out[0] = {p_x - sx / links, p_z - sz / links, theta_1};
  for (int j = 1; j < links; ++j) out[j] = {link_length, 0.0, -alpha[j - 1]};
}

std::uint8_t mode_level(std::uint8_t mode) noexcept {
  const auto m = static_cast<runtime::Mode>(mode);
  if (m == runtime::Mode::kFault || m == runtime::Mode::kSafeStop) return 2;
  return 0;
}

std::uint8_t severity_level(std::uint8_t severity) noexcept {
  switch (static_cast<runtime::Severity>(severity)) {
    case runtime::Severity::kInfo: return 0;
    case runtime::Severity::kWarning:
    case runtime::Severity::kDegrade: return 1;
    case runtime::Severity::kStop: return 2;
  }
  return 2;
}

}  // namespace pedalwave::telemetry
