#include <cmath>
#include <stdexcept>

#include "pedalwave/model/lanes.hpp"

namespace pedalwave::model {

LaneStepper::LaneStepper(LanePlant& plant, const Plant& scalar, const IntegratorOptions& o)
    : plant_(plant), o_(o), W_(plant.width()), nq_(plant.nq()),
      lu_(plant.nq(), plant.joints(), plant.width()), t0_(plant.make_terms()), t1_(plant.make_terms()) {
  validate(o_);
  if (o_.method != Method::kImplicitContact)
    throw std::invalid_argument(std::string("LaneStepper: method ") + std::string(to_string(o_.method)) +
                                ": expected implicit_contact");
  if (scalar.nq() != nq_) throw std::invalid_argument("LaneStepper: the plant and the lanes differ in nq");
  m_.assign(static_cast<size_t>(W_), Member{});
  stats_.assign(static_cast<size_t>(W_), IntegratorStats{});
  for (auto* x : {&v1_, &q1_, &r_, &tmp_}) x->assign(static_cast<size_t>(nq_ * W_), 0.0);
  for (auto* x : {&newton_, &need_, &ok_, &converged_}) x->assign(static_cast<size_t>(W_), 0);
}

void LaneStepper::factor(const LaneTerms& at, double a, double h, StepStatus* status) {
  bool any = false;
  for (int l = 0; l < W_; ++l) any |= need_[static_cast<size_t>(l)] != 0;
  if (!any) return;
  plant_.factor(t0_.Mb, at.D, a, need_.data(), lu_, ok_.data());
  for (int l = 0; l < W_; ++l) {
    const auto i = static_cast<size_t>(l);
    if (!need_[i]) continue;
    ++stats_[i].jacobians;
    Member& mb = m_[i];
    mb.valid = ok_[i] != 0;
    mb.sig = at.signature[i];
    mb.h = h;
    mb.age = 0;
    if (!mb.valid) status[l] = StepStatus::kNonFinite;
  }
}

// Integrator::step_implicit_contact, member by member in its decisions, in lanes in its arithmetic.
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
  // contact branches changed (each counts the evaluations its own Integrator would: a second one,
  // with the Jacobian, when only the branches changed).
  plant_.evaluate(q, v, in, true, t0_, any_stale ? a : 0.0);
  bool again = false;
  for (int l = 0; l < W; ++l) {
    const auto i = static_cast<size_t>(l);
    need_[i] = 0;
    if (status[l] != StepStatus::kOk) continue;
    const Member& mb = m_[i];
    ++stats_[i].evaluations;
    need_[i] = !mb.valid || t0_.signature[i] != mb.sig;
    if (mb.valid && need_[i]) {
      ++stats_[i].evaluations;
      again |= !any_stale;
    }
  }
  if (again) plant_.evaluate(q, v, in, true, t0_, a);
  factor(t0_, a, h, status);
  // Predictor: (M − θh D_v − θ²h² D_q) Δv = h (F + θh D_q v).
  for (size_t i = 0; i < r_.size(); ++i) r_[i] = h * (t0_.F[i] + a * t0_.dFdq_v[i]);
  plant_.solve(lu_, r_.data());
  bool iterating = false;
  for (int l = 0; l < W; ++l) {
    const auto i = static_cast<size_t>(l);
    newton_[i] = 0;
    converged_[i] = o_.newton_iterations == 0;
    if (status[l] != StepStatus::kOk) continue;
    for (int c = 0; c < n; ++c) v1_[at(c, l)] = v[at(c, l)] + r_[at(c, l)];
    newton_[i] = o_.newton_iterations > 0;
    iterating |= newton_[i] != 0;
  }
  const double tol = o_.newton_tol;
  for (int it = 0; it < o_.newton_iterations && iterating; ++it) {
    for (size_t i = 0; i < q1_.size(); ++i) q1_[i] = q[i] + b * v[i] + a * v1_[i];
    plant_.evaluate(q1_.data(), v1_.data(), in, false, t1_, always ? a : 0.0, always ? v : nullptr);
    bool with_jacobian = false;
    for (int l = 0; l < W; ++l) {
      const auto i = static_cast<size_t>(l);
      need_[i] = 0;
      if (!newton_[i]) continue;
      ++stats_[i].evaluations;
      need_[i] = always || t1_.signature[i] != m_[i].sig;
      if (!always && need_[i]) {
        ++stats_[i].evaluations;
        with_jacobian = true;
      }
    }
    if (with_jacobian) plant_.evaluate(q1_.data(), v1_.data(), in, false, t1_, a, v);
    // Residual G(v₁) = M₀ (v₁ − v₀) − h [(1−θ) F₀ + θ F₁]; the members' fresh Jacobians where
    // their Integrators would make them; every solve at once.
    for (size_t i = 0; i < tmp_.size(); ++i) tmp_[i] = v1_[i] - v[i];
    plant_.residual(t0_.Mb, tmp_.data(), t0_.F.data(), t1_.F.data(), b, a, r_.data());
    factor(t1_, a, h, status);
    plant_.solve(lu_, r_.data());
    iterating = false;
    for (int l = 0; l < W; ++l) {
      const auto i = static_cast<size_t>(l);
      if (!newton_[i]) continue;
      if (status[l] != StepStatus::kOk) {  // its Jacobian did not factor
        newton_[i] = 0;
        continue;
      }
      double dmax = 0.0, vmax = 0.0;
      bool finite = true;
      for (int c = 0; c < n; ++c) {
        const double d = r_[at(c, l)];
        const double x = v1_[at(c, l)] - d;
        v1_[at(c, l)] = x;
        finite = finite && std::isfinite(x);
        dmax = std::max(dmax, std::abs(d));
        vmax = std::max(vmax, std::abs(x));
      }
      newton_[i] = 0;
      if (!finite) continue;
      if (dmax <= tol * (1.0 + vmax)) {
        converged_[i] = 1;
        continue;
      }
      newton_[i] = 1;
      iterating = true;
    }
  }
  for (int l = 0; l < W; ++l) {
    if (status[l] != StepStatus::kOk) continue;
    IntegratorStats& st = stats_[static_cast<size_t>(l)];
    if (!converged_[static_cast<size_t>(l)]) ++st.newton_unconverged;
    bool finite = true;
    for (int c = 0; c < n; ++c) {
      const size_t k = at(c, l);
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
