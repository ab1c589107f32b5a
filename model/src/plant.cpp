#include "pedalwave/model/plant.hpp"

#include "pedalwave/interface/io.hpp"
#include "pedalwave/interface/sea.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace pedalwave::model {

// The model's largest robot is the one the driver interface can carry (one bound, two headers).
static_assert(kMaxLinks == drivers::kMaxLinks, "model::kMaxLinks and drivers::kMaxLinks must agree");

const char* to_string(FrictionLaw f) {
  switch (f) {
    case FrictionLaw::kCoulomb: return "coulomb";
    case FrictionLaw::kRegularized: return "regularized";
    case FrictionLaw::kTanh: return "tanh";
    case FrictionLaw::kStickSlip: return "stick_slip";
  }
  return "?";
}

Plant::Plant(const Scene& scene)
    : scene_(scene), model_(scene.robot), data_(model_), rng_(scene.sensor_noise.seed) {
  validate(scene_);
  const int J = model_.joints(), n = model_.nq(), P = model_.points();
  for (auto* x : {&input_.tau, &input_.beta_ref, &input_.beta_dot_ref, &input_.kp, &input_.kd})
    *x = VectorXd::Zero(J);
  u_ = VectorXd::Zero(J);
  Q_ = VectorXd::Zero(n);
  faults_.torque_gain = VectorXd::Ones(J);
  faults_.motor_friction = VectorXd::Zero(J);
  faults_.spring_scale = VectorXd::Ones(J);
  faults_.joint_load = VectorXd::Zero(J);
  Ja_ = MatrixXd::Zero(2, n);
  Jb_ = MatrixXd::Zero(2, n);
  jn_ = Eigen::RowVectorXd::Zero(n);
  jt_ = Eigen::RowVectorXd::Zero(n);
  jw_ = Eigen::RowVectorXd::Zero(n);
  pts_x_ = VectorXd::Zero(P);
  pts_z_ = VectorXd::Zero(P);
  anchor_ = VectorXd::Zero(P);
  anchored_.assign(static_cast<size_t>(P), 0);
  // Boxes placed relative to the leading (head) tip of the initial state.
  bool relative = false;
  for (const Box& b : scene_.boxes) relative |= std::isfinite(b.ahead_of_head);
  if (relative) {
    VectorXd q, v;
    initial_state(q, v);
    update_kinematics(model_, data_, q, v);
    // The head's front: its tip, or the surface ahead of it when the links are thick.
    double x_head = point_position(model_, data_, q, model_.point_head()).x();
    if (model_.params().link_shape == LinkShape::kCapsule) x_head += model_.params().link_radius;
    if (model_.params().link_shape == LinkShape::kBox)
      x_head += model_.params().half_thickness() * std::abs(data_.sin_t(model_.N() - 1));
    for (Box& b : scene_.boxes)
      if (std::isfinite(b.ahead_of_head)) b.x_near = x_head + b.ahead_of_head;
  }
}

void Plant::initial_state(VectorXd& q, VectorXd& v) const {
  const Model& m = model_;
  const InitialState& in = scene_.initial;
  q = VectorXd::Zero(m.nq());
  v = VectorXd::Zero(m.nq());
  if (in.pose == InitialPose::kExplicit) {
    for (int i = 0; i < m.nq(); ++i) q(i) = in.q[static_cast<size_t>(i)];
    if (!in.v.empty())
      for (int i = 0; i < m.nq(); ++i) v(i) = in.v[static_cast<size_t>(i)];
    return;
  }
  if (in.pose == InitialPose::kGaitStart) {
    const GaitParams& g = scene_.gait;
    for (int j = 0; j < m.joints(); ++j) q(m.i_alpha(j)) = g.A_p * std::sin(g.eta * j);
  }
  if (m.flexible())
    for (int j = 0; j < m.joints(); ++j) q(m.i_beta(j)) = q(m.i_alpha(j));
  q(m.i_px()) = in.x;
  Data d(m);
  // The base angle: as given, or the one that levels the chord. With θ_N = 0 the links' absolute
  // angles θ_i (θ_N = 0) give the chord Σ 2l (cos θ_i, sin θ_i); rotating every link by
  // −atan2(Σ sin θ_i, Σ cos θ_i) makes its vertical part zero. (θ_N = 0 for every N put the head
  // of a 12-link gait_start 32 cm up, of a 64-link one 2.5 m.)
  if (std::isfinite(in.theta)) {
    q(m.i_theta_N()) = in.theta;
  } else {
    update_kinematics(m, d, q, VectorXd());
    double s = 0.0, c = 0.0;
    for (int i = 0; i < m.N(); ++i) {
      s += d.sin_t(i);
      c += d.cos_t(i);
    }
    q(m.i_theta_N()) = -std::atan2(s, c);
  }
  // Rest the lowest point on the ground (plus the requested height), whatever the shape: of the
  // links' surface when they are thick.
  update_kinematics(m, d, q, VectorXd());
  double z_low = 1e300;
  for (int k = 0; k < m.points(); ++k) z_low = std::min(z_low, point_position(m, d, q, k).y());
  if (m.params().link_shape == LinkShape::kCapsule) z_low -= m.params().link_radius;
  if (m.params().link_shape == LinkShape::kBox) {
    z_low = 1e300;
    for (int i = 0; i < m.N(); ++i)
      for (int k : {2 * i, 2 * i + 2})
        z_low = std::min(z_low, point_position(m, d, q, k).y() - m.params().half_thickness() * std::abs(d.cos_t(i)));
  }
  const double z_ground = scene_.ground_on ? scene_.ground.z : 0.0;
  q(m.i_pz()) = z_ground - z_low + in.height;
}

