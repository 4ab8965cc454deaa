#include "qpreduce/testing/invariants.h"

#include <Eigen/Eigenvalues>
#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

namespace qpreduce::testing {

namespace detail {

Eigen::VectorXd random_vector(Index size, double scale, std::mt19937_64& rng) {
  std::normal_distribution<double> normal(0.0, scale);
  Eigen::VectorXd v(size);
  for (Index i = 0; i < size; ++i) v(i) = normal(rng);
  return v;
}

CheckResult fail(double worst, std::string message) {
  CheckResult r;
  r.ok = false;
  r.worst = worst;
  r.message = std::move(message);
  return r;
}

}  // namespace detail

using detail::fail;

CheckResult check_symmetric_psd(const SparseMatrix<double>& H, const PsdOptions& options) {
  if (H.rows() != H.cols()) {
    throw std::invalid_argument(fmt::format("check_symmetric_psd: H is {} × {}, not square", H.rows(), H.cols()));
  }
  if (H.rows() > options.max_dense) {
    throw std::invalid_argument(fmt::format(
        "check_symmetric_psd: H has {} rows, more than max_dense = {} (the kit is for small test models)", H.rows(),
        options.max_dense));
  }
  const Matrix<double> Hd(H);
  if (!Hd.allFinite()) return fail(1.0, "H has NaN or Inf entries");
  const double norm = Hd.norm();
  if (norm == 0.0) return {};
  const double asym = (Hd - Hd.transpose()).norm() / norm;
  if (asym > options.tolerance) {
    return fail(asym, fmt::format("H is not symmetric: ‖H − Hᵀ‖/‖H‖ = {:.3e} > {:.1e}", asym, options.tolerance));
  }
  const Eigen::SelfAdjointEigenSolver<Matrix<double>> eig(0.5 * (Hd + Hd.transpose()), Eigen::EigenvaluesOnly);
  const double lmin = eig.eigenvalues().minCoeff(), lmax = eig.eigenvalues().maxCoeff();
  CheckResult r;
  r.worst = std::max(asym, lmax > 0 ? -lmin / lmax : 0.0);
  if (lmin < -options.tolerance * std::max(lmax, 0.0)) {
    return fail(-lmin / std::max(lmax, 1e-300),
                fmt::format("H is not PSD: λ_min = {:.3e}, λ_max = {:.3e} (tolerance {:.1e}·λ_max)", lmin, lmax,
                            options.tolerance));
  }
  return r;
}

CheckResult check_gradient(const EnergyFunction& energy, const Eigen::VectorXd& gradient, const Eigen::VectorXd& x,
                           const GradientOptions& options) {
  if (gradient.size() != x.size()) {
    throw std::invalid_argument(
        fmt::format("check_gradient: gradient has {} entries, x has {}", gradient.size(), x.size()));
  }
  std::mt19937_64 rng(options.seed);
  const double h = options.step * std::max(1.0, x.size() ? x.cwiseAbs().maxCoeff() : 0.0);
  CheckResult r;
  for (int k = 0; k < options.directions; ++k) {
    Eigen::VectorXd v = detail::random_vector(x.size(), 1.0, rng);
    v.normalize();
    const double fd = (energy(x + h * v) - energy(x - h * v)) / (2.0 * h);
    const double exact = gradient.dot(v);
    const double err = std::abs(fd - exact) / (1.0 + gradient.norm());
    r.worst = std::max(r.worst, err);
    if (!(err <= options.tolerance)) {
      return fail(err, fmt::format("direction {}: finite difference {:.9e} vs gradient {:.9e} (relative error "
                                   "{:.3e} > {:.1e})",
                                   k, fd, exact, err, options.tolerance));
    }
  }
  return r;
}

CheckResult check_quadratic_model(const EnergyFunction& energy, const SparseMatrix<double>& H, const Eigen::VectorXd& q,
                                  const QuadraticOptions& options) {
  if (H.rows() != H.cols() || q.size() != H.rows()) {
    throw std::invalid_argument(
        fmt::format("check_quadratic_model: H is {} × {}, q has {} entries", H.rows(), H.cols(), q.size()));
  }
  std::mt19937_64 rng(options.seed);
  const double e0 = energy(Eigen::VectorXd::Zero(q.size()));
  CheckResult r;
  for (int k = 0; k < options.points; ++k) {
    const Eigen::VectorXd x = detail::random_vector(q.size(), options.scale, rng);
    const Eigen::VectorXd Hx = H * x;
    const double quad = 0.5 * x.dot(Hx), lin = q.dot(x);
    const double err = std::abs(energy(x) - e0 - (quad - lin)) / (1.0 + std::abs(quad) + std::abs(lin));
    r.worst = std::max(r.worst, err);
    if (!(err <= options.tolerance)) {
      return fail(err, fmt::format("point {}: E(x) − E(0) = {:.12e} but ½xᵀHx − qᵀx = {:.12e} (relative error "
                                   "{:.3e} > {:.1e})",
                                   k, energy(x) - e0, quad - lin, err, options.tolerance));
    }
    GradientOptions go = options.gradient;
    go.seed += static_cast<std::uint64_t>(k);
    const CheckResult g = check_gradient(energy, Hx - q, x, go);
    if (!g) return fail(g.worst, fmt::format("point {}: {}", k, g.message));
    r.worst = std::max(r.worst, g.worst);
  }
  return r;
}

}  // namespace qpreduce::testing
