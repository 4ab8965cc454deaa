#include "qpreduce/alternating.h"

#include "blas.h"
#include "qpreduce/detail/qp_operators.h"
#include "qpreduce/detail/timer.h"

#include <fmt/format.h>

#include <optional>
#include <type_traits>

namespace qpreduce {

bool AlternatingOptions::is_valid(std::string* why) const {
  if (iterations < 1) {
    if (why) *why = fmt::format("iterations must be at least 1, got {}", iterations);
    return false;
  }
  if (!(tolerance >= 0.0)) {
    if (why) *why = "tolerance must be non-negative";
    return false;
  }
  return true;
}

template <typename Scalar>
ConstraintSummary FixedCoordinateSolver<Scalar>::set_constraints(const SubspaceSolver<Scalar>& solver,
                                                                 const SparseMatrix<Scalar>& A,
                                                                 const ConstraintOptions& options) {
  using MatD = Matrix<double>;
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("ConstraintOptions: " + why);
  if (!solver.ready()) {
    throw std::invalid_argument("FixedCoordinateSolver::set_constraints: the subspace solver is not ready");
  }
  detail::check_size("FixedCoordinateSolver::set_constraints: A rows", solver.n(), A.rows());
  detail::check_finite("FixedCoordinateSolver::set_constraints: A", A);
  const detail::Timer timer;
  ready_ = false;
  const Index d = solver.d(), k = solver.k();
  const MatD Hr = solver.reduced_hessian().template cast<double>();
  const MatD Az = (A.transpose() * solver.subspace().N).template cast<double>();
  const MatD Ay = (A.transpose() * solver.subspace().UD).template cast<double>();
  const MatD G = solver.reduced_linear_map().topRows(d).template cast<double>() - Hr.topRightCorner(d, k);

  std::optional<detail::ScopedBlasThreads> blas;  // single-threaded BLAS unless asked (see ConstraintOptions)
  if (options.threads > 0) blas.emplace(options.threads);
  ConstraintSummary summary;
  const detail::QpOperators ops = detail::qp_operators(Hr.topLeftCorner(d, d), Az, options, &summary);
  Mb_ = ops.Mc.template cast<Scalar>();
  MatD MY(d, k);  // M_g·G − M_c·A_y, through the BLAS (blas.h)
  detail::blas_gemm(false, false, 1.0, ops.Mg, G, 0.0, MY);
  detail::blas_gemm(false, false, -1.0, ops.Mc, Ay, 1.0, MY);
  if constexpr (std::is_same_v<Scalar, double>) {
    MY_ = std::move(MY);
  } else {
    MY_ = MY.template cast<Scalar>();
  }
  ready_ = true;
  summary.seconds = timer.seconds();
  return summary;
}

template <typename Scalar>
void FixedCoordinateSolver<Scalar>::solve(const ConstRef& b, const ConstRef& Y, Ref z) const {
  assert(ready_ && b.size() == m() && Y.size() == k() && z.size() == d());
  z.noalias() = Mb_ * b;
  z.noalias() += MY_ * Y;
}

template <typename Scalar>
AlternatingSummary alternate(const FixedCoordinateSolver<Scalar>& phase1, Phase2Projection<Scalar>& phase2,
                             const Eigen::Ref<const Vector<Scalar>>& b, const AlternatingOptions& options,
                             Eigen::Ref<Vector<Scalar>> z, Eigen::Ref<Vector<Scalar>> y) {
  assert(options.is_valid(nullptr));
  assert(phase1.ready() && z.size() == phase1.d() && y.size() == phase1.k() && b.size() == phase1.m());
  AlternatingSummary summary;
  double change = 0.0;
  for (int it = 0; it < options.iterations; ++it) {
    phase1.solve(b, y, z);
    change = phase2.project(z, y);
    summary.iterations = it + 1;
    if (options.tolerance > 0 && change <= options.tolerance * std::max(1.0, static_cast<double>(y.norm()))) break;
  }
  phase1.solve(b, y, z);
  summary.last_change = change;
  return summary;
}

template <typename Scalar>
void FusedAlternation<Scalar>::set(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz,
                                   const Matrix<Scalar>& Gy, int threads) {
  std::optional<detail::ScopedBlasThreads> blas;  // single-threaded BLAS unless asked (see ConstraintOptions)
  if (threads > 0) blas.emplace(threads);
  if (!phase1.ready()) throw std::invalid_argument("FusedAlternation::set: Phase 1 has no constraints yet");
  detail::check_size("FusedAlternation::set: G_z columns (d)", phase1.d(), Gz.cols());
  detail::check_size("FusedAlternation::set: G_y columns (k)", phase1.k(), Gy.cols());
  detail::check_size("FusedAlternation::set: G_y rows (as G_z)", Gz.rows(), Gy.rows());
  Fy_ = Gy;
  if constexpr (std::is_same_v<Scalar, double>) {
    Fb_.resize(Gz.rows(), phase1.m());
    detail::blas_gemm(false, false, 1.0, Gz, phase1.Mb(), 0.0, Fb_);
    detail::blas_gemm(false, false, 1.0, Gz, phase1.MY(), 1.0, Fy_);
  } else {
    Fb_.noalias() = Gz * phase1.Mb();
    Fy_.noalias() += Gz * phase1.MY();
  }
  Fy_f_ = Fy_.template cast<float>();
  gb_.resize(Gz.rows());
  g_.resize(Gz.rows());
  gf_.resize(Gz.rows());
  yf_.resize(Fy_.cols());
  ready_ = true;
}

template <typename Scalar>
AlternatingSummary FusedAlternation<Scalar>::run(const FixedCoordinateSolver<Scalar>& phase1,
                                                 InputProjection<Scalar>& projection,
                                                 const Eigen::Ref<const Vector<Scalar>>& b,
                                                 const AlternatingOptions& options, Eigen::Ref<Vector<Scalar>> z,
                                                 Eigen::Ref<Vector<Scalar>> y) {
  assert(ready_ && options.is_valid(nullptr) && b.size() == Fb_.cols() && y.size() == Fy_.cols());
  AlternatingSummary summary;
  gb_.noalias() = Fb_ * b;
  for (int it = 0; it < options.iterations; ++it) {
    g_ = gb_;
    if (options.float_products) {
      // Mixed precision: the k×k product in float (twice the SIMD width of
      // double in Eigen's baseline kernels), accumulated onto g in double.
      yf_ = y.template cast<float>();
      gf_.noalias() = Fy_f_ * yf_;
      g_ += gf_.template cast<Scalar>();
    } else {
      g_.noalias() += Fy_ * y;
    }
    summary.last_change = projection.project(g_, y);
    summary.iterations = it + 1;
    if (options.tolerance > 0 &&
        summary.last_change <= options.tolerance * std::max(1.0, static_cast<double>(y.norm())))
      break;
  }
  phase1.solve(b, y, z);
  return summary;
}

template class FusedAlternation<double>;
template class FusedAlternation<float>;
template class FixedCoordinateSolver<double>;
template class FixedCoordinateSolver<float>;
template AlternatingSummary alternate<double>(const FixedCoordinateSolver<double>&, Phase2Projection<double>&,
                                              const Eigen::Ref<const Vector<double>>&, const AlternatingOptions&,
                                              Eigen::Ref<Vector<double>>, Eigen::Ref<Vector<double>>);
template AlternatingSummary alternate<float>(const FixedCoordinateSolver<float>&, Phase2Projection<float>&,
                                             const Eigen::Ref<const Vector<float>>&, const AlternatingOptions&,
                                             Eigen::Ref<Vector<float>>, Eigen::Ref<Vector<float>>);

}  // namespace qpreduce
