#include "qpreduce/alternating.h"

#include "blas.h"
#include "range_space.h"
#include "simd_kernels.h"

#include "qpreduce/detail/qp_operators.h"
#include "qpreduce/detail/timer.h"

#include <fmt/format.h>

#include <cstring>
#include <memory>
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

namespace detail {

// The fast path's per-solver part (alternating.h), in double.
struct FixedCoordinatePrep {
  std::uint64_t generation = 0;  // SubspaceSolver::generation_ it was made from
  RangeSpace range;              // of H_zz (d × d)
  Matrix<double> G;              // NᵀD − H_zy (d × k)
  Matrix<double> P0;             // M0·G (d × k): the unconstrained z-response to Y
};

}  // namespace detail

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
  fast_ = false;
  const Index d = solver.d(), k = solver.k(), m = A.cols();
  const MatD Az = (A.transpose() * solver.subspace().N).template cast<double>();
  const MatD Ay = (A.transpose() * solver.subspace().UD).template cast<double>();

  std::optional<detail::ScopedBlasThreads> blas;  // single-threaded BLAS unless asked (see ConstraintOptions)
  if (options.threads > 0) blas.emplace(options.threads);
  ConstraintSummary summary;
  summary.m = m;
  if (options.fast_path) {
    if (!prep_ || prep_->generation != solver.generation_) {
      auto prep = std::make_shared<detail::FixedCoordinatePrep>();
      prep->generation = solver.generation_;
      prep->range = detail::prepare_range_space(solver.Hr_d_.topLeftCorner(d, d), solver.lift_tolerance_);
      prep->G = solver.BtD_d_.topRows(d) - solver.Hr_d_.topRightCorner(d, k);
      prep->P0.resize(d, k);
      detail::blas_gemm(false, false, 1.0, prep->range.Minv0, prep->G, 0.0, prep->P0);
      prep_ = std::move(prep);
    }
    detail::RangeSpaceOperators rso;
    if (detail::range_space_operators(prep_->range, Az, options, &summary, &rso)) {
      // M_b = T·U_mᵀ, R = WᵀG + U_mᵀ·A_y, M_Y = P0 − T·R.
      const Index mu = rso.T.cols();
      MatD Mb(d, m), MY = prep_->P0;
      detail::blas_gemm(false, true, 1.0, rso.T, rso.Um, 0.0, Mb);
      R_.resize(mu, k);
      detail::blas_gemm(true, false, 1.0, rso.W, prep_->G, 0.0, R_);
      detail::blas_gemm(true, false, 1.0, rso.Um, Ay, 1.0, R_);
      detail::blas_gemm(false, false, -1.0, rso.T, R_, 1.0, MY);
      if (Mb.allFinite() && MY.allFinite()) {
        fast_ = true;
        T_ = std::move(rso.T);
        Um_ = std::move(rso.Um);
        Mb_ = Mb.template cast<Scalar>();
        if constexpr (std::is_same_v<Scalar, double>) {
          MY_ = std::move(MY);
        } else {
          MY_ = MY.template cast<Scalar>();
        }
      }
    }
  }
  if (!fast_) {
    // The null-space method on H_zz (detail/qp_operators.h).
    summary = ConstraintSummary{};
    const MatD Hr = solver.reduced_hessian().template cast<double>();
    const MatD G = solver.reduced_linear_map().topRows(d).template cast<double>() - Hr.topRightCorner(d, k);
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
  }
  summary.fast_path = fast_;
  ready_ = true;
  summary.seconds = timer.seconds();
  return summary;
}

