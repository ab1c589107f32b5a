// O(N) forward dynamics: Featherstone's articulated-body algorithm (ABA) for the planar chain with a
// floating base, the SEA rotors as geared bodies. Same equations as the dense solver
// (model-spec.md §4, §5; dynamics.hpp), the same q̈ to rounding (tests/model/recursive_test.cpp).
//
// Why this and not a structured solve of M: in q the body block Tᵀ Mz T is dense (p, the mean of
// the link COMs, couples every link with every other), so an exact structured solve needs the
// semiseparable structure of W plus rank-2 corrections and an O(N) Coriolis rewrite — more algebra,
// more to get wrong. The ABA works on the tree (link N-1 the floating root, α_i the revolute joint
// from link i+1 to link i) where everything is local, gives gravity and Coriolis by itself, and
// needs only a change of coordinates at the two ends:
//   - q's root coordinates are (θ_N, p), p = (1/N) Σ_i g_i the mean link COM g_i, not a point of a
//     body. Input: a generalized force Q_p on p does the virtual work Q_p·δp = Σ_i (Q_p/N)·δg_i,
//     i.e. it is the force Q_p/N applied at every link COM; Q_θN is a couple on the root link
//     (θ_N moves with α and p held: in the tree, with α and the root COM held, the remaining
//     virtual work Q_p·δp is already carried by those forces). Output: p̈ = (1/N) Σ_i g̈_i.
//     Velocities: the root COM velocity V is chosen so that the mean of the COM velocities is ṗ.
//   - Flexible rotor j (spin θ̇_j − n β̇_j, a massless disc I_r on link j): a leaf on a joint of
//     rate −n β̇_j. Its articulated inertia is I_r − I_r n² I_r / (n² I_r) = 0 (exactly: it is not
//     formed), its bias on link j is the couple −τ_β/n, and β̈_j = τ_β / (n² I_r) + θ̈_j / n, with
//     τ_β = u_j + Q_β − K_j (β_j − α_j). (The dense solver's Schur complement of the motor block.)
//   - Rigid, exact limit (spin θ̇_j − n α̇_j = θ̇_{j+1} + (1−n) α̇_j): joint α_j drives link j at
//     rate 1 and the rotor at rate (1−n): D_j = Sᵀ I^A S + (1−n)² I_r, U_j = I^A S + (1−n) I_r e_1,
//     the rotor's I_r e_1 e_1ᵀ joins the parent's inertia. Paper variant: I_r on link j's rotation.
// Planar spatial algebra, vectors [rotation; x; z] in world-aligned frames at each link's reference
// point o_i (its joint to the parent; the root: its COM), so the joint axis is S = e_1 and every
// lever arm is a link length (no large moments about a far origin). With J(x, z) = (−z, x):
//   point mass m at r from o:  I = m [[|r|², (J r)ᵀ], [J r, 1₂]];  link: + I_l on I₀₀
//   force F at r:              f = (F·J r, F);        v ×* f = ((J v_o)·F, ω J F)
//   velocity product:          c_i = v_{i+1} × S α̇_i = (0, −α̇_i J v_o)   (at o_i)
//   shift from o_A to o_B, k = J(o_A − o_B):
//     motion a_A = (a₀, a_B + a₀ k);  force n_B = n_A + k·F;
//     inertia I₀₀ += 2 h·k + kᵀ M k, h += M k (M unchanged)
// Passes (each O(N), nothing allocated: the d.links slots):
//   1. root → tail: lever arms, θ̇, point velocities; p_i = v ×* I v − f_gravity − f_Q (bias).
//   2. tail → root: U = I^A S, D = Sᵀ I^A S, u = τ − Sᵀ p^A,
//        I^a = I^A − U Uᵀ / D,  p^a = p^A + I^a c + U u / D,  shifted onto the parent.
//   3. root: I^A a = −p^A (3×3 Cholesky); root → tail: a' = a_parent + c,
//        α̈ = (u − U·a') / D,  a = a' + S α̈;  COM accelerations g̈ = a_o + ω̇ J r + ω J ġ.
#include <cmath>

#include "pedalwave/model/dynamics.hpp"