double Plant::mu_at(double x) const {
  double mu = scene_.ground.mu;
  for (const SurfacePatch& p : scene_.ground.patches)
    if (x >= p.x_begin) mu = p.mu;
  return mu;
}

double Plant::friction(double mu, double fN, double vt, double xt, int slot, double& dfdv) const {
  const Ground& g = scene_.ground;
  dfdv = 0.0;
  switch (g.law) {
    case FrictionLaw::kCoulomb:
      return vt > 0 ? -mu * fN : (vt < 0 ? mu * fN : 0.0);
    case FrictionLaw::kRegularized:
      if (std::abs(vt) < g.v_s) {
        dfdv = -mu * fN / g.v_s;
        return dfdv * vt;
      }
      return vt > 0 ? -mu * fN : mu * fN;
    case FrictionLaw::kTanh: {
      const double th = std::tanh(vt / g.v_s);
      dfdv = -mu * fN * (1 - th * th) / g.v_s;
      return -mu * fN * th;
    }
    case FrictionLaw::kStickSlip: {
      if (slot < 0 || !anchored_[static_cast<size_t>(slot)]) {  // no anchor yet: regularized
        if (std::abs(vt) < g.v_s) {
          dfdv = -mu * fN / g.v_s;
          return dfdv * vt;
        }
        return vt > 0 ? -mu * fN : mu * fN;
      }
      // Stick spring to the anchor plus critical-ish damping; slips at μ f_N.
      const double c = 2.0 * std::sqrt(g.k_t * 0.1);
      const double f = -g.k_t * (xt - anchor_(slot)) - c * vt;
      const double lim = mu * fN;
      if (std::abs(f) <= lim) {
        dfdv = -c;
        return f;
      }
      return f > 0 ? lim : -lim;
    }
  }
  return 0.0;
}

// One contact at the material point (1 − s)·A + s·B of body points k_a, k_b (s = 0 for a body
// point), normal n, penetration depth > 0. Force f = f_N n + f_T t enters as Jᵀ f.
void Plant::add_contact(int k_a, int k_b, double s, const Vec2& n, double depth, double mu,
                        const VectorXd& v, double xt, int slot, Eigen::Ref<VectorXd> Q,
                        ImplicitTerms* jac, ContactReport* report) {
  const Model& m = model_;
  const Ground& g = scene_.ground;
  const Vec2 t(n.y(), -n.x());
  Vec2 vel = point_velocity(m, data_, v, k_a);
  if (s > 0) vel = (1 - s) * vel + s * point_velocity(m, data_, v, k_b);
  const double depth_rate = -vel.dot(n);
  const double fN = std::max(g.k * depth + g.d * depth_rate, 0.0);
  const double vt = vel.dot(t);
  double dfdv = 0.0;
  const bool with_friction = !(g.friction_at_com && s == 0 && (k_a % 2) == 0);
  const double fT = with_friction ? friction(mu, fN, vt, xt, slot, dfdv) : 0.0;
  const Vec2 f = fN * n + fT * t;
  if (s > 0) {
    add_point_force(m, data_, k_a, (1 - s) * f, Q);
    add_point_force(m, data_, k_b, s * f, Q);
  } else {
    add_point_force(m, data_, k_a, f, Q);
  }
  if (report) {
    report->max_penetration = std::max(report->max_penetration, depth);
    report->elastic_energy += 0.5 * g.k * depth * depth;
    if (fN > 0) ++report->active;
    const int k = s > 0.5 ? k_b : k_a;
    report->f_normal(k) += fN;
    report->f_tangent(k) += fT;
  }
  Vec2 fq;
  if (jac && fN > 0 && add_signature(k_a, k_b, dfdv, fT, n, vel, fN, jac, fq)) {
    if (fq.allFinite()) {  // D_q v = −k (J_n v) Jᵀ(n + (f_T/f_N) t): a point force
      if (s > 0) {
        add_point_force(m, data_, k_a, (1 - s) * fq, jac->dFdq_v);
        add_point_force(m, data_, k_b, s * fq, jac->dFdq_v);
      } else {
        add_point_force(m, data_, k_a, fq, jac->dFdq_v);
      }
    }
  } else if (jac && fN > 0) {
    // Stiff terms for the implicit scheme: −k JnᵀJn on q, −d JnᵀJn + ∂f_T/∂v_t JtᵀJt on v.
    point_jacobian(m, data_, k_a, Ja_);
    if (s > 0) {
      point_jacobian(m, data_, k_b, Jb_);
      Ja_ = (1 - s) * Ja_ + s * Jb_;
    }
    add_contact_jacobian(n, fN, fT, dfdv, vt, mu, with_friction, v, jac);
  }
}

