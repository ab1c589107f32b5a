// Physical parameters of the SEA snake robot (model-spec.md §1, §8). Plain data, validated once by
// validate(); a Model is built from a validated copy and never changes afterwards.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace pedalwave::model {

inline constexpr int kMinLinks = 2;
inline constexpr int kMaxLinks = 64;

enum class JointModel : std::uint8_t {
  kFlexible,  // §4: SEA springs, motor angles β are states, 2N+1 coordinates
  kRigid,     // §5: β ≡ α, N+2 coordinates
};

enum class RigidVariant : std::uint8_t {
  kExactLimit,  // K → ∞ limit of §4: reflected rotor inertia n² I_r kept on the α rows (default)
  kPaper,       // P-32 as printed: rotor spin through the link rotation only (S_2, S_3 dropped)
};

// The module's solid around the link axis, for contact only (mass and inertia stay m_l, I_l):
// model-spec.md §6 and the README's "Link shapes".
enum class LinkShape : std::uint8_t {
  kSegment,  // the axis itself, zero thickness: the spec's 2N+1 points + box corners (default)
  kCapsule,  // every point within link_radius of the axis segment
  kBox,      // the rectangle 2l long, link_height tall, centred on the axis
};
const char* to_string(LinkShape s);

struct Params {
  int N = 6;                   // number of links [-]
  double m_l = 0.1;            // link mass [kg]
  double l = 0.035;            // half link length [m] (links are 2l = 0.07 m long)
  double I_l = 0.1 * 0.07 * 0.07 / 12.0;  // link inertia about its COM [kg·m²] (uniform rod)
  double m_r = 0.02;           // rotor/module mass at each joint [kg]
  double I_r = 5e-8;           // rotor inertia about its spin axis [kg·m²]
  double n = 255.0;            // gear ratio [-]
  std::vector<double> K;       // SEA spring stiffness per joint [N·m/rad], (N-1); empty → K_all
  double K_all = 3.0;          // stiffness used for every joint when K is empty [N·m/rad]
  double g = 9.81;             // gravity [m/s²] (along −Z)
  JointModel joints = JointModel::kFlexible;
  RigidVariant rigid_variant = RigidVariant::kExactLimit;
  LinkShape link_shape = LinkShape::kSegment;  // contact geometry of each module
  double link_radius = 0.0;    // capsule radius r [m] (link_shape capsule)
  double link_height = 0.0;    // box height h_m across the axis [m] (link_shape box)

  // The surface's distance from the axis on either side: 0, r or h_m/2 [m].
  double half_thickness() const {
    return link_shape == LinkShape::kCapsule ? link_radius
           : link_shape == LinkShape::kBox   ? 0.5 * link_height
                                             : 0.0;
  }
  // Stiffness of joint j (0-based).
  double stiffness(int j) const { return K.empty() ? K_all : K[static_cast<std::size_t>(j)]; }
};

// The paper's robot (model-spec.md §8) with N links.
Params paper_params(int N = 6);

// Throws std::invalid_argument naming the parameter, its value and what was expected, e.g.
// "model parameter I_r = 0 [kg·m²]: must be > 0 with flexible joints (the motor block of the mass
//  matrix is singular); use joints: rigid, or give the rotor inertia".
void validate(const Params& p);

// Human-readable one-line summary.
std::string describe(const Params& p);

}  // namespace pedalwave::model
