// qpreduce::testing — the invariant kit every plugin passes (see
// docs/plugins.md). It knows no meshes: a plugin hands it its energy as a
// quadratic form plus a direct evaluation, and its Phase 2 projection.
//
// Checks (each returns a CheckResult naming what failed, with the numbers):
//   check_symmetric_psd    ‖H − Hᵀ‖_F ≤ tol·‖H‖_F and λ_min(H) ≥ −tol·λ_max(H)
//                          (dense eigenvalues; for the small test models the kit
//                          is meant for, n ≤ PsdOptions::max_dense);
//   check_gradient         central differences of E along random unit
//                          directions v match gᵀv: |ΔE/2h − gᵀv| ≤ tol·(1 + ‖g‖);
//   check_quadratic_model  E(x) − E(0) = ½xᵀHx − qᵀx at random points, and
//                          check_gradient with g = Hx − q (the assembly of
//                          H, q agrees with the energy evaluated term by term);
//   check_projection       for a Phase 2 projection P (duck-typed: see below),
//                          on random inputs: retract(y) is valid and
//                          idempotent (retract(retract(y)) = retract(y)), every
//                          project(g, y) output is valid, and project never
//                          increases P's Phase 2 energy from a valid y.
#pragma once

#include <qpreduce/common.h>

#include <algorithm>
#include <cstdint>
#include <functional>
#include <random>
#include <string>

namespace qpreduce::testing {

struct CheckResult {
  bool ok = true;
  std::string message;  // empty when ok
  double worst = 0.0;   // the largest measured violation (relative), for reports

  explicit operator bool() const { return ok; }
};

struct PsdOptions {
  double tolerance = 1e-9;
  Index max_dense = 4000;  // larger H: std::invalid_argument (use a smaller test model)
};
CheckResult check_symmetric_psd(const SparseMatrix<double>& H, const PsdOptions& options = {});

using EnergyFunction = std::function<double(const Eigen::VectorXd&)>;

struct GradientOptions {
  int directions = 8;
  double step = 1e-5;       // relative to max(1, ‖x‖_∞)
  double tolerance = 1e-6;
  std::uint64_t seed = 1;
};
CheckResult check_gradient(const EnergyFunction& energy, const Eigen::VectorXd& gradient, const Eigen::VectorXd& x,
                           const GradientOptions& options = {});

struct QuadraticOptions {
  int points = 4;           // random x with entries of size `scale`
  double scale = 1.0;
  double tolerance = 1e-9;  // on |E(x) − E(0) − (½xᵀHx − qᵀx)| / (1 + |½xᵀHx| + |qᵀx|)
  GradientOptions gradient;
  std::uint64_t seed = 2;
};
// E(x) − E(0) against ½xᵀHx − qᵀx (H n × n, q n), plus check_gradient at
// each point with g = Hx − q.
CheckResult check_quadratic_model(const EnergyFunction& energy, const SparseMatrix<double>& H,
                                  const Eigen::VectorXd& q, const QuadraticOptions& options = {});

struct ProjectionOptions {
  int samples = 16;
  double input_scale = 1.0;  // scale of the random inputs g and y
  double tolerance = 1e-9;
  std::uint64_t seed = 3;
};

namespace detail {
Eigen::VectorXd random_vector(Index size, double scale, std::mt19937_64& rng);
CheckResult fail(double worst, std::string message);
}  // namespace detail

// P must provide (as qpreduce::deform::ClusterProjection does):
//   double project(const Eigen::Ref<const Eigen::VectorXd>& g, Eigen::Ref<Eigen::VectorXd> y);
//   void retract(Eigen::Ref<Eigen::VectorXd> y) const;
//   bool valid(const Eigen::Ref<const Eigen::VectorXd>& y, double tolerance, std::string* why) const;
//   double energy(const Eigen::Ref<const Eigen::VectorXd>& g, const Eigen::Ref<const Eigen::VectorXd>& y) const;
// `size` is the length of g and y.
template <typename P>
CheckResult check_projection(P& projection, Index size, const ProjectionOptions& options = {}) {
  using detail::fail;
  std::mt19937_64 rng(options.seed);
  CheckResult result;
  for (int sample = 0; sample < options.samples; ++sample) {
    const Eigen::VectorXd g = detail::random_vector(size, options.input_scale, rng);
    Eigen::VectorXd y = detail::random_vector(size, options.input_scale, rng);
    std::string why;
    projection.retract(y);
    if (!projection.valid(y, options.tolerance, &why)) {
      return fail(1.0, "sample " + std::to_string(sample) + ": retract gave an invalid element: " + why);
    }
    Eigen::VectorXd again = y;
    projection.retract(again);
    const double drift = (again - y).norm() / std::max(1.0, y.norm());
    result.worst = std::max(result.worst, drift);
    if (drift > options.tolerance) {
      return fail(drift, "sample " + std::to_string(sample) + ": retract is not idempotent (relative change " +
                             std::to_string(drift) + ")");
    }
    const double before = projection.energy(g, y);
    projection.project(g, y);
    if (!projection.valid(y, options.tolerance, &why)) {
      return fail(1.0, "sample " + std::to_string(sample) + ": project gave an invalid element: " + why);
    }
    const double after = projection.energy(g, y);
    const double rise = (after - before) / std::max(1.0, std::abs(before));
    result.worst = std::max(result.worst, rise);
    if (rise > options.tolerance) {
      return fail(rise, "sample " + std::to_string(sample) + ": project raised its Phase 2 energy from " +
                            std::to_string(before) + " to " + std::to_string(after));
    }
  }
  return result;
}

}  // namespace qpreduce::testing