bool Plant::add_signature(int k_a, int k_b, double dfdv, double fT, const Vec2& n, const Vec2& vel,
                          double fN, ImplicitTerms* jac, Vec2& fq) const {
  // The contact and its friction branch: 1 on the slope of the law (stick band, tanh, stick
  // spring), 2 or 3 sliding (or no friction) with f_T > 0 or ≤ 0.
  const int branch = dfdv != 0.0 ? 1 : (fT > 0 ? 2 : 3);
  jac->signature = jac->signature * 1000003u + static_cast<std::uint64_t>(k_a * 4096 + k_b * 4 + branch);
  if (jac->with_jacobian) return false;
  // Without the Jacobian: what D_q v needs (when asked; else NaN), the force
  // −k (J_n v)(n + (f_T/f_N) t) at the point.
  const Vec2 t(n.y(), -n.x());
  if (jac->dq_in_dv > 0 && jac->dFdq_v.size() > 0)
    fq = (-scene_.ground.k * vel.dot(n)) * (n + (fT / fN) * t);
  else
    fq = Vec2::Constant(std::numeric_limits<double>::quiet_NaN());
  return true;
}

void Plant::add_contact_jacobian(const Vec2& n, double fN, double fT, double dfdv, double vt, double mu,
                                 bool with_friction, const VectorXd& v, ImplicitTerms* jac) {
  const Model& m = model_;
  const Ground& g = scene_.ground;
  const Vec2 t(n.y(), -n.x());
  // One fused pass over the body block (contact never touches the β columns):
  //   ∂F/∂q −= k Jnᵀ Jn + (f_T/f_N) k Jtᵀ Jn
  //   ∂F/∂v −= d Jnᵀ Jn + (f_T/f_N) d Jtᵀ Jn − (∂f_T/∂v_t) Jtᵀ Jt
  // (plain loops: Eigen's dynamic outer products go through its GEMM path, 30 % of a step).
  const int nb = m.nq1();
  for (int c = 0; c < nb; ++c) {
    jn_(c) = n.x() * Ja_(0, c) + n.y() * Ja_(1, c);
    jt_(c) = t.x() * Ja_(0, c) + t.y() * Ja_(1, c);
  }
  const double r = fN > 0 ? fT / fN : 0.0;
  // A Newton iterate sliding after the step started in the stick band or sliding the other way
  // (ImplicitTerms::v_start): the stick band's slope, so that the next correction can land in it.
  if (jac->v_start && with_friction && g.law == FrictionLaw::kRegularized && std::abs(vt) >= g.v_s) {
    double vt0 = 0.0;
    for (int c = 0; c < nb; ++c) vt0 += jt_(c) * (*jac->v_start)(c);
    if (std::abs(vt0) < g.v_s || vt0 * vt < 0) dfdv = -mu * fN / g.v_s;
  }
  if (jac->dq_in_dv > 0) {
    // Only ∂F/∂v + s ∂F/∂q (ImplicitTerms::dq_in_dv): −(d + s k) w Jnᵀ + ∂f_T/∂v_t JtᵀJt with
    // the shared factor w = J_n + r J_t, one pass.
    for (int c = 0; c < nb; ++c) jw_(c) = jn_(c) + r * jt_(c);
    if (jac->dFdq_v.size() > 0) {  // ∂F/∂q · v = −k w (J_n v)
      double jnv = 0.0;
      for (int c = 0; c < nb; ++c) jnv += jn_(c) * v(c);
      for (int c = 0; c < nb; ++c) jac->dFdq_v(c) -= g.k * jnv * jw_(c);
    }
    const double kd = g.d + jac->dq_in_dv * g.k;
    for (int b = 0; b < nb; ++b) {
      const double jnb = kd * jn_(b), jtb = dfdv * jt_(b);
      for (int a = 0; a < nb; ++a) jac->dFdv(a, b) += jt_(a) * jtb - jw_(a) * jnb;
    }
    return;
  }
  for (int b = 0; b < nb; ++b) {
    const double jnb = jn_(b), jtb = jt_(b);
    for (int a = 0; a < nb; ++a) {
      const double nn = jn_(a) * jnb, tn = jt_(a) * jnb, tt = jt_(a) * jtb;
      jac->dFdq(a, b) -= g.k * (nn + r * tn);
      jac->dFdv(a, b) -= g.d * (nn + r * tn) - dfdv * tt;
    }
  }
}

