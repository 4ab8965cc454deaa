// Anderson-accelerated rounds with the energy safeguard, and the reduced
// energy they and the second-order steps judge by (fused_steps.h).
#include "fused_steps.h"

#include "blas.h"
#include "round_product.h"
#include "simd_kernels.h"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

namespace qpreduce::detail {

double reduced_energy(const detail::PhaseOneEnergy& E, FusedWorkspace& W, const InputProjection<double>& projection,
                      const Eigen::Ref<const Vector<double>>& b, const Eigen::Ref<const Vector<double>>& y,
                      bool float_rounds, const Vector<double>* D, double* slack) {
  const bool corrected = D != nullptr;
  double constraint = 0.0;
  if (W.constraint_affine) {
    constraint = W.blb + W.lyb.dot(y);
  } else {
    const Index m = E.Lb.rows();
    detail::gemv(E.AyLy, y.data(), W.ay_ly.data(), false);  // [A_y·y; Λ_y·y]
    for (Index i = 0; i < m; ++i) {
      const double lambda = W.lambda_b(i) + W.ay_ly(m + i);
      constraint += (corrected ? b(i) : b(i) - W.ay_ly(i)) * lambda;
    }
  }
  const double quadratic = projection.quadratic_term(y), linear = W.g.dot(y);
  const double proximal = corrected ? y.dot(D->cwiseProduct(y)) : 0.0;
  *slack = (float_rounds ? 1e-9 : 1e-11) *
           (std::abs(quadratic) + std::abs(linear) + std::abs(constraint) + std::abs(proximal));
  return quadratic - 0.5 * linear + 0.5 * proximal - 0.5 * constraint;
}

void constraint_term(const detail::PhaseOneEnergy& E, const Eigen::Ref<const Vector<double>>& b, bool corrected,
                     FusedWorkspace& W) {
  const Index m = E.Lb.rows();
  detail::gemv(E.Lb, b.data(), W.lambda_b.data(), false);
  W.constraint_affine = corrected || E.ay_zero;
  if (!W.constraint_affine) return;
  W.blb = b.dot(W.lambda_b);
  if (m == 0) {
    W.lyb.setZero();
  } else {
    detail::gemtv(E.AyLy.data() + m, m, E.AyLy.cols(), E.AyLy.outerStride(), b.data(), W.lyb.data());
  }
}

AlternationResults run_accelerated(const FusedModel& M, FusedWorkspace& W, InputProjection<double>& projection,
                                   const detail::PhaseOneEnergy& E, const Eigen::Ref<const Vector<double>>& b,
                                   const AlternationSettings& options, const detail::StopTest& stop,
                                   Eigen::Ref<Vector<double>> y) {
  AlternationResults summary;
  const bool use_float = options.float_products;
  const bool corrected = M.energy != nullptr;
  auto product = [&](const Vector<double>& at) {
    round_product(M, W, at.data(), use_float, summary.iterations == 0 ? kNoChange : summary.last_change);
  };
  constraint_term(E, b, corrected, W);
  W.anderson.restart();
  W.y_try = y;
  W.y_plain = y;
  double accepted = std::numeric_limits<double>::infinity(), slack = 0.0;
  bool extrapolated = false;  // y_try is an extrapolation (else the plain step itself)
  for (int it = 0; it < options.iterations; ++it) {
    product(W.y_try);
    const Vector<double>* D = corrected ? &M.proximal_entries : nullptr;
    double energy = reduced_energy(E, W, projection, b, W.y_try, use_float, D, &slack);
    if (extrapolated && !W.anderson.accept(energy, accepted, slack)) {  // the safeguard: back to the plain step
      W.y_try = W.y_plain;
      product(W.y_try);
      energy = reduced_energy(E, W, projection, b, W.y_try, use_float, D, &slack);
    }
    accepted = energy;
    W.y_plain = W.y_try;
    summary.last_change = projection.project(W.g, W.y_plain);
    summary.iterations = it + 1;
    if (stop.done(summary.last_change, [&] { return W.y_try.norm(); }, &summary)) break;
    extrapolated = W.anderson.propose(W.y_try, W.y_plain, W.y_next);
    if (extrapolated) projection.retract(W.y_next);
    W.y_try.swap(W.y_next);
  }
  y = W.y_plain;
  summary.energy = accepted;
  summary.rejected = W.anderson.rejected();
  return summary;
}

void prepare_acceleration(const FixedCoordinateSolver<double>& phase1, const InputProjection<double>& projection,
                          const AlternationSettings& options, const Eigen::Ref<const Vector<double>>& y,
                          FusedWorkspace& W) {
  if (!phase1.has_energy_terms()) {
    throw std::invalid_argument(
        "FusedAlternation::run: accelerated rounds (anderson_window > 0) need the energy terms of Phase 1 "
        "(FixedCoordinateSolver::form_energy_terms after set_constraints)");
  }
  if (!std::isfinite(projection.quadratic_term(y))) {
    throw std::invalid_argument(
        "FusedAlternation::run: this projection cannot be accelerated (its quadratic_term is not given)");
  }
  const Index k = y.size(), m = phase1.m();
  if (W.anderson.size() != k || W.anderson.window() != options.anderson_window) {
    W.anderson.reset(k, AndersonOptions{options.anderson_window});
  }
  W.y_plain.resize(k);
  size_energy_workspace(k, m, W);
}

void size_energy_workspace(Index k, Index m, FusedWorkspace& W) {
  W.y_try.resize(k);
  W.y_next.resize(k);
  W.ay_ly.resize(2 * m);
  W.lambda_b.resize(m);
  W.lyb.resize(k);
}

}  // namespace qpreduce::detail