namespace pedalwave::model {

bool recursive_forward_dynamics(const Model& m, Data& d, const Eigen::Ref<const VectorXd>& q,
                                const Eigen::Ref<const VectorXd>& qd,
                                const Eigen::Ref<const VectorXd>& u,
                                const Eigen::Ref<const VectorXd>& Q, Eigen::Ref<VectorXd> qdd) {
  const Params& p = m.params();
  const int N = m.N(), root = N - 1;
  const double l = p.l, ml = p.m_l, Il = p.I_l, Ir = p.I_r, n = p.n, g = p.g;
  const bool flexible = m.flexible();
  const bool geared = !flexible && p.rigid_variant == RigidVariant::kExactLimit;
  const bool paper = !flexible && p.rigid_variant == RigidVariant::kPaper;
  const bool has_u = u.size() > 0, has_Q = Q.size() > 0;
  const double Qpx = has_Q ? Q(m.i_px()) / N : 0.0, Qpz = has_Q ? Q(m.i_pz()) / N : 0.0;
  RecursiveLink* L = d.links.data();

  // ---- 1. Kinematics of the tree, root → tail (root COM velocity 0 first, shifted below).
  {
    RecursiveLink& R = L[root];
    R.d[0] = R.d[1] = 0.0;
    R.r[0] = R.r[1] = 0.0;
    R.w = d.theta_dot(root);
    R.vo[0] = R.vo[1] = 0.0;
    R.vg[0] = R.vg[1] = 0.0;
  }
  double sx = 0.0, sz = 0.0;  // Σ COM velocities (relative)
  for (int i = root - 1; i >= 0; --i) {
    RecursiveLink& C = L[i];
    const RecursiveLink& P = L[i + 1];
    // o_i is the rear end of link i+1: 2l behind o_{i+1} (the root's COM: l behind).
    const double len = (i + 1 == root) ? l : 2.0 * l;
    C.d[0] = -len * d.cos_t(i + 1);
    C.d[1] = -len * d.sin_t(i + 1);
    C.r[0] = -l * d.cos_t(i);
    C.r[1] = -l * d.sin_t(i);
    C.w = d.theta_dot(i);
    // o_i moves with link i+1; the COM with link i.
    C.vo[0] = P.vo[0] - P.w * C.d[1];
    C.vo[1] = P.vo[1] + P.w * C.d[0];
    C.vg[0] = C.vo[0] - C.w * C.r[1];
    C.vg[1] = C.vo[1] + C.w * C.r[0];
    sx += C.vg[0];
    sz += C.vg[1];
  }
  // The root COM velocity V that makes the mean COM velocity ṗ.
  const double Vx = qd(m.i_px()) - sx / N, Vz = qd(m.i_pz()) - sz / N;

  // ---- Body inertias and bias forces, joint torques, velocity products.
  for (int i = 0; i < N; ++i) {
    RecursiveLink& B = L[i];
    B.vo[0] += Vx;
    B.vo[1] += Vz;
    B.vg[0] += Vx;
    B.vg[1] += Vz;
    const double mr = i < root ? p.m_r : 0.0;  // rotor j = i sits at o_i (the joint)
    const double rx = B.r[0], rz = B.r[1];
    const double jrx = -rz, jrz = rx;  // J r
    double* I = B.IA;
    I[0] = Il + ml * (rx * rx + rz * rz) + (paper && i < root ? Ir : 0.0);
    I[1] = ml * jrx;
    I[2] = ml * jrz;
    I[3] = ml + mr;
    I[4] = 0.0;
    I[5] = ml + mr;
    // Momentum h = I v, then the bias v ×* h.
    const double w = B.w, vx = B.vo[0], vz = B.vo[1];
    const double hx = I[1] * w + I[3] * vx, hz = I[2] * w + I[5] * vz;
    double* pA = B.pA;
    pA[0] = -vz * hx + vx * hz;  // (J v_o)·F
    pA[1] = -w * hz;             // ω J F
    pA[2] = w * hx;
    // Gravity (0, −m g) at the COM and at o_i; the Q_p share Q_p/N at the COM.
    pA[0] -= -ml * g * jrz + Qpx * jrx + Qpz * jrz;
    pA[1] -= Qpx;
    pA[2] -= -(ml + mr) * g + Qpz;
    if (i == root) {
      if (has_Q) pA[0] -= Q(m.i_theta_N());
      continue;
    }
    // Joint α_i: its torque, the rotor, and the velocity product c = −α̇ J v_o.
    const int ia = m.i_alpha(i);
    double tau = has_Q ? Q(ia) : 0.0;
    if (flexible) {
      const int ib = m.i_beta(i);
      const double spring = m.K()(i) * (q(ib) - q(ia));
      tau += spring;
      B.tau_b = (has_u ? u(i) : 0.0) + (has_Q ? Q(ib) : 0.0) - spring;
      pA[0] -= B.tau_b / n;  // the rotor's reaction on its stator
    } else if (has_u) {
      tau += u(i);
    }
    B.u = tau;  // τ; the − Sᵀ p^A part is taken in pass 2
    const double ad = qd(ia);
    B.c[0] = ad * vz;
    B.c[1] = -ad * vx;
  }

  // ---- 2. Articulated inertias, tail → root.
  const double gear = 1.0 - n;
  for (int i = 0; i < root; ++i) {
    RecursiveLink& B = L[i];
    double* I = B.IA;
    double* pA = B.pA;
    double U0 = I[0], U1 = I[1], U2 = I[2];
    double D = I[0];
    if (geared) {
      U0 += gear * Ir;
      D += gear * gear * Ir;
    }
    if (!(D > 0.0)) return false;  // also catches NaN
    const double Dinv = 1.0 / D;
    B.U[0] = U0;
    B.U[1] = U1;
    B.U[2] = U2;
    B.D_inv = Dinv;
    B.u -= pA[0];
    const double uD = B.u * Dinv;
    // I^a = I^A (+ rotor) − U Uᵀ / D
    double a0 = I[0] - U0 * U0 * Dinv + (geared ? Ir : 0.0);
    double a1 = I[1] - U0 * U1 * Dinv;
    double a2 = I[2] - U0 * U2 * Dinv;
    const double a3 = I[3] - U1 * U1 * Dinv;
    const double a4 = I[4] - U1 * U2 * Dinv;
    const double a5 = I[5] - U2 * U2 * Dinv;
    // p^a = p^A + I^a c + U u / D   (c = (0, c_x, c_z))
    double f0 = pA[0] + a1 * B.c[0] + a2 * B.c[1] + U0 * uD;
    const double f1 = pA[1] + a3 * B.c[0] + a4 * B.c[1] + U1 * uD;
    const double f2 = pA[2] + a4 * B.c[0] + a5 * B.c[1] + U2 * uD;
    // Shift from o_i to o_{i+1}: k = J d.
    const double kx = -B.d[1], kz = B.d[0];
    const double Mkx = a3 * kx + a4 * kz, Mkz = a4 * kx + a5 * kz;
    a0 += 2.0 * (a1 * kx + a2 * kz) + kx * Mkx + kz * Mkz;
    a1 += Mkx;
    a2 += Mkz;
    f0 += kx * f1 + kz * f2;
    RecursiveLink& P = L[i + 1];
    P.IA[0] += a0;
    P.IA[1] += a1;
    P.IA[2] += a2;
    P.IA[3] += a3;
    P.IA[4] += a4;
    P.IA[5] += a5;
    P.pA[0] += f0;
    P.pA[1] += f1;
    P.pA[2] += f2;
  }

  // ---- 3. The floating root: I^A a = −p^A by a 3×3 Cholesky.
  {
    RecursiveLink& R = L[root];
    const double* I = R.IA;
    const double l00 = I[0];
    if (!(l00 > 0.0)) return false;
    const double s0 = std::sqrt(l00);
    const double l10 = I[1] / s0, l20 = I[2] / s0;
    const double d1 = I[3] - l10 * l10;
    if (!(d1 > 0.0)) return false;
    const double s1 = std::sqrt(d1);
    const double l21 = (I[4] - l20 * l10) / s1;
    const double d2 = I[5] - l20 * l20 - l21 * l21;
    if (!(d2 > 0.0)) return false;
    const double s2 = std::sqrt(d2);
    const double y0 = -R.pA[0] / s0;
    const double y1 = (-R.pA[1] - l10 * y0) / s1;
    const double y2 = (-R.pA[2] - l20 * y0 - l21 * y1) / s2;
    R.a[2] = y2 / s2;
    R.a[1] = (y1 - l21 * R.a[2]) / s1;
    R.a[0] = (y0 - l10 * R.a[1] - l20 * R.a[2]) / s0;
  }
  // Root → tail: joint accelerations.
  for (int i = root - 1; i >= 0; --i) {
    RecursiveLink& B = L[i];
    const RecursiveLink& P = L[i + 1];
    const double kx = -B.d[1], kz = B.d[0];
    const double w0 = P.a[0];
    const double a1 = P.a[1] + w0 * kx + B.c[0];
    const double a2 = P.a[2] + w0 * kz + B.c[1];
    const double add = (B.u - B.U[0] * w0 - B.U[1] * a1 - B.U[2] * a2) * B.D_inv;
    B.a[0] = w0 + add;
    B.a[1] = a1;
    B.a[2] = a2;
    qdd(m.i_alpha(i)) = add;
  }
  qdd(m.i_theta_N()) = L[root].a[0];

  // ---- Outputs: p̈ the mean COM acceleration; β̈ from the rotors.
  double gx = 0.0, gz = 0.0;
  for (int i = 0; i < N; ++i) {
    const RecursiveLink& B = L[i];
    const double wd = B.a[0];
    gx += B.a[1] - wd * B.r[1] - B.w * B.vg[1];
    gz += B.a[2] + wd * B.r[0] + B.w * B.vg[0];
  }
  qdd(m.i_px()) = gx / N;
  qdd(m.i_pz()) = gz / N;
  if (flexible) {
    const double inv_n2Ir = 1.0 / (n * n * Ir);
    for (int j = 0; j < m.joints(); ++j)
      qdd(m.i_beta(j)) = L[j].tau_b * inv_n2Ir + L[j].a[0] / n;
  }
  return true;
}

}  // namespace pedalwave::model