void Plant::contact_forces(const VectorXd& q, const VectorXd& v, Eigen::Ref<VectorXd> Q,
                           ImplicitTerms* jac, ContactReport* report) {
  const Model& m = model_;
  const int P = m.points();
  x_min_ = 1e300;
  x_max_ = -1e300;
  if (!scene_.ground_on && scene_.boxes.empty()) return;
  const Ground& g = scene_.ground;
  // All body points at once: [x, z] = p + c [cos θ, sin θ].
  pts_x_.noalias() = m.point_coeff() * data_.cos_t;
  pts_z_.noalias() = m.point_coeff() * data_.sin_t;
  pts_x_.array() += q(m.i_px());
  pts_z_.array() += q(m.i_pz());
  // Thick links: their own geometry (nothing of it runs for the segment).
  if (m.params().link_shape != LinkShape::kSegment) {
    shape_contacts(v, Q, jac, report);
    return;
  }
  auto pos = [&](int k) { return Vec2(pts_x_(k), pts_z_(k)); };
  // The robot's X extent (the boxes' broad phase), before the contacts: a member updated inside
  // the loop below was stored and reloaded around every add_contact (14 % of contact_forces).
  x_min_ = pts_x_.minCoeff();
  x_max_ = pts_x_.maxCoeff();
  // Ground: every body point against the plane z = ground.z.
  if (scene_.ground_on) {
    for (int k = 0; k < P; ++k) {
      const double depth = g.z - pts_z_(k);
      if (depth > 0)
        add_contact(k, k, 0.0, Vec2(0, 1), depth, mu_at(pts_x_(k)), v, pts_x_(k), k, Q, jac, report);
    }
  }
  // Boxes: only those the robot's X extent reaches (broad phase).
  for (const Box& b : scene_.boxes) {
    const double x0 = b.x_near, x1 = b.x_near + b.width, z0 = g.z, z1 = g.z + b.height;
    if (x_max_ < x0 || x_min_ > x1) continue;
    // Body points inside the box: pushed out through the nearest face.
    for (int k = 0; k < P; ++k) {
      const Vec2 p = pos(k);
      if (p.x() <= x0 || p.x() >= x1 || p.y() >= z1 || p.y() <= z0 - 1e-9) continue;
      const double d_top = z1 - p.y(), d_left = p.x() - x0, d_right = x1 - p.x();
      Vec2 n(0, 1);
      double depth = d_top;
      if (d_left < depth) depth = d_left, n = Vec2(-1, 0);
      if (d_right < depth) depth = d_right, n = Vec2(1, 0);
      add_contact(k, k, 0.0, n, depth, b.mu, v, 0.0, -1, Q, jac, report);
    }
    // The box's top corners against each link segment (a link resting on an edge).
    if (!b.corner_contact) continue;
    const double cap = 0.5 * std::min(b.width, b.height);
    const Vec2 centre(0.5 * (x0 + x1), 0.5 * (z0 + z1));
    for (const Vec2& c : {Vec2(x0, z1), Vec2(x1, z1)}) {
      for (int i = 0; i < m.N(); ++i) {
        const int ka = 2 * i, kb = 2 * i + 2;
        const Vec2 A = pos(ka), B = pos(kb);
        const Vec2 ab = B - A;
        const double len2 = ab.squaredNorm();
        const double s = (c - A).dot(ab) / len2;
        if (s <= 0.0 || s >= 1.0) continue;
        Vec2 n(-ab.y(), ab.x());
        n /= std::sqrt(len2);
        if (n.dot(c - centre) < 0) n = -n;  // away from the box interior
        const double depth = (c - A).dot(n);
        if (depth <= 0 || depth > cap) continue;
        add_contact(ka, kb, s, n, depth, std::isnan(b.edge_mu) ? b.mu : b.edge_mu, v, 0.0, -1, Q, jac, report);
      }
    }
  }
}

// ---- thick links -------------------------------------------------------------------------------
// Geometry (README "Link shapes"), link i from A = p_2i to B = p_2i+2, axis u_i, normal ν_i:
//   capsule: the 2N+1 body points are the centres of spheres of radius r (the capsule's closest
//            points to a flat face are among them: its ends, and the COMs of a link lying flat);
//            each is tested against the ground and the box (the nearest point of its top and side
//            faces, which run down into the ground), the contact point offset by r along the
//            normal (a joint's sphere belongs to both links: ½ + ½). A box's top corner against
//            each link: r minus the distance from the corner to the axis segment (signed inside the
//            link, as the segment's corner test; its end caps included). Every depth is continuous;
//            where a sphere and a link both see a corner (near a COM, a joint) the corner acts
//            through both (stiffer there, up to 3 k at a joint, same statics). r → 0 gives the
//            segment's contacts (tests/model/shapes_test.cpp).
//   box:     the 4 corners A ± (h_m/2) ν, B ± (h_m/2) ν of each link against the ground and the
//            boxes' faces; a box's top corner inside a link's rectangle is pushed out through the
//            nearer long face (the chain's two end faces too).
// Broad phase: a box is tested only when the robot's extent, grown by the thickness, reaches it;
// a link's corners against the ground only when the link reaches down to it.

Plant::ShapePoint Plant::on_point(int k, const Vec2& r) const {
  const int N = model_.N();
  ShapePoint c;
  c.ka = c.kb = k;
  c.r = r;
  if (k % 2 == 1) {
    c.la = c.lb = (k - 1) / 2;  // a COM
  } else if (k == 0) {
    c.la = c.lb = 0;
  } else if (k == 2 * N) {
    c.la = c.lb = N - 1;
  } else {  // joint k/2 − 1 between links k/2 − 1 and k/2
    c.la = k / 2 - 1;
    c.lb = k / 2;
    c.w = 0.5;
  }
  return c;
}