template <typename Scalar>
void FixedCoordinateSolver<Scalar>::solve(const ConstRef& b, const ConstRef& Y, Ref z) const {
  assert(ready_ && b.size() == m() && Y.size() == k() && z.size() == d());
  detail::gemv(Mb_, b.data(), z.data(), false);
  detail::gemv(MY_, Y.data(), z.data(), true);
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

namespace {

// Columns per block when the fast path forms F_y and its float copy: a
// q × 32 double block stays in L2 until it is copied (q = 9d ≤ 1000 →
// ≤ 256 KiB).
constexpr Index kColumnBlock = 32;

// Same shape and the same bits.
template <typename T>
bool same_matrix(const Matrix<T>& a, const Matrix<T>& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() &&
         (a.size() == 0 || std::memcmp(a.data(), b.data(), sizeof(T) * static_cast<size_t>(a.size())) == 0);
}

}  // namespace

template <typename Scalar>
void FusedAlternation<Scalar>::set(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz,
                                   const Matrix<Scalar>& Gy, int threads) {
  std::optional<detail::ScopedBlasThreads> blas;  // single-threaded BLAS unless asked (see ConstraintOptions)
  if (threads > 0) blas.emplace(threads);
  if (!phase1.ready()) throw std::invalid_argument("FusedAlternation::set: Phase 1 has no constraints yet");
  detail::check_size("FusedAlternation::set: G_z columns (d)", phase1.d(), Gz.cols());
  detail::check_size("FusedAlternation::set: G_y columns (k)", phase1.k(), Gy.cols());
  detail::check_size("FusedAlternation::set: G_y rows (as G_z)", Gz.rows(), Gy.rows());
  ready_ = false;
  const Index q = Gz.rows();
  bool fast = false;
  if constexpr (std::is_same_v<Scalar, double>) {
    if (phase1.fast_) {
      if (prep_ != phase1.prep_ || !same_matrix(Gz_, Gz)) {
        // C0 = G_z·P0, once per (Phase 1 preparation, G_z).
        prep_.reset();
        detail::check_finite("FusedAlternation::set: G_z", Gz);
        C0_.resize(q, phase1.k());
        detail::blas_gemm(false, false, 1.0, Gz, phase1.prep_->P0, 0.0, C0_);
        Gz_ = Gz;
        prep_ = phase1.prep_;
      }
      // G_z·T (q × μ), F_b = (G_z·T)·U_mᵀ, F_y = C0 + G_y − (G_z·T)·R, the
      // last in column blocks that are still in cache for the float copy.
      Matrix<double> GzT(q, phase1.T_.cols());
      detail::blas_gemm(false, false, 1.0, Gz, phase1.T_, 0.0, GzT);
      Fb_.resize(q, phase1.m());
      detail::blas_gemm(false, true, 1.0, GzT, phase1.Um_, 0.0, Fb_);
      const Index k = Gy.cols();
      Fy_.resize(q, k);
      Fy_f_.resize(q, k);
      for (Index c0 = 0; c0 < k; c0 += kColumnBlock) {
        const Index w = std::min(kColumnBlock, k - c0);
        if (!Gy.middleCols(c0, w).allFinite()) detail::check_finite("FusedAlternation::set: G_y", Gy);  // throws
        Fy_.middleCols(c0, w) = C0_.middleCols(c0, w) + Gy.middleCols(c0, w);
        detail::blas_gemm(false, false, -1.0, GzT, phase1.R_.middleCols(c0, w), 1.0, Fy_.middleCols(c0, w));
        Fy_f_.middleCols(c0, w) = Fy_.middleCols(c0, w).template cast<float>();
      }
      fast = true;
    }
  }
  if (!fast) {
    detail::check_finite("FusedAlternation::set: G_z", Gz);
    detail::check_finite("FusedAlternation::set: G_y", Gy);
    Fy_ = Gy;
    if constexpr (std::is_same_v<Scalar, double>) {
      Fb_.resize(q, phase1.m());
      detail::blas_gemm(false, false, 1.0, Gz, phase1.Mb(), 0.0, Fb_);
      detail::blas_gemm(false, false, 1.0, Gz, phase1.MY(), 1.0, Fy_);
    } else {
      Fb_.noalias() = Gz * phase1.Mb();
      Fy_.noalias() += Gz * phase1.MY();
    }
    Fy_f_ = Fy_.template cast<float>();
  }
  gb_.resize(q);
  g_.resize(q);
  gf_.resize(q);
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
  // The products go through the run-time dispatched AVX2/FMA kernels
  // (simd_kernels.h) when the CPU has them.
  detail::gemv(Fb_, b.data(), gb_.data(), false);
  for (int it = 0; it < options.iterations; ++it) {
    if (options.float_products) {
      // Mixed precision: the q×k product in float (twice the SIMD width of
      // double), accumulated onto g in double.
      yf_ = y.template cast<float>();
      detail::gemv(Fy_f_, yf_.data(), gf_.data(), false);
      g_ = gb_ + gf_.template cast<Scalar>();
    } else {
      g_ = gb_;
      detail::gemv(Fy_, y.data(), g_.data(), true);
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
