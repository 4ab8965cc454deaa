#include "qpreduce/subspace_solver.h"

#include "blas.h"
#include "subspace_internal.h"

#include "qpreduce/detail/qp_operators.h"
#include "qpreduce/detail/timer.h"

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <type_traits>
#include <vector>

namespace qpreduce {

bool ConstraintOptions::is_valid(std::string* why) const {
  auto fail = [why](const char* msg) {
    if (why) *why = msg;
    return false;
  };
  if (soft && !(delta > 0.0 && std::isfinite(delta))) return fail("delta must be positive and finite");
  if (!(rank_tolerance > 0.0 && rank_tolerance < 1.0)) return fail("rank_tolerance must lie in (0, 1)");
  if (threads < 0) return fail("threads must be non-negative");
  return true;
}

namespace {

using MatD = Matrix<double>;

// ---- the per-frame products of `solve` -----------------------------------
// The engine is compiled for baseline x86-64, where Eigen's matrix–vector
// products use SSE2 without FMA and run compute-bound on the p × p M_q (about
// 20 µs at p = 300). These kernels are compiled for AVX2 + FMA and chosen at
// run time when the CPU has both; otherwise Eigen's products are used.
#if defined(__x86_64__) && defined(__GNUC__)
#define QPREDUCE_HAVE_AVX2_KERNELS 1
#include <immintrin.h>

__attribute__((target("avx2,fma"))) inline double hsum(__m256d v) {
  const __m128d lo = _mm256_castpd256_pd128(v), hi = _mm256_extractf128_pd(v, 1);
  const __m128d s = _mm_add_pd(lo, hi);
  return _mm_cvtsd_f64(_mm_add_sd(s, _mm_unpackhi_pd(s, s)));
}
__attribute__((target("avx2,fma"))) inline float hsum(__m256 v) {
  const __m128 lo = _mm256_castps256_ps128(v), hi = _mm256_extractf128_ps(v, 1);
  __m128 s = _mm_add_ps(lo, hi);
  s = _mm_add_ps(s, _mm_movehl_ps(s, s));
  s = _mm_add_ss(s, _mm_shuffle_ps(s, s, 1));
  return _mm_cvtss_f32(s);
}

// SIMD traits: 4 doubles or 8 floats per register.
template <typename T>
struct Avx;
template <>
struct Avx<double> {
  using V = __m256d;
  static constexpr int width = 4;
  __attribute__((target("avx2,fma"))) static V load(const double* p) { return _mm256_loadu_pd(p); }
  __attribute__((target("avx2,fma"))) static void store(double* p, V v) { _mm256_storeu_pd(p, v); }
  __attribute__((target("avx2,fma"))) static V set1(double a) { return _mm256_set1_pd(a); }
  __attribute__((target("avx2,fma"))) static V zero() { return _mm256_setzero_pd(); }
  __attribute__((target("avx2,fma"))) static V fma(V a, V b, V c) { return _mm256_fmadd_pd(a, b, c); }
};
template <>
struct Avx<float> {
  using V = __m256;
  static constexpr int width = 8;
  __attribute__((target("avx2,fma"))) static V load(const float* p) { return _mm256_loadu_ps(p); }
  __attribute__((target("avx2,fma"))) static void store(float* p, V v) { _mm256_storeu_ps(p, v); }
  __attribute__((target("avx2,fma"))) static V set1(float a) { return _mm256_set1_ps(a); }
  __attribute__((target("avx2,fma"))) static V zero() { return _mm256_setzero_ps(); }
  __attribute__((target("avx2,fma"))) static V fma(V a, V b, V c) { return _mm256_fmadd_ps(a, b, c); }
};

// y += M·x, M column-major rows × cols with leading dimension ld.
template <typename T>
__attribute__((target("avx2,fma"))) void gemv_add_avx2(const T* M, Index rows, Index cols, Index ld, const T* x,
                                                        T* y) {
  using A = Avx<T>;
  constexpr Index W = A::width;
  const Index vrows = rows - rows % W;
  Index j = 0;
  for (; j + 4 <= cols; j += 4) {
    const T* c0 = M + j * ld;
    const T* c1 = c0 + ld;
    const T* c2 = c1 + ld;
    const T* c3 = c2 + ld;
    const auto x0 = A::set1(x[j]), x1 = A::set1(x[j + 1]), x2 = A::set1(x[j + 2]), x3 = A::set1(x[j + 3]);
    for (Index i = 0; i < vrows; i += W) {
      auto acc = A::load(y + i);
      acc = A::fma(A::load(c0 + i), x0, acc);
      acc = A::fma(A::load(c1 + i), x1, acc);
      acc = A::fma(A::load(c2 + i), x2, acc);
      acc = A::fma(A::load(c3 + i), x3, acc);
      A::store(y + i, acc);
    }
    for (Index i = vrows; i < rows; ++i) y[i] += c0[i] * x[j] + c1[i] * x[j + 1] + c2[i] * x[j + 2] + c3[i] * x[j + 3];
  }
  for (; j < cols; ++j) {
    const T* c = M + j * ld;
    const auto xj = A::set1(x[j]);
    for (Index i = 0; i < vrows; i += W) A::store(y + i, A::fma(A::load(c + i), xj, A::load(y + i)));
    for (Index i = vrows; i < rows; ++i) y[i] += c[i] * x[j];
  }
}

// y += M·x for symmetric M (n × n, leading dimension ld) of which only the
// lower triangle is read: four columns at a time, each below-diagonal entry
// is used twice (y_i += m_ij·x_j and y_j += m_ij·x_i).
template <typename T>
__attribute__((target("avx2,fma"))) void symv_lower_add_avx2(const T* M, Index n, Index ld, const T* x, T* y) {
  using A = Avx<T>;
  constexpr Index W = A::width;
  Index j = 0;
  for (; j + 4 <= n; j += 4) {
    // The 4 × 4 diagonal block.
    for (Index a = 0; a < 4; ++a)
      for (Index b = 0; b < 4; ++b) {
        const Index r = j + std::max(a, b), c = j + std::min(a, b);
        y[j + a] += M[r + c * ld] * x[j + b];
      }
    const T* c0 = M + j * ld;
    const T* c1 = c0 + ld;
    const T* c2 = c1 + ld;
    const T* c3 = c2 + ld;
    const auto x0 = A::set1(x[j]), x1 = A::set1(x[j + 1]), x2 = A::set1(x[j + 2]), x3 = A::set1(x[j + 3]);
    auto d0 = A::zero(), d1 = A::zero(), d2 = A::zero(), d3 = A::zero();
    Index i = j + 4;
    for (; i + W <= n; i += W) {
      const auto m0 = A::load(c0 + i), m1 = A::load(c1 + i), m2 = A::load(c2 + i), m3 = A::load(c3 + i);
      const auto xi = A::load(x + i);
      auto yi = A::load(y + i);
      yi = A::fma(m0, x0, yi);
      yi = A::fma(m1, x1, yi);
      yi = A::fma(m2, x2, yi);
      yi = A::fma(m3, x3, yi);
      A::store(y + i, yi);
      d0 = A::fma(m0, xi, d0);
      d1 = A::fma(m1, xi, d1);
      d2 = A::fma(m2, xi, d2);
      d3 = A::fma(m3, xi, d3);
    }
    T t0 = hsum(d0), t1 = hsum(d1), t2 = hsum(d2), t3 = hsum(d3);
    for (; i < n; ++i) {
      y[i] += c0[i] * x[j] + c1[i] * x[j + 1] + c2[i] * x[j + 2] + c3[i] * x[j + 3];
      t0 += c0[i] * x[i];
      t1 += c1[i] * x[i];
      t2 += c2[i] * x[i];
      t3 += c3[i] * x[i];
    }
    y[j] += t0;
    y[j + 1] += t1;
    y[j + 2] += t2;
    y[j + 3] += t3;
  }
  for (; j < n; ++j) {  // the last n mod 4 columns
    const T* c = M + j * ld;
    y[j] += c[j] * x[j];
    for (Index i = j + 1; i < n; ++i) {
      y[i] += c[i] * x[j];
      y[j] += c[i] * x[i];
    }
  }
}

bool cpu_has_avx2_fma() {
  static const bool yes = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return yes;
}
#endif

// y += M·x for a column-major block M (rows × cols, leading dimension ld).
template <typename T>
void gemv_add(const T* M, Index rows, Index cols, Index ld, const T* x, T* y) {
#ifdef QPREDUCE_HAVE_AVX2_KERNELS
  if (cpu_has_avx2_fma()) {
    gemv_add_avx2(M, rows, cols, ld, x, y);
    return;
  }
#endif
  const Eigen::Map<const Matrix<T>, 0, Eigen::OuterStride<>> Mv(M, rows, cols, Eigen::OuterStride<>(ld));
  Eigen::Map<Vector<T>>(y, rows).noalias() += Mv * Eigen::Map<const Vector<T>>(x, cols);
}

// y = M·x (+ y when accumulate), M a whole column-major matrix.
template <typename T>
void gemv(const Matrix<T>& M, const T* x, T* y, bool accumulate) {
  if (!accumulate) Eigen::Map<Vector<T>>(y, M.rows()).setZero();
  gemv_add(M.data(), M.rows(), M.cols(), M.outerStride(), x, y);
}

// The O(n·p) passes (reduce_linear_term, reconstruct) stream the whole basis;
// below this many entries (n·p) one thread is faster than waking a team and
// is not exposed to a descheduled second thread on a shared machine.
constexpr Index kParallelEntries = Index(1) << 24;
// Rows per block of reconstruct: X's block and one panel of N stay in L2.
constexpr Index kReconstructRows = 2048;

// y += M·x for symmetric M, reading its lower triangle.
template <typename T>
void symv_lower_add(const Matrix<T>& M, const T* x, T* y) {
#ifdef QPREDUCE_HAVE_AVX2_KERNELS
  if (cpu_has_avx2_fma()) {
    symv_lower_add_avx2(M.data(), M.rows(), M.outerStride(), x, y);
    return;
  }
#endif
  const Eigen::Map<const Vector<T>> xv(x, M.cols());
  Eigen::Map<Vector<T>> yv(y, M.rows());
  yv.noalias() += M.template selfadjointView<Eigen::Lower>() * xv;
}

}  // namespace

template <typename Scalar>
void SubspaceSolver<Scalar>::require_ready(const char* what) const {
  if (!ready_) {
    throw std::invalid_argument(std::string(what) + ": no subspace (precompute did not succeed)");
  }
}

template <typename Scalar>
void SubspaceSolver<Scalar>::require_constrained(const char* what) const {
  require_ready(what);
  if (!constrained_) throw std::invalid_argument(std::string(what) + ": call set_constraints first");
}

template <typename Scalar>
SubspaceSummary SubspaceSolver<Scalar>::precompute(const SparseMatrix<Scalar>& H, const SparseMatrix<Scalar>& C,
                                                   const SparseMatrix<Scalar>& D, const SubspaceOptions& options) {
  ready_ = constrained_ = false;
  detail::SubspaceExtras extras;
  SubspaceSummary summary = detail::build_subspace_with_extras(H, C, D, options, &subspace_, &extras);
  if (!summary.ok()) return summary;
  n_ = H.rows();
  // H_r = BᵀHB, from the build's blocked residual pass (subspace_internal.h).
  Hr_d_ = std::move(extras.Hr);
  BtD_d_ = std::move(extras.BtD);
  Hr_ = Hr_d_.template cast<Scalar>();
  BtD_ = BtD_d_.template cast<Scalar>();
  prepare_fast_path(options.reduced_lift_tolerance);
  ready_ = true;
  return summary;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::restore(VariationalSubspace<Scalar> subspace, Matrix<double> Hr, Matrix<double> BtD,
                                     const SubspaceOptions& options) {
  ready_ = constrained_ = false;
  const Index n = subspace.N.rows(), d = subspace.N.cols(), k = subspace.UD.cols();
  const Index p = d + k;
  detail::check_size("SubspaceSolver::restore: UD rows", n, subspace.UD.rows());
  detail::check_size("SubspaceSolver::restore: H_r rows", p, Hr.rows());
  detail::check_size("SubspaceSolver::restore: H_r cols", p, Hr.cols());
  detail::check_size("SubspaceSolver::restore: BᵀD rows", p, BtD.rows());
  detail::check_size("SubspaceSolver::restore: BᵀD cols", k, BtD.cols());
  if (d == 0) throw std::invalid_argument("SubspaceSolver::restore: N has no columns");
  detail::check_finite("SubspaceSolver::restore: N", subspace.N);
  detail::check_finite("SubspaceSolver::restore: UD", subspace.UD);
  detail::check_finite("SubspaceSolver::restore: H_r", Hr);
  detail::check_finite("SubspaceSolver::restore: BᵀD", BtD);
  const double asym = (Hr - Hr.transpose()).norm();
  if (asym > 1e-12 * std::max(1.0, Hr.norm())) {
    throw std::invalid_argument(fmt::format("SubspaceSolver::restore: H_r is not symmetric (‖H_r − H_rᵀ‖ = {:.3e})",
                                            asym));
  }
  subspace_ = std::move(subspace);
  n_ = n;
  Hr_d_ = std::move(Hr);
  BtD_d_ = std::move(BtD);
  Hr_ = Hr_d_.template cast<Scalar>();
  BtD_ = BtD_d_.template cast<Scalar>();
  prepare_fast_path(options.reduced_lift_tolerance);
  ready_ = true;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::prepare_fast_path(double lift_tolerance) {
  const Index p = Hr_d_.rows();
  // D_s = diag(H_r)^(−1/2); a column without energy keeps the largest scale.
  const double max_diag = p > 0 ? Hr_d_.diagonal().maxCoeff() : 0.0;
  scale_.resize(p);
  for (Index i = 0; i < p; ++i) {
    const double h = Hr_d_(i, i);
    scale_(i) = h > std::numeric_limits<double>::epsilon() * max_diag ? 1.0 / std::sqrt(h)
                : max_diag > 0                                          ? 1.0 / std::sqrt(max_diag)
                                                                        : 1.0;
  }
  inv_scale_ = scale_.cwiseInverse();
  const MatD Hbar = scale_.asDiagonal() * Hr_d_ * scale_.asDiagonal();
  const Eigen::SelfAdjointEigenSolver<MatD> es(0.5 * (Hbar + Hbar.transpose()));
  const Eigen::VectorXd& lambda = es.eigenvalues();
  hbar_max_ = p > 0 ? std::max(lambda.maxCoeff(), std::numeric_limits<double>::min()) : 1.0;
  const double sigma = hbar_max_;
  Eigen::VectorXd inv(p);
  std::vector<Index> lifted;
  for (Index i = 0; i < p; ++i) {
    if (lambda(i) <= lift_tolerance * sigma) {
      lifted.push_back(i);
      inv(i) = 1.0 / sigma;
    } else {
      inv(i) = 1.0 / lambda(i);
    }
  }
  const MatD DV = scale_.asDiagonal() * es.eigenvectors();  // D_s·V
  Minv0_ = DV * inv.asDiagonal() * DV.transpose();
  Minv0_ = 0.5 * (Minv0_ + Minv0_.transpose()).eval();
  const Index nu = static_cast<Index>(lifted.size());
  lift_cols_.resize(p, nu);
  lift_block_.resize(nu);
  for (Index j = 0; j < nu; ++j) {
    const Index i = lifted[static_cast<size_t>(j)];
    lift_cols_.col(j) = DV.col(i) / sigma;
    lift_block_(j) = -lambda(i) / (sigma * (sigma - lambda(i)));  // = 1/σ − 1/(σ − λ), without cancellation
  }
  P0_ = Minv0_ * BtD_d_;
}

// In unscaled coordinates (Y' = D_s·Y, see the header):
//   Y' = [M0·A_rᵀ, D_sV_L/σ],  M0 = D_sH̃⁻¹D_s,
//   Σ  = [[A_r·M0·A_rᵀ + c·I, A_r·D_sV_L/σ], [·, −λ_L/(σ(σ − λ_L))]],
//   M_q = M0 − Y'Σ⁻¹Y'ᵀ,  M_b = Y'Σ⁻¹[I; 0],  M_Y = M0·BᵀD − Y'Σ⁻¹(Y'ᵀBᵀD).
// With Σ = U·diag(s)·Uᵀ and W = Y'U, M_q is two symmetric rank-q updates of M0
// (one per sign of s), of which only the lower triangle is formed.
template <typename Scalar>
bool SubspaceSolver<Scalar>::fast_operators(const MatD& Ar, bool soft, double delta, double rank_tolerance,
                                            MatD* Mb, MatD* Mq, MatD* MY) const {
  const Index p = Ar.cols(), m = Ar.rows(), nu = lift_cols_.cols(), q = m + nu, k = P0_.cols();
  MatD Y(p, q);
  detail::blas_gemm(false, true, 1.0, Minv0_, Ar, 0.0, Y.leftCols(m));
  Y.rightCols(nu) = lift_cols_;
  MatD Sigma(q, q);
  detail::blas_gemm(false, false, 1.0, Ar, Y.leftCols(m), 0.0, Sigma.topLeftCorner(m, m));
  if (soft) Sigma.topLeftCorner(m, m).diagonal().array() += 1.0 / (2.0 * delta);
  Sigma.topRightCorner(m, nu).noalias() = Ar * lift_cols_;
  Sigma.bottomLeftCorner(nu, m) = Sigma.topRightCorner(m, nu).transpose();
  Sigma.bottomRightCorner(nu, nu) = lift_block_.asDiagonal();
  Sigma = 0.5 * (Sigma + Sigma.transpose()).eval();
  if (!Sigma.allFinite()) return false;
  const Eigen::SelfAdjointEigenSolver<MatD> es(Sigma);
  const Eigen::VectorXd& s = es.eigenvalues();  // ascending: negative ones first
  if (q > 0 && !(s.cwiseAbs().minCoeff() > 0.0)) return false;
  MatD W(p, q);
  detail::blas_gemm(false, false, 1.0, Y, es.eigenvectors(), 0.0, W);
  // Lower triangle of M_q = M0 − Σ_i w_i w_iᵀ / s_i.
  Index negative = 0;
  while (negative < q && s(negative) < 0.0) ++negative;
  const MatD Wscaled = W * s.cwiseAbs().cwiseSqrt().cwiseInverse().asDiagonal();
  *Mq = Minv0_;
  detail::blas_syrk_lower(1.0, Wscaled.leftCols(negative), 1.0, *Mq);
  detail::blas_syrk_lower(-1.0, Wscaled.rightCols(q - negative), 1.0, *Mq);
  // Accept only when the null-space method would call the problem
  // nonsingular: with M̄_q = D_s⁻¹M_qD_s⁻¹, ‖M̄_q‖₂ = 1/λ_min on the
  // constraint set (hard) or 1/λ_min(K̄) (soft), and λ_max there is at most
  // λ_max(H̄) (+ 2δ‖Ā‖² for soft).
  // (A NaN or Inf in M_q makes the bound non-finite, so this also checks M_q.)
  double norm2 = 0.0;
  for (Index j = 0; j < p; ++j) {
    const double sj = inv_scale_(j);
    const double diag = (*Mq)(j, j) * sj * sj;
    double col = 0.0;
    for (Index i = j + 1; i < p; ++i) {
      const double v = (*Mq)(i, j) * inv_scale_(i);
      col += v * v;
    }
    norm2 += diag * diag + 2.0 * col * sj * sj;
  }
  const double lambda_up =
      hbar_max_ + (soft ? 2.0 * delta * (Ar * scale_.asDiagonal()).squaredNorm() : 0.0);
  const double cond_bound = lambda_up * std::sqrt(norm2);
  if (!std::isfinite(cond_bound) || !(cond_bound * rank_tolerance < 1.0)) return false;
  // M_q's strict upper triangle is left as M0's: only the lower one is used.

  // T = W·diag(1/s): M_b = T·U(0:m, :)ᵀ, M_Y = P0 − T·(WᵀBᵀD).
  const MatD T = W * s.cwiseInverse().asDiagonal();
  Mb->resize(p, m);
  detail::blas_gemm(false, true, 1.0, T, es.eigenvectors().topRows(m), 0.0, *Mb);
  *MY = P0_;
  if (k > 0) {
    MatD WtBd(q, k);
    detail::blas_gemm(true, false, 1.0, W, BtD_d_, 0.0, WtBd);
    detail::blas_gemm(false, false, -1.0, T, WtBd, 1.0, *MY);
  }
  return Mb->allFinite() && MY->allFinite();
}

template <typename Scalar>
void SubspaceSolver<Scalar>::reference_operators(const MatD& Abar, const ConstraintOptions& options,
                                                 ConstraintSummary* summary, MatD* Mb_out, MatD* Mq_out,
                                                 MatD* MY_out) const {
  // The small QP in the scaled coordinates w̄ (w = D_s·w̄): Hessian D_s·H_r·D_s,
  // constraints Ā (m×p). Shared with the Phase 1 solver (detail/qp_operators.h).
  const auto& Ds = scale_.asDiagonal();
  const MatD Hbar = Ds * Hr_d_ * Ds;
  const detail::QpOperators ops = detail::qp_operators(Hbar, Abar, options, summary);
  const MatD& Mq = ops.Mg;
  const MatD& Mb = ops.Mc;
  *Mq_out = Ds * Mq * Ds;
  *Mq_out = 0.5 * (*Mq_out + Mq_out->transpose()).eval();
  *Mb_out = Ds * Mb;
  *MY_out = *Mq_out * BtD_d_;
}

template <typename Scalar>
ConstraintSummary SubspaceSolver<Scalar>::set_constraints(const SparseMatrix<Scalar>& A,
                                                          const ConstraintOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("ConstraintOptions: " + why);
  require_ready("SubspaceSolver::set_constraints");
  detail::check_size("SubspaceSolver::set_constraints: A rows", n_, A.rows());
  detail::check_finite("SubspaceSolver::set_constraints: A", A);
  const detail::Timer timer;
  const detail::ScopedOmpThreads threads(options.threads);
  constrained_ = false;
  const Index d = this->d(), k = this->k(), p = d + k, m = A.cols();
  // A_r = AᵀB: nnz(A)·p work for sparse A.
  MatD Ar(m, p);
  Ar.leftCols(d) = (A.transpose() * subspace_.N).template cast<double>();
  Ar.rightCols(k) = (A.transpose() * subspace_.UD).template cast<double>();
  ConstraintSummary summary = apply_constraints(std::move(Ar), options);
  summary.seconds = timer.seconds();
  return summary;
}

template <typename Scalar>
ConstraintSummary SubspaceSolver<Scalar>::set_constraints_in_design(const MatrixS& A_c,
                                                                    const ConstraintOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("ConstraintOptions: " + why);
  require_ready("SubspaceSolver::set_constraints_in_design");
  detail::check_size("SubspaceSolver::set_constraints_in_design: A_c rows", d(), A_c.rows());
  detail::check_finite("SubspaceSolver::set_constraints_in_design: A_c", A_c);
  const detail::Timer timer;
  const detail::ScopedOmpThreads threads(options.threads);
  constrained_ = false;
  // A_r = A_cᵀ·Cᵀ[N UD] = [A_cᵀ 0]: CᵀN = I and CᵀUD = 0 (Eq. 4, second row).
  MatD Ar = MatD::Zero(A_c.cols(), p());
  Ar.leftCols(d()) = A_c.transpose().template cast<double>();
  ConstraintSummary summary = apply_constraints(std::move(Ar), options);
  summary.seconds = timer.seconds();
  return summary;
}

template <typename Scalar>
ConstraintSummary SubspaceSolver<Scalar>::apply_constraints(MatD Ar, const ConstraintOptions& options) {
  ConstraintSummary summary;
  const Index m = Ar.rows();
  summary.m = m;
  const MatD Abar = Ar * scale_.asDiagonal();
  // The operators are formed in double: in place for Scalar = double (no
  // p × p copy), in scratch that is cast afterwards otherwise.
  MatD scratch_b, scratch_q, scratch_y;
  MatD* Mb_out = &scratch_b;
  MatD* Mq_out = &scratch_q;
  MatD* MY_out = &scratch_y;
  if constexpr (std::is_same_v<Scalar, double>) {
    Mb_out = &Mb_;
    Mq_out = &Mq_;
    MY_out = &MY_;
  }
  MatD &Mb = *Mb_out, &Mq = *Mq_out, &MY = *MY_out;

  bool fast = false;
  if (options.fast_path) {
    // The BLAS runs single-threaded here unless the caller asked for more.
    std::optional<detail::ScopedBlasThreads> blas;
    if (options.threads > 0) blas.emplace(options.threads);
    if (!options.soft) {
      // The fast path needs full row rank; the reference path handles the rest.
      Eigen::ColPivHouseholderQR<MatD> qr(Abar.transpose());
      qr.setThreshold(options.rank_tolerance);
      const bool nonzero = m > 0 && qr.matrixQR().diagonal().cwiseAbs().maxCoeff() > 0;
      const Index r = nonzero ? qr.rank() : 0;
      if (r == m && fast_operators(Ar, false, 0.0, options.rank_tolerance, &Mb, &Mq, &MY)) {
        fast = true;
        summary.rank = r;
        if (m > 0) {
          // Ā's singular values are R's (ĀᵀΠ = QR).
          const MatD R = qr.matrixQR().topRows(m).template triangularView<Eigen::Upper>();
          const Eigen::JacobiSVD<MatD> svd(R);
          const auto& sv = svd.singularValues();
          summary.condition = sv(0) / sv(m - 1);
        }
        summary.status = Status::Success;
        summary.message = fmt::format("{} hard constraints, rank {}", m, r);
      }
    } else if (fast_operators(Ar, true, options.delta, options.rank_tolerance, &Mb, &Mq, &MY)) {
      fast = true;
      summary.rank = m > 0 ? Eigen::ColPivHouseholderQR<MatD>(Abar).rank() : 0;
      summary.status = Status::Success;
      summary.message = fmt::format("{} soft constraints, δ = {:.3g}", m, options.delta);
    }
  }
  if (!fast) {
    reference_operators(Abar, options, &summary, &Mb, &Mq, &MY);
    if (options.soft) summary.rank = m > 0 ? Eigen::ColPivHouseholderQR<MatD>(Abar).rank() : 0;
  }
  summary.fast_path = fast;

  Ar_ = Ar.template cast<Scalar>();
  if constexpr (!std::is_same_v<Scalar, double>) {
    Mb_ = Mb.template cast<Scalar>();
    Mq_ = Mq.template cast<Scalar>();
    MY_ = MY.template cast<Scalar>();
  }
  m_ = m;
  constrained_ = true;
  return summary;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::reduce_linear_term(const ConstRef& q, Ref q_r) const {
  require_ready("SubspaceSolver::reduce_linear_term");
  detail::check_size("SubspaceSolver::reduce_linear_term: q size", n_, q.size());
  detail::check_size("SubspaceSolver::reduce_linear_term: q_r size", p(), q_r.size());
  // Column dot products, OpenMP over column blocks of the basis.
  const Index d = this->d(), p = this->p();
  constexpr Index kCols = 8;
  const Index blocks = (p + kCols - 1) / kCols;
#pragma omp parallel for schedule(static) if (n_ * p > kParallelEntries)
  for (Index b = 0; b < blocks; ++b) {
    const Index j0 = b * kCols, j1 = std::min(p, j0 + kCols);
    for (Index j = j0; j < j1; ++j) q_r(j) = j < d ? subspace_.N.col(j).dot(q) : subspace_.UD.col(j - d).dot(q);
  }
}

template <typename Scalar>
void SubspaceSolver<Scalar>::reduce_linear_term_in_D(const ConstRef& Y, Ref q_r) const {
  require_ready("SubspaceSolver::reduce_linear_term_in_D");
  detail::check_size("SubspaceSolver::reduce_linear_term_in_D: Y size", k(), Y.size());
  detail::check_size("SubspaceSolver::reduce_linear_term_in_D: q_r size", p(), q_r.size());
  q_r.noalias() = BtD_ * Y;
}

template <typename Scalar>
void SubspaceSolver<Scalar>::solve(const ConstRef& b, const ConstRef& q_r, Ref w) const {
  assert(constrained_ && b.size() == m_ && q_r.size() == p() && w.size() == p());
  gemv(Mb_, b.data(), w.data(), false);
  symv_lower_add(Mq_, q_r.data(), w.data());
}

template <typename Scalar>
void SubspaceSolver<Scalar>::solve_in_D(const ConstRef& b, const ConstRef& Y, Ref w) const {
  assert(constrained_ && b.size() == m_ && Y.size() == k() && w.size() == p());
  gemv(Mb_, b.data(), w.data(), false);
  gemv(MY_, Y.data(), w.data(), true);
}

template <typename Scalar>
void SubspaceSolver<Scalar>::reconstruct(const ConstRef& w, Ref X) const {
  require_ready("SubspaceSolver::reconstruct");
  detail::check_size("SubspaceSolver::reconstruct: w size", p(), w.size());
  detail::check_size("SubspaceSolver::reconstruct: X size", n_, X.size());
  // Row blocks, OpenMP: X_r = N_r·z + UD_r·y.
  const Index d = this->d(), k = this->k();
  const Index blocks = (n_ + kReconstructRows - 1) / kReconstructRows;
#pragma omp parallel for schedule(static) if (n_ * p() > kParallelEntries)
  for (Index b = 0; b < blocks; ++b) {
    const Index r = b * kReconstructRows, len = std::min(kReconstructRows, n_ - r);
    Scalar* x = X.data() + r;
    std::fill(x, x + len, Scalar(0));
    gemv_add(subspace_.N.data() + r, len, d, subspace_.N.outerStride(), w.data(), x);
    gemv_add(subspace_.UD.data() + r, len, k, subspace_.UD.outerStride(), w.data() + d, x);
  }
}

template class SubspaceSolver<double>;
template class SubspaceSolver<float>;

}  // namespace qpreduce