void Plant::add_shape_contact(const ShapePoint& c, const Vec2& n, double depth, double mu,
                              const VectorXd& v, Eigen::Ref<VectorXd> Q, ImplicitTerms* jac,
                              ContactReport* report) {
  const Model& m = model_;
  const Ground& g = scene_.ground;
  const Vec2 t(n.y(), -n.x());
  Vec2 vel = point_velocity(m, data_, v, c.ka);
  if (c.s > 0) vel = (1 - c.s) * vel + c.s * point_velocity(m, data_, v, c.kb);
  const double omega = (1 - c.w) * data_.theta_dot(c.la) + c.w * data_.theta_dot(c.lb);
  vel += omega * Vec2(-c.r.y(), c.r.x());
  const double depth_rate = -vel.dot(n);
  const double fN = std::max(g.k * depth + g.d * depth_rate, 0.0);
  const double vt = vel.dot(t);
  double dfdv = 0.0;
  // The paper's option: friction only where a COM touches (capsule: the COMs' spheres).
  const bool with_friction = !g.friction_at_com || (c.s == 0 && c.ka % 2 == 1);
  const double fT = with_friction ? friction(mu, fN, vt, 0.0, -1, dfdv) : 0.0;
  const Vec2 f = fN * n + fT * t;
  if (c.s > 0) {
    add_point_force(m, data_, c.ka, (1 - c.s) * f, Q);
    add_point_force(m, data_, c.kb, c.s * f, Q);
  } else {
    add_point_force(m, data_, c.ka, f, Q);
  }
  const double tau = c.r.x() * f.y() - c.r.y() * f.x();  // r × f
  if (c.w < 1) add_link_torque(m, c.la, (1 - c.w) * tau, Q);
  if (c.w > 0) add_link_torque(m, c.lb, c.w * tau, Q);
  if (report) {
    report->max_penetration = std::max(report->max_penetration, depth);
    report->elastic_energy += 0.5 * g.k * depth * depth;
    if (fN > 0) ++report->active;
    const int k = c.s > 0.5 ? c.kb : c.ka;
    report->f_normal(k) += fN;
    report->f_tangent(k) += fT;
  }
  Vec2 fq;
  if (jac && fN > 0 && add_signature(c.ka, c.kb, dfdv, fT, n, vel, fN, jac, fq)) {
    if (fq.allFinite()) {  // D_q v as a force at the contact point (add_contact)
      if (c.s > 0) {
        add_point_force(m, data_, c.ka, (1 - c.s) * fq, jac->dFdq_v);
        add_point_force(m, data_, c.kb, c.s * fq, jac->dFdq_v);
      } else {
        add_point_force(m, data_, c.ka, fq, jac->dFdq_v);
      }
      const double tq = c.r.x() * fq.y() - c.r.y() * fq.x();
      if (c.w < 1) add_link_torque(m, c.la, (1 - c.w) * tq, jac->dFdq_v);
      if (c.w > 0) add_link_torque(m, c.lb, c.w * tq, jac->dFdq_v);
    }
  } else if (jac && fN > 0) {
    point_jacobian(m, data_, c.ka, Ja_);
    if (c.s > 0) {
      point_jacobian(m, data_, c.kb, Jb_);
      Ja_ = (1 - c.s) * Ja_ + c.s * Jb_;
    }
    // The lever: ∂(r)/∂q = J r · ∂θ/∂q, θ_i depending on α_i … α_{N−2} and θ_N (columns i … N−1).
    const double rx = -c.r.y(), rz = c.r.x();
    for (int col = std::min(c.la, c.lb); col < m.N(); ++col) {
      const double w = (col >= c.la ? 1 - c.w : 0.0) + (col >= c.lb ? c.w : 0.0);
      Ja_(0, col) += w * rx;
      Ja_(1, col) += w * rz;
    }
    add_contact_jacobian(n, fN, fT, dfdv, vt, mu, with_friction, v, jac);
  }
}

