#include <cmath>
#include <stdexcept>

#include "pedalwave/model/lanes.hpp"

namespace pedalwave::model {

LaneStepper::LaneStepper(LanePlant& plant, const Plant& scalar, const IntegratorOptions& o)
    : plant_(plant), o_(o), W_(plant.width()), nq_(plant.nq()), n1_(plant.nq1()), J_(plant.joints()),
      M_spin_(scalar.model().M_spin()), t0_(plant.make_terms()), t1_(plant.make_terms()) {
  validate(o_);
  if (o_.method != Method::kImplicitContact)
    throw std::invalid_argument(std::string("LaneStepper: method ") + std::string(to_string(o_.method)) +
                                ": expected implicit_contact");
  if (scalar.nq() != nq_) throw std::invalid_argument("LaneStepper: the plant and the lanes differ in nq");
  for (int l = 0; l < W_; ++l) m_.emplace_back(nq_);
  stats_.assign(static_cast<size_t>(W_), IntegratorStats{});
  for (auto* x : {&v1_, &q1_, &r_, &tmp_}) x->assign(static_cast<size_t>(nq_ * W_), 0.0);
  x_ = VectorXd::Zero(nq_);
  newton_.assign(static_cast<size_t>(W_), 0);
  fresh_.assign(static_cast<size_t>(W_), 0);
}

// Member l's M₀ − a D (M₀ from the step's start, D from `D`), factored and kept with its signature.
bool LaneStepper::factor(int l, double a, double h, std::uint64_t sig, const std::vector<double>& D) {
  Member& mb = m_[static_cast<size_t>(l)];
  ++stats_[static_cast<size_t>(l)].jacobians;
  MatrixXd& A = mb.lu.matrix();
  for (int c = 0; c < nq_; ++c)
    for (int r = 0; r < nq_; ++r) {
      double x = M_spin_(r, c);
      if (r < n1_ && c < n1_) x += t0_.Mb[static_cast<size_t>((c * n1_ + r) * W_ + l)];
      A(r, c) = x - a * D[static_cast<size_t>((c * nq_ + r) * W_ + l)];
    }
  mb.valid = mb.lu.factor(J_);
  mb.sig = sig;
  mb.h = h;
  mb.age = 0;
  return mb.valid;
}

void LaneStepper::solve(int l, double* x) {
  for (int i = 0; i < nq_; ++i) x_(i) = x[i * W_ + l];
  m_[static_cast<size_t>(l)].lu.solve(x_);
  for (int i = 0; i < nq_; ++i) x[i * W_ + l] = x_(i);
}

void LaneStepper::step(double t, double h, double* q, double* v, const LaneInputs& in, StepStatus* status) {
  (void)t;  // the plant is autonomous; t only labels the step
  const double th = o_.theta, a = th * h, b = (1 - th) * h;
  const bool always = o_.jacobian_age == 0;
  const int W = W_, n = nq_;
  const auto at = [W](int i, int l) { return static_cast<size_t>(i * W + l); };
  bool any_stale = false;
  for (int l = 0; l < W; ++l) {
    if (status[l] != StepStatus::kOk) continue;
    Member& mb = m_[static_cast<size_t>(l)];
    if (always || std::abs(h - mb.h) > 1e-9 * h || ++mb.age > o_.jacobian_age) mb.valid = false;
    any_stale |= !mb.valid;
  }
  // The start: F₀, M₀, D_q v₀; the Jacobian for the members whose kept one expired or whose
  // contact branches changed (each counts the evaluations its own Integrator would).
  plant_.evaluate(q, v, in, true, t0_, any_stale ? a : 0.0);
  bool any_changed = false;
  for (int l = 0; l < W; ++l) {
    if (status[l] != StepStatus::kOk) continue;
    const Member& mb = m_[static_cast<size_t>(l)];
    ++stats_[static_cast<size_t>(l)].evaluations;
    fresh_[static_cast<size_t>(l)] = !mb.valid || t0_.signature[static_cast<size_t>(l)] != mb.sig;
    if (mb.valid && fresh_[static_cast<size_t>(l)]) {
      ++stats_[static_cast<size_t>(l)].evaluations;  // its Integrator evaluates again, with the Jacobian
      any_changed |= !any_stale;
    }
  }
  if (any_changed) plant_.evaluate(q, v, in, true, t0_, a);
  for (int l = 0; l < W; ++l) {
    if (status[l] != StepStatus::kOk || !fresh_[static_cast<size_t>(l)]) continue;
    if (!factor(l, a, h, t0_.signature[static_cast<size_t>(l)], t0_.D)) status[l] = StepStatus::kNonFinite;
  }
  // Predictor: (M − θh D_v − θ²h² D_q) Δv = h (F + θh D_q v).
  for (size_t i = 0; i < r_.size(); ++i) r_[i] = h * (t0_.F[i] + a * t0_.dFdq_v[i]);
  bool iterating = false;
  for (int l = 0; l < W; ++l) {
    newton_[static_cast<size_t>(l)] = 0;
    if (status[l] != StepStatus::kOk) continue;
    solve(l, r_.data());
    for (int i = 0; i < n; ++i) v1_[at(i, l)] = v[at(i, l)] + r_[at(i, l)];
    newton_[static_cast<size_t>(l)] = o_.newton_iterations > 0;
    iterating |= o_.newton_iterations > 0;
  }
  std::vector<char>& converged = fresh_;  // reused: fresh_ is done with
  for (int l = 0; l < W; ++l) converged[static_cast<size_t>(l)] = o_.newton_iterations == 0;
  const double tol = o_.newton_tol;
  for (int it = 0; it < o_.newton_iterations && iterating; ++it) {
    for (size_t i = 0; i < q1_.size(); ++i) q1_[i] = q[i] + b * v[i] + a * v1_[i];
    plant_.evaluate(q1_.data(), v1_.data(), in, false, t1_, always ? a : 0.0, always ? v : nullptr);
    bool any_jac = false;
    for (int l = 0; l < W; ++l) {
      if (!newton_[static_cast<size_t>(l)]) continue;
      ++stats_[static_cast<size_t>(l)].evaluations;
      if (!always && t1_.signature[static_cast<size_t>(l)] != m_[static_cast<size_t>(l)].sig) {
        ++stats_[static_cast<size_t>(l)].evaluations;
        any_jac = true;
      }
    }
    if (any_jac) plant_.evaluate(q1_.data(), v1_.data(), in, false, t1_, a, v);
    // Residual G(v₁) = M₀ (v₁ − v₀) − h [(1−θ) F₀ + θ F₁].
    for (size_t i = 0; i < tmp_.size(); ++i) tmp_[i] = v1_[i] - v[i];
    for (int l = 0; l < W; ++l) {
      if (!newton_[static_cast<size_t>(l)]) continue;
      for (int r = 0; r < n; ++r) {
        double s = 0.0;
        for (int c = 0; c < n; ++c) {
          double mrc = M_spin_(r, c);
          if (r < n1_ && c < n1_) mrc += t0_.Mb[static_cast<size_t>((c * n1_ + r) * W + l)];
          s += mrc * tmp_[at(c, l)];
        }
        r_[at(r, l)] = s - (b * t0_.F[at(r, l)] + a * t1_.F[at(r, l)]);
      }
    }
    iterating = false;
    for (int l = 0; l < W; ++l) {
      if (!newton_[static_cast<size_t>(l)]) continue;
      const bool jac = always || t1_.signature[static_cast<size_t>(l)] != m_[static_cast<size_t>(l)].sig;
      if (jac && !factor(l, a, h, t1_.signature[static_cast<size_t>(l)], t1_.D)) {
        status[l] = StepStatus::kNonFinite;
        newton_[static_cast<size_t>(l)] = 0;
        continue;
      }
      solve(l, r_.data());
      double dmax = 0.0, vmax = 0.0;
      bool finite = true;
      for (int i = 0; i < n; ++i) {
        const double d = r_[at(i, l)];
        const double x = v1_[at(i, l)] - d;
        v1_[at(i, l)] = x;
        finite = finite && std::isfinite(x);
        dmax = std::max(dmax, std::abs(d));
        vmax = std::max(vmax, std::abs(x));
      }
      if (!finite) {
        newton_[static_cast<size_t>(l)] = 0;
        continue;
      }
      if (dmax <= tol * (1.0 + vmax)) {
        converged[static_cast<size_t>(l)] = 1;
        newton_[static_cast<size_t>(l)] = 0;
        continue;
      }
      iterating = true;
    }
  }
  for (int l = 0; l < W; ++l) {
    if (status[l] != StepStatus::kOk) continue;
    IntegratorStats& st = stats_[static_cast<size_t>(l)];
    if (!converged[static_cast<size_t>(l)]) ++st.newton_unconverged;
    bool finite = true;
    for (int i = 0; i < n; ++i) {
      const size_t k = at(i, l);
      q[k] += b * v[k] + a * v1_[k];
      v[k] = v1_[k];
      finite = finite && std::isfinite(q[k]) && std::isfinite(v[k]);
    }
    ++st.steps;
    st.h_last = h;
    if (!finite) status[l] = StepStatus::kNonFinite;
  }
}

}  // namespace pedalwave::model
