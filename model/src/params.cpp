#include "pedalwave/model/params.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace pedalwave::model {

const char* to_string(LinkShape s) {
  switch (s) {
    case LinkShape::kSegment: return "segment";
    case LinkShape::kCapsule: return "capsule";
    case LinkShape::kBox: return "box";
  }
  return "?";
}

Params paper_params(int N) {
  Params p;
  p.N = N;
  return p;
}

namespace {
[[noreturn]] void reject(const char* name, double value, const char* unit, const char* expected) {
  std::ostringstream os;
  os << "model parameter " << name << " = " << value << " [" << unit << "]: " << expected;
  throw std::invalid_argument(os.str());
}
void require_finite(const char* name, double v, const char* unit) {
  if (!std::isfinite(v)) reject(name, v, unit, "must be a finite number");
}
}  // namespace

void validate(const Params& p) {
  if (p.N < kMinLinks || p.N > kMaxLinks) {
    std::ostringstream os;
    os << "model parameter N = " << p.N << " [links]: must be in [" << kMinLinks << ", "
       << kMaxLinks << "]";
    throw std::invalid_argument(os.str());
  }
  require_finite("m_l", p.m_l, "kg");
  require_finite("l", p.l, "m");
  require_finite("I_l", p.I_l, "kg·m²");
  require_finite("m_r", p.m_r, "kg");
  require_finite("I_r", p.I_r, "kg·m²");
  require_finite("n", p.n, "-");
  require_finite("g", p.g, "m/s²");
  require_finite("K_all", p.K_all, "N·m/rad");
  if (!(p.m_l > 0)) reject("m_l", p.m_l, "kg", "link mass must be > 0");
  if (!(p.l > 0)) reject("l", p.l, "m", "half link length must be > 0");
  if (!(p.I_l > 0)) reject("I_l", p.I_l, "kg·m²", "link inertia must be > 0");
  if (p.m_r < 0) reject("m_r", p.m_r, "kg", "rotor mass must be >= 0");
  if (p.I_r < 0) reject("I_r", p.I_r, "kg·m²", "rotor inertia must be >= 0");
  if (!(p.n > 0)) reject("n", p.n, "-", "gear ratio must be > 0");
  if (p.g < 0) reject("g", p.g, "m/s²", "gravity must be >= 0 (it acts along -Z)");
  if (!p.K.empty() && static_cast<int>(p.K.size()) != p.N - 1) {
    std::ostringstream os;
    os << "model parameter K has " << p.K.size() << " entries: expected N-1 = " << p.N - 1
       << " (one per joint) or none (then K_all is used)";
    throw std::invalid_argument(os.str());
  }
  require_finite("link_radius", p.link_radius, "m");
  require_finite("link_height", p.link_height, "m");
  if (p.link_shape == LinkShape::kCapsule && !(p.link_radius > 0))
    reject("link_radius", p.link_radius, "m", "the capsule's radius must be > 0 with link_shape capsule");
  if (p.link_shape == LinkShape::kBox && !(p.link_height > 0))
    reject("link_height", p.link_height, "m", "the module's height must be > 0 with link_shape box");
  if (p.link_radius < 0) reject("link_radius", p.link_radius, "m", "must be >= 0");
  if (p.link_height < 0) reject("link_height", p.link_height, "m", "must be >= 0");
  if (p.joints == JointModel::kFlexible) {
    if (p.I_r == 0)
      reject("I_r", p.I_r, "kg·m²",
             "must be > 0 with flexible joints (the motor block n²·I_r of the mass matrix would "
             "be singular: a massless motor); use joints: rigid, or give the rotor inertia");
    for (int j = 0; j < p.N - 1; ++j) {
      const double k = p.stiffness(j);
      if (!std::isfinite(k) || !(k > 0)) {
        std::ostringstream os;
        os << "model parameter K[" << j << "] = " << k
           << " [N·m/rad]: spring stiffness must be finite and > 0 with flexible joints";
        throw std::invalid_argument(os.str());
      }
    }
  }
}

std::string describe(const Params& p) {
  std::ostringstream os;
  os << "N=" << p.N << " links, 2l=" << 2 * p.l << " m, m_l=" << p.m_l << " kg, m_r=" << p.m_r
     << " kg, I_r=" << p.I_r << " kg·m², n=" << p.n << ", n²I_r=" << p.n * p.n * p.I_r
     << " kg·m², K=" << p.stiffness(0) << " N·m/rad, joints="
     << (p.joints == JointModel::kFlexible ? "flexible" : "rigid");
  if (p.link_shape == LinkShape::kCapsule) os << ", links: capsule r=" << p.link_radius << " m";
  if (p.link_shape == LinkShape::kBox) os << ", links: box h_m=" << p.link_height << " m";
  return os.str();
}

}  // namespace pedalwave::model