void Plant::shape_contacts(const VectorXd& v, Eigen::Ref<VectorXd> Q, ImplicitTerms* jac,
                           ContactReport* report) {
  const Model& m = model_;
  const Params& p = m.params();
  const Ground& g = scene_.ground;
  const int N = m.N(), P = m.points();
  const bool capsule = p.link_shape == LinkShape::kCapsule;
  const double r = p.link_radius, hh = p.half_thickness(), len = 2.0 * p.l;
  auto pos = [&](int k) { return Vec2(pts_x_(k), pts_z_(k)); };
  auto axis = [&](int i) { return Vec2(data_.cos_t(i), data_.sin_t(i)); };
  auto normal = [&](int i) { return Vec2(-data_.sin_t(i), data_.cos_t(i)); };
  // A box link's corner c (0 … 3) of link i: body point and lever.
  auto corner_of = [&](int i, int c, int& k, Vec2& lever) {
    k = c < 2 ? 2 * i : 2 * i + 2;
    lever = (c % 2 == 0 ? hh : -hh) * normal(i);
  };
  double z_min = 1e300;
  for (int k = 0; k < P; ++k) {
    x_min_ = std::min(x_min_, pts_x_(k));
    x_max_ = std::max(x_max_, pts_x_(k));
    z_min = std::min(z_min, pts_z_(k));
  }
  x_min_ -= hh;
  x_max_ += hh;
  z_min -= hh;

  // Ground: the capsule's spheres, or the box links' corners.
  if (scene_.ground_on && z_min < g.z) {
    if (capsule) {
      for (int k = 0; k < P; ++k) {
        const double depth = g.z - (pts_z_(k) - r);
        if (depth > 0)
          add_shape_contact(on_point(k, Vec2(0, -r)), Vec2(0, 1), depth, mu_at(pts_x_(k)), v, Q, jac, report);
      }
    } else {
      for (int i = 0; i < N; ++i) {
        if (std::min(pts_z_(2 * i), pts_z_(2 * i + 2)) - hh >= g.z) continue;  // broad phase
        for (int c = 0; c < 4; ++c) {
          int k;
          Vec2 lever;
          corner_of(i, c, k, lever);
          const Vec2 x = pos(k) + lever;
          const double depth = g.z - x.y();
          if (depth > 0) {
            ShapePoint sp;
            sp.ka = sp.kb = k;
            sp.r = lever;
            sp.la = sp.lb = i;
            add_shape_contact(sp, Vec2(0, 1), depth, mu_at(x.x()), v, Q, jac, report);
          }
        }
      }
    }
  }

  for (const Box& b : scene_.boxes) {
    const double x0 = b.x_near, x1 = b.x_near + b.width, z0 = g.z, z1 = g.z + b.height;
    if (x_max_ < x0 || x_min_ > x1 || z_min > z1) continue;  // broad phase
    const double edge_mu = std::isnan(b.edge_mu) ? b.mu : b.edge_mu;
    const double cap = 0.5 * std::min(b.width, b.height);
    const Vec2 centre(0.5 * (x0 + x1), 0.5 * (z0 + z1));
    const Vec2 corners[2] = {Vec2(x0, z1), Vec2(x1, z1)};
    // A point inside the box: out through the nearest face (depth, outward normal).
    auto inside = [&](const Vec2& x, double& depth, Vec2& n) {
      if (x.x() <= x0 || x.x() >= x1 || x.y() >= z1 || x.y() <= z0 - 1e-9) return false;
      const double d_top = z1 - x.y(), d_left = x.x() - x0, d_right = x1 - x.x();
      n = Vec2(0, 1);
      depth = d_top;
      if (d_left < depth) depth = d_left, n = Vec2(-1, 0);
      if (d_right < depth) depth = d_right, n = Vec2(1, 0);
      return true;
    };
    if (capsule) {
      for (int k = 0; k < P; ++k) {
        const Vec2 a = pos(k);
        if (a.x() < x0 - r || a.x() > x1 + r || a.y() > z1 + r) continue;
        double depth;
        Vec2 n;
        if (inside(a, depth, n)) {
          add_shape_contact(on_point(k, -r * n), n, depth + r, b.mu, v, Q, jac, report);
          continue;
        }
        if (a.y() < z0) continue;  // below the ground: the ground's
        // The step's nearest point (its faces run down into the ground).
        const Vec2 c(std::clamp(a.x(), x0, x1), std::min(a.y(), z1));
        const Vec2 d = a - c;
        const double dist = d.norm();
        if (!(dist < r) || dist == 0.0) continue;
        n = d / dist;
        const bool at_corner = c.y() == z1 && (c.x() == x0 || c.x() == x1);
        add_shape_contact(on_point(k, -r * n), n, r - dist, at_corner && b.corner_contact ? edge_mu : b.mu, v,
                          Q, jac, report);
      }
      if (!b.corner_contact) continue;
      // The top corners against each link's capsule: r minus the distance from the corner to the
      // axis segment (its end caps included, so the depth is continuous along the chain).
      for (const Vec2& c : corners) {
        for (int i = 0; i < N; ++i) {
          const Vec2 A = pos(2 * i), B = pos(2 * i + 2);
          // Broad phase: the corner is at most max(r, cap) off the axis when it counts.
          const double reach = std::max(r, cap);
          if (c.x() < std::min(A.x(), B.x()) - reach || c.x() > std::max(A.x(), B.x()) + reach ||
              c.y() < std::min(A.y(), B.y()) - reach || c.y() > std::max(A.y(), B.y()) + reach)
            continue;
          const Vec2 ab = B - A;
          const double len2 = ab.squaredNorm();
          const double s = (c - A).dot(ab) / len2;
          ShapePoint sp;
          sp.la = sp.lb = i;
          Vec2 n;
          double depth;
          if (s > 0.0 && s < 1.0) {
            n = Vec2(-ab.y(), ab.x()) / std::sqrt(len2);
            if (n.dot(c - centre) < 0) n = -n;  // away from the box interior
            const double past = (c - A).dot(n);  // how far the axis is past the corner
            if (past + r <= 0 || past > cap) continue;
            depth = past + r;
            sp.ka = 2 * i;
            sp.kb = 2 * i + 2;
            sp.s = s;
          } else {  // an end's cap
            sp.ka = sp.kb = s <= 0.0 ? 2 * i : 2 * i + 2;
            const Vec2 e = pos(sp.ka);
            if (e.x() > x0 && e.x() < x1 && e.y() < z1) continue;  // inside: its sphere's face contact
            const Vec2 d = e - c;
            const double dist = d.norm();
            if (!(dist < r) || dist == 0.0) continue;
            n = d / dist;
            depth = r - dist;
          }
          sp.r = -r * n;
          add_shape_contact(sp, n, depth, edge_mu, v, Q, jac, report);
        }
      }
      continue;
    }
    // Box links: their corners against the box's faces, the box's corners against their faces.
    for (int i = 0; i < N; ++i) {
      for (int cc = 0; cc < 4; ++cc) {
        int k;
        Vec2 lever;
        corner_of(i, cc, k, lever);
        double depth;
        Vec2 n;
        if (!inside(pos(k) + lever, depth, n)) continue;
        ShapePoint sp;
        sp.ka = sp.kb = k;
        sp.r = lever;
        sp.la = sp.lb = i;
        add_shape_contact(sp, n, depth, b.mu, v, Q, jac, report);
      }
    }
    if (!b.corner_contact) continue;
    for (const Vec2& c : corners) {
      for (int i = 0; i < N; ++i) {
        const Vec2 A = pos(2 * i), u = axis(i), nu = normal(i);
        const Vec2 rel = c - A;
        const double s = rel.dot(u), nb = rel.dot(nu);
        if (s <= 0.0 || s >= len || std::abs(nb) >= hh) continue;
        // Out through the nearer long face (the link moves away from the corner) …
        double depth = hh - std::abs(nb);
        Vec2 n = nb >= 0 ? Vec2(-nu) : Vec2(nu);
        // … or the chain's end faces.
        if (i == 0 && s < depth) depth = s, n = u;
        if (i == N - 1 && len - s < depth) depth = len - s, n = -u;
        ShapePoint sp;
        sp.ka = 2 * i;
        sp.kb = 2 * i + 2;
        sp.s = s / len;
        sp.r = nb * nu;
        sp.la = sp.lb = i;
        add_shape_contact(sp, n, depth, edge_mu, v, Q, jac, report);
      }
    }
  }
}

