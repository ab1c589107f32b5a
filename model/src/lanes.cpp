#include "pedalwave/model/lanes.hpp"

#include <immintrin.h>

#include <cmath>
#include <stdexcept>

namespace pedalwave::model {

namespace {
constexpr int kMaxWidth = 8;
constexpr int kMaxPatches = 8;
constexpr int kMaxBoxes = 8;
constexpr int kMaxPoints = 2 * kMaxLinks + 1;
}  // namespace

struct LanePlant::Constants {
  int N = 0, P = 0;
  double c[kMaxPoints][kMaxLinks] = {};  // point coefficients c_ki
  double W[kMaxLinks][kMaxLinks] = {};
  double s[kMaxLinks] = {};
  double K[kMaxLinks] = {};
  double I_l = 0, m_total = 0, g = 0;
  double l = 0;  // half a link's length [m]: from one body point to the next
  bool ground_on = false;
  double gz = 0, gk = 0, gd = 0, gmu = 0, v_s = 0;
  int n_patches = 0;
  double patch_x[kMaxPatches] = {}, patch_mu[kMaxPatches] = {};
  struct BoxC {
    double x0, x1, z0, z1, xc, zc, cap, mu, edge_mu;
    bool corners;
  };
  int n_boxes = 0;
  BoxC box[kMaxBoxes] = {};
  // M_spin's nonzero entries (row, column, value): the body block's first (n_spin_body of them,
  // added to Mb), then the motor rows' and columns' (the Newton residual's).
  int n_spin = 0, n_spin_body = 0;
  int spin_r[(2 * kMaxLinks + 1) * (2 * kMaxLinks + 1)] = {}, spin_c[(2 * kMaxLinks + 1) * (2 * kMaxLinks + 1)] = {};
  double spin_v[(2 * kMaxLinks + 1) * (2 * kMaxLinks + 1)] = {};
  double spin_dense[(2 * kMaxLinks + 1) * (2 * kMaxLinks + 1)] = {};  // M_spin, row-major
  int nq = 0, nq1 = 0;
};

struct LanePlant::Workspace {
  alignas(64) double td[kMaxLinks * kMaxWidth];  // θ̇
  alignas(64) double sn[kMaxLinks * kMaxWidth];
  alignas(64) double cs[kMaxLinks * kMaxWidth];
  alignas(64) double x[kMaxPoints * kMaxWidth];  // body points
  alignas(64) double z[kMaxPoints * kMaxWidth];
  alignas(64) double vx[kMaxPoints * kMaxWidth];
  alignas(64) double vz[kMaxPoints * kMaxWidth];
  alignas(64) double fx[kMaxPoints * kMaxWidth];  // contact force per point
  alignas(64) double fz[kMaxPoints * kMaxWidth];
  alignas(64) double gx[kMaxPoints * kMaxWidth];  // D_q v's force per point
  alignas(64) double gz[kMaxPoints * kMaxWidth];
  std::uint64_t sig[kMaxWidth];
  alignas(64) double y[(2 * kMaxLinks + 1) * kMaxWidth];  // a solve's permuted right-hand side
  alignas(64) double A[(kMaxLinks + 2) * (kMaxLinks + 2) * kMaxWidth];  // a factorization's Schur complement
  // The Jacobian's contacts not yet added to its block (the kernel's jacobian_flush): each four
  // rows of nq1 entries.
  static constexpr int kContacts = 32;
  int nj = 0;
  alignas(64) double jl[kContacts * 4 * (kMaxLinks + 2) * kMaxWidth];
};

namespace {

#define PW_LANES_NS avx512
#define PW_LANES_W 8
#define PW_LANES_TARGET __attribute__((target("avx512f,avx512dq,avx2,fma")))
#define PW_LANES_SIN _ZGVeN8v_sin
#define PW_LANES_COS _ZGVeN8v_cos
#define PW_LANES_NATIVE __m512d
#define PW_LANES_ANY(m) (_mm512_test_epi64_mask((__m512i)(m), (__m512i)(m)) != 0)
#define PW_LANES_SQRT(x) _mm512_mask_sqrt_pd((x), 0xFF, (x))  // _mm512_sqrt_pd: GCC 12 -Wmaybe-uninitialized in its header
#include "lanes_kernel.inc"  // undefines the PW_LANES_ macros

#define PW_LANES_NS avx2
#define PW_LANES_W 4
#define PW_LANES_TARGET __attribute__((target("avx2,fma")))
#define PW_LANES_SIN _ZGVdN4v_sin
#define PW_LANES_COS _ZGVdN4v_cos
#define PW_LANES_NATIVE __m256d
#define PW_LANES_ANY(m) (_mm256_testz_si256((__m256i)(m), (__m256i)(m)) == 0)
#define PW_LANES_SQRT(x) _mm256_sqrt_pd(x)
#include "lanes_kernel.inc"  // undefines the PW_LANES_ macros

}  // namespace

std::string LanePlant::unsupported(const Scene& s) {
  const Params& p = s.robot;
  if (p.link_shape != LinkShape::kSegment) return "link_shape is not segment";
  if (p.joints != JointModel::kFlexible) return "the joints are not flexible";
  if (p.N < 2 || p.N > kMaxLinks) return "N is outside 2 … " + std::to_string(kMaxLinks);
  if (s.ground.law != FrictionLaw::kRegularized) return "the ground's friction law is not regularized";
  if (s.ground.friction_at_com) return "friction_at_com is on";
  if (s.ground.patches.size() > static_cast<size_t>(kMaxPatches))
    return "more than " + std::to_string(kMaxPatches) + " surface patches";
  if (s.boxes.size() > static_cast<size_t>(kMaxBoxes)) return "more than " + std::to_string(kMaxBoxes) + " boxes";
  if (s.joint_friction_on) return "joint friction is on";
  if (s.torque_limit_on) return "a torque limit is on";
  if (!s.faults.empty()) return "the scene injects faults";
  return "";
}

int LanePlant::machine_width() {
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512dq")) return 8;
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return 4;
  return 0;
}

LanePlant::LanePlant(const Plant& plant, int width)
    : width_(width), c_(std::make_unique<Constants>()), w_(std::make_unique<Workspace>()) {
  const Scene& sc = plant.scene();
  if (const std::string why = unsupported(sc); !why.empty())
    throw std::invalid_argument("LanePlant: scene '" + sc.name + "': " + why);
  const int mw = machine_width();
  if (!((width == 8 || width == 4) && width <= mw))
    throw std::invalid_argument("LanePlant: width " + std::to_string(width) + " is not one this machine runs (its widest: " +
                                std::to_string(mw) + "; 8 needs AVX-512 F and DQ, 4 AVX2 and FMA)");
  const Model& m = plant.model();
  Constants& c = *c_;
  c.N = m.N();
  c.P = m.points();
  nq_ = m.nq();
  nq1_ = m.nq1();
  joints_ = m.joints();
  for (int k = 0; k < c.P; ++k)
    for (int i = 0; i < c.N; ++i) c.c[k][i] = m.point_coeff()(k, i);
  for (int k = 0; k < c.N; ++k)
    for (int l = 0; l < c.N; ++l) c.W[k][l] = m.W()(k, l);
  for (int i = 0; i < c.N; ++i) c.s[i] = m.s()(i);
  for (int j = 0; j < m.joints(); ++j) c.K[j] = m.K()(j);
  c.I_l = m.params().I_l;
  c.l = m.params().l;
  c.m_total = m.total_mass();
  c.g = m.params().g;
  const Ground& g = sc.ground;
  c.ground_on = sc.ground_on;
  c.gz = g.z;
  c.gk = g.k;
  c.gd = g.d;
  c.gmu = g.mu;
  c.v_s = g.v_s;
  c.n_patches = static_cast<int>(g.patches.size());
  for (int i = 0; i < c.n_patches; ++i) {
    c.patch_x[i] = g.patches[static_cast<size_t>(i)].x_begin;
    c.patch_mu[i] = g.patches[static_cast<size_t>(i)].mu;
  }
  c.nq = m.nq();
  c.nq1 = m.nq1();
  for (int body = 1; body >= 0; --body)
    for (int col = 0; col < m.nq(); ++col)
      for (int r = 0; r < m.nq(); ++r) {
        c.spin_dense[r * m.nq() + col] = m.M_spin()(r, col);
        if (m.M_spin()(r, col) == 0.0 || (r < m.nq1() && col < m.nq1()) != (body == 1)) continue;
        c.spin_r[c.n_spin] = r;
        c.spin_c[c.n_spin] = col;
        c.spin_v[c.n_spin] = m.M_spin()(r, col);
        ++c.n_spin;
        c.n_spin_body += body;
      }
  c.n_boxes = static_cast<int>(sc.boxes.size());
  for (int i = 0; i < c.n_boxes; ++i) {
    const Box& b = sc.boxes[static_cast<size_t>(i)];
    Constants::BoxC& o = c.box[i];
    o.x0 = b.x_near;
    o.x1 = b.x_near + b.width;
    o.z0 = g.z;
    o.z1 = g.z + b.height;
    o.xc = 0.5 * (o.x0 + o.x1);
    o.zc = 0.5 * (o.z0 + o.z1);
    o.cap = 0.5 * std::min(b.width, b.height);
    o.mu = b.mu;
    o.edge_mu = std::isnan(b.edge_mu) ? b.mu : b.edge_mu;
    o.corners = b.corner_contact;
  }
}

LanePlant::~LanePlant() = default;

LaneTerms LanePlant::make_terms() const {
  LaneTerms t;
  t.F.assign(static_cast<size_t>(nq_ * width_), 0.0);
  t.Mb.assign(static_cast<size_t>(nq1_ * nq1_ * width_), 0.0);
  t.dFdq_v.assign(static_cast<size_t>(nq_ * width_), 0.0);
  t.D.assign(static_cast<size_t>(nq_ * nq_ * width_), 0.0);
  t.signature.assign(static_cast<size_t>(width_), 0);
  return t;
}

LaneInputs LanePlant::make_inputs() const {
  LaneInputs in;
  for (auto* x : {&in.tau, &in.kp, &in.beta_ref, &in.kd, &in.beta_dot_ref})
    x->assign(static_cast<size_t>(joints_ * width_), 0.0);
  return in;
}

void LanePlant::evaluate(const double* q, const double* v, const LaneInputs& in, bool with_mass, LaneTerms& out,
                         double jacobian, const double* v_start) {
  const double* const inputs[5] = {in.tau.data(), in.kp.data(), in.beta_ref.data(), in.kd.data(),
                                   in.beta_dot_ref.data()};
  if (width_ == 8) {
    const avx512::Jac jac{with_mass, jacobian, out.D.data(), nq_, v_start};
    avx512::evaluate(*c_, *w_, q, v, inputs, with_mass, jac, out.F.data(), out.Mb.data(), out.dFdq_v.data(),
                     out.signature.data());
  } else {
    const avx2::Jac jac{with_mass, jacobian, out.D.data(), nq_, v_start};
    avx2::evaluate(*c_, *w_, q, v, inputs, with_mass, jac, out.F.data(), out.Mb.data(), out.dFdq_v.data(),
                   out.signature.data());
  }
}

void LanePlant::solve(const LaneLU& lu, double* x) const {
  if (width_ == 8)
    avx512::solve(lu, *w_, x);
  else
    avx2::solve(lu, *w_, x);
}

void LanePlant::residual(const std::vector<double>& Mb, const double* x, const double* F0, const double* F1,
                         double b, double a, double* r) const {
  if (width_ == 8)
    avx512::residual(*c_, Mb.data(), x, F0, F1, b, a, r);
  else
    avx2::residual(*c_, Mb.data(), x, F0, F1, b, a, r);
}

LaneLU::LaneLU(int n_, int nd_, int width_)
    : n(n_), nd(nd_), width(width_), A(static_cast<size_t>(n_ * n_ * width_), 0.0),
      d_inv(static_cast<size_t>(nd_ * width_), 0.0), u_inv(static_cast<size_t>((n_ - nd_) * width_), 0.0),
      perm(static_cast<size_t>((n_ - nd_) * width_), 0),
      Z(static_cast<size_t>((n_ - nd_) * (n_ - nd_) * width_), 0.0),
      key(static_cast<size_t>(3 * nd_ * width_), 0.0), motor_ok(static_cast<size_t>(width_), 0.0) {
  for (int k = 0; k < n - nd; ++k)
    for (int l = 0; l < width; ++l) perm[static_cast<size_t>(k * width + l)] = k;
}

void LanePlant::factor(const std::vector<double>& Mb, const std::vector<double>& D, double a, const char* need,
                       LaneLU& out, char* ok) {
  if (width_ == 8)
    avx512::factor(*c_, *w_, Mb.data(), D.data(), a, need, out, ok);
  else
    avx2::factor(*c_, *w_, Mb.data(), D.data(), a, need, out, ok);
}

}  // namespace pedalwave::model