void Plant::motor_torques(const VectorXd& q, const VectorXd& v, Eigen::Ref<VectorXd> u) const {
  const Model& m = model_;
  const int first = m.flexible() ? m.i_beta(0) : m.i_alpha(0);
  const double b = scene_.joint_friction_on ? scene_.joint_friction.motor_viscous : 0.0;
  const double lim = scene_.torque_limit_on ? scene_.torque_limit.u_max : 0.0;
  for (int j = 0; j < m.joints(); ++j) {
    const double beta = q(first + j), beta_dot = v(first + j);
    double uj = 0.0;
    if (!input_.torque_off)
      uj = module_law(input_.tau(j), input_.kp(j), input_.beta_ref(j), input_.kd(j), input_.beta_dot_ref(j),
                      beta, beta_dot);
    if (lim > 0) uj = std::clamp(uj, -lim, lim);
    // Injected faults: output gain, extra motor friction (healthy: × 1, + 0, bit-identical).
    u(j) = faults_.torque_gain(j) * uj - (b + faults_.motor_friction(j)) * beta_dot;
  }
}

void Plant::fault_forces(const VectorXd& q, Eigen::Ref<VectorXd> Q, ImplicitTerms* jac) const {
  const Model& m = model_;
  for (int j = 0; j < m.joints(); ++j) {
    const int a = m.i_alpha(j);
    // Joint load: a link-side torque between links j and j+1 acts on α_j alone.
    if (faults_.joint_load(j) != 0.0) Q(a) += faults_.joint_load(j);
    // Spring stiffness change: the extra spring (s − 1) K between β_j and α_j.
    const double dK = (faults_.spring_scale(j) - 1.0) * m.K()(j);
    if (!m.flexible() || dK == 0.0) continue;
    const int b = m.i_beta(j);
    const double f = dK * (q(b) - q(a));
    Q(b) -= f;
    Q(a) += f;
    if (jac) {
      MatrixXd& D = jac->dq_in_dv > 0 ? jac->dFdv : jac->dFdq;
      const double k = jac->dq_in_dv > 0 ? jac->dq_in_dv * dK : dK;
      D(a, a) -= k;
      D(b, b) -= k;
      D(a, b) += k;
      D(b, a) += k;
    }
  }
}

bool Plant::acceleration(double, const VectorXd& q, const VectorXd& v, VectorXd& a) {
  const Model& m = model_;
  update_kinematics(m, data_, q, v);
  motor_torques(q, v, u_);
  Q_.setZero();
  contact_forces(q, v, Q_, nullptr, nullptr);
  fault_forces(q, Q_, nullptr);
  if (a.size() != m.nq()) a.resize(m.nq());  // once: integrators pass sized vectors
  return solve_forward_dynamics(m, data_, q, v, u_, Q_, a, solver_);
}

bool Plant::implicit_terms(double, const VectorXd& q, const VectorXd& v, ImplicitTerms& out) {
  const Model& m = model_;
  update_kinematics(m, data_, q, v);
  motor_torques(q, v, u_);
  // ∂F/∂q's terms go to dFdq, or scaled by s into dFdv (ImplicitTerms::dq_in_dv).
  const double s = out.dq_in_dv;
  MatrixXd& Dq = s > 0 ? out.dFdv : out.dFdq;
  const double sq = s > 0 ? s : 1.0;
  const bool jac = out.with_jacobian;
  if (jac && !(s > 0)) out.dFdq.setZero();
  if (jac) out.dFdv.setZero();
  const bool dq_v = s > 0 && out.dFdq_v.size() > 0;
  if (dq_v) out.dFdq_v.setZero();
  Q_.setZero();
  // Without the Jacobian the contacts still run their Jacobian block when D_q v is asked for.
  out.signature = 0;
  contact_forces(q, v, Q_, &out, nullptr);
  fault_forces(q, Q_, jac ? &out : nullptr);
  if (out.with_mass) {
    compute_mass_matrix(m, data_, out.check_mass);
    if (out.check_mass && !data_.mass_valid) return false;
    out.M = data_.M;
  }
  compute_bias(m, data_, q);
  const int first = m.flexible() ? m.i_beta(0) : 0;
  out.n_diag = m.flexible() ? m.joints() : 0;  // the motor block of M, dFdq, dFdv is diagonal
  out.F = Q_ - data_.bias;
  out.F.segment(first, m.joints()) += u_;
  // Springs: F = −K_T q.
  if (m.flexible()) {
    for (int j = 0; j < m.joints(); ++j) {
      const double K = sq * m.K()(j);
      const int a = m.i_alpha(j), b = m.i_beta(j);
      if (jac) {
        Dq(a, a) -= K;
        Dq(b, b) -= K;
        Dq(a, b) += K;
        Dq(b, a) += K;
      }
      if (dq_v) {  // the spring and its injected change (fault_forces): −K_j (1 + (scale − 1)) …
        const double Kt = faults_.spring_scale(j) * m.K()(j), dv = v(b) - v(a);
        out.dFdq_v(a) += Kt * dv;
        out.dFdq_v(b) -= Kt * dv;
      }
    }
  }
  // Module PD and joint friction (zero slope where the torque limit is active), through the
  // injected output gain and extra friction (healthy: × 1, + 0).
  const double bm = scene_.joint_friction_on ? scene_.joint_friction.motor_viscous : 0.0;
  const double lim = scene_.torque_limit_on ? scene_.torque_limit.u_max : 0.0;
  for (int j = 0; j < m.joints(); ++j) {
    const int r = first + j;
    const double bj = bm + faults_.motor_friction(j);
    const double gain = faults_.torque_gain(j);
    // The limited law value: undo the gain and friction of u_ (exact when the gain is 1).
    const double law = gain == 1.0 ? u_(j) + bj * v(r) : (u_(j) + bj * v(r)) / gain;
    const bool saturated = lim > 0 && gain != 0.0 && std::abs(law) >= lim;
    if (!input_.torque_off && !saturated) {
      if (dq_v) out.dFdq_v(r) -= gain * input_.kp(j) * v(r);
      if (jac) {
        Dq(r, r) -= sq * gain * input_.kp(j);
        out.dFdv(r, r) -= gain * input_.kd(j);
      }
    }
    if (jac) out.dFdv(r, r) -= bj;
  }
  return true;
}

void Plant::after_step(const VectorXd& q, const VectorXd& v) {
  if (!scene_.ground_on || scene_.ground.law != FrictionLaw::kStickSlip) return;
  const Model& m = model_;
  const Ground& g = scene_.ground;
  update_kinematics(m, data_, q, v);
  for (int k = 0; k < m.points(); ++k) {
    const Vec2 p = point_position(m, data_, q, k);
    const size_t s = static_cast<size_t>(k);
    if (p.y() >= g.z) {
      anchored_[s] = 0;
      continue;
    }
    const Vec2 vel = point_velocity(m, data_, v, k);
    const double fN = std::max(g.k * (g.z - p.y()) - g.d * vel.y(), 0.0);
    if (!anchored_[s]) {
      anchored_[s] = 1;
      anchor_(k) = p.x();
      continue;
    }
    // Slipping: drag the anchor so the spring force stays at the friction limit.
    const double lim = mu_at(p.x()) * fN / g.k_t;
    const double dx = p.x() - anchor_(k);
    if (dx > lim) anchor_(k) = p.x() - lim;
    if (dx < -lim) anchor_(k) = p.x() + lim;
  }
}

void Plant::measure(const VectorXd& q, const VectorXd& v, Measurement& out) {
  const Model& m = model_;
  const SensorNoise& sn = scene_.sensor_noise;
  std::normal_distribution<double> unit(0.0, 1.0);
  auto quantize = [](double x, double step) { return step > 0 ? step * std::round(x / step) : x; };
  for (int j = 0; j < m.joints(); ++j) {
    const double alpha = q(m.i_alpha(j));
    const double beta = m.flexible() ? q(m.i_beta(j)) : alpha;
    const double beta_dot = m.flexible() ? v(m.i_beta(j)) : v(m.i_alpha(j));
    double b = beta, bd = beta_dot, def = beta - alpha;
    if (scene_.sensor_noise_on) {
      b = quantize(b + sn.beta_sigma * unit(rng_), sn.encoder_resolution);
      bd += sn.beta_dot_sigma * unit(rng_);
      def = quantize(def + sn.deflection_sigma * unit(rng_), sn.deflection_resolution);
    }
    out.beta(j) = b;
    out.beta_dot(j) = bd;
    out.deflection(j) = def;
  }
}

void Plant::report(const VectorXd& q, const VectorXd& v, ContactReport& out) {
  out.f_normal = VectorXd::Zero(model_.points());
  out.f_tangent = VectorXd::Zero(model_.points());
  out.max_penetration = 0.0;
  out.active = 0;
  out.elastic_energy = 0.0;
  update_kinematics(model_, data_, q, v);
  Q_.setZero();
  contact_forces(q, v, Q_, nullptr, &out);
}

double Plant::energy(const VectorXd& q, const VectorXd& v) {
  update_kinematics(model_, data_, q, v);
  compute_mass_matrix(model_, data_);
  return kinetic_energy(data_, v) + gravity_energy(model_, data_, q) + spring_energy(model_, q);
}

Simulation::Simulation(const Scene& scene) : Simulation(scene, scene.integrator) {}

Simulation::Simulation(const Scene& scene, const IntegratorOptions& integ)
    : plant_(scene), integ_(plant_.nq(), integ) {
  plant_.initial_state(q_, v_);
}

StepStatus Simulation::advance_to(double t_end) {
  if (is_adaptive(integ_.options().method)) {
    const StepStatus s = integ_.advance(plant_, t_, t_end, q_, v_);
    if (s == StepStatus::kOk) plant_.after_step(q_, v_);
    return s;
  }
  const double h = integ_.options().h;
  while (t_end - t_ > 1e-12 * std::max(1.0, std::abs(t_end))) {
    const double step = std::min(h, t_end - t_);
    const StepStatus s = integ_.step(plant_, t_, step, q_, v_);
    if (s != StepStatus::kOk) return s;
    t_ += step;
    plant_.after_step(q_, v_);
  }
  t_ = t_end;
  return StepStatus::kOk;
}

}  // namespace pedalwave::model
