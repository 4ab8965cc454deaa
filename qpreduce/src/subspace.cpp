#include "qpreduce/subspace.h"

#include "blas.h"
#include "simd_kernels.h"
#include "subspace_internal.h"

#include "dense.h"

#include <Eigen/Eigenvalues>
#include <Eigen/SparseCholesky>
#include <fmt/format.h>

#include <omp.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <optional>
#include <vector>

namespace qpreduce {

bool SubspaceOptions::is_valid(std::string* why) const {
  auto fail = [why](const std::string& msg) {
    if (why) *why = msg;
    return false;
  };
  if (!(rho_scale > 0.0) || !std::isfinite(rho_scale)) return fail("rho_scale must be positive and finite");
  if (!(max_augmentation_fill > 0.0)) return fail("max_augmentation_fill must be positive");
  if (block_size < 1) return fail("block_size must be at least 1");
  if (!(symmetry_tolerance >= 0.0)) return fail("symmetry_tolerance must be non-negative");
  if (!(psd_shift > 0.0)) return fail("psd_shift must be positive");
  if (!(rank_tolerance > 0.0 && rank_tolerance < 1.0)) return fail("rank_tolerance must lie in (0, 1)");
  if (!(max_probe_error > 0.0)) return fail("max_probe_error must be positive");
  if (!(reduced_lift_tolerance >= 0.0 && reduced_lift_tolerance < 1.0)) {
    return fail("reduced_lift_tolerance must lie in [0, 1)");
  }
  return true;
}

std::string SubspaceSummary::brief_report() const {
  return fmt::format("{}: {} (n={}, d={}, k={}, backend={}, rho={:.3g}, kkt_residual={:.2e}, {:.3f} s)",
                     to_string(status), message, n, d, k, to_string(backend_used), rho,
                     kkt_residual, total_seconds);
}

namespace detail {

namespace {
using SpD = SparseMatrix<double>;
using MatD = Matrix<double>;
}  // namespace

SpD kkt_matrix(const SpD& H, const SpD& C) {
  const Index n = H.rows(), d = C.cols();
  std::vector<Eigen::Triplet<double>> t;
  t.reserve(H.nonZeros() + 2 * C.nonZeros());
  for (Index j = 0; j < n; ++j)
    for (SpD::InnerIterator it(H, j); it; ++it) t.emplace_back(it.row(), j, it.value());
  for (Index j = 0; j < d; ++j)
    for (SpD::InnerIterator it(C, j); it; ++it) {
      t.emplace_back(it.row(), n + j, it.value());
      t.emplace_back(n + j, it.row(), it.value());
    }
  SpD K(n + d, n + d);
  K.setFromTriplets(t.begin(), t.end());
  return K;
}

// Columns per block of the blocked residual / BᵀHB pass.
constexpr Index kResidualColumns = 32;

// (subspace_internal.h)
void blocked_pass(const SpD& H, const SpD& C, const SpD& D, const MatD& N, const MatD& UD, double* residual,
                  MatD* gram) {
  const Index d = N.cols(), k = UD.cols(), p = d + k;
  // CᵀC is as sparse as C's column overlaps (diagonal for a selection): a
  // sparse factor, not a dense d × d one.
  const Eigen::SimplicialLDLT<SpD> CtC(SpD(C.transpose() * C));
  const Index nb_d = (d + kResidualColumns - 1) / kResidualColumns;
  const Index nb_k = (k + kResidualColumns - 1) / kResidualColumns;
  if (gram) gram->setZero(p, p);
  const ScopedBlasThreads one_blas_thread(1);  // the OpenMP loop below calls the BLAS from each thread
  // H by rows (a copy, so that H need not be exactly symmetric) for the
  // row-major panel product of sparse_times_block.
  const Eigen::SparseMatrix<double, Eigen::RowMajor, int> Hrows = H;
  double r1sq = 0.0, r2sq = 0.0;
  // Later blocks have taller Gram panels: hand them out first.
#pragma omp parallel reduction(+ : r1sq, r2sq)
  {
    MatD HBbuf(H.rows(), kResidualColumns);  // reused: fresh n-sized buffers cost page faults
    std::vector<double> panel(static_cast<size_t>(H.cols() * kResidualColumns));
#pragma omp for schedule(dynamic, 1)
    for (Index bb = 0; bb < nb_d + nb_k; ++bb) {
      const Index b = nb_d + nb_k - 1 - bb;
      const bool in_n = b < nb_d;
      const Index j = (in_n ? b : b - nb_d) * kResidualColumns;
      const Index w = std::min(kResidualColumns, (in_n ? d : k) - j);
      const Index col = in_n ? j : d + j;  // first column of the block in B
      const auto Bj = in_n ? N.middleCols(j, w) : UD.middleCols(j, w);
      auto HB = HBbuf.leftCols(w);
      sparse_times_block(Hrows, Bj.data(), Bj.outerStride(), w, panel.data(), HB.data(), HB.outerStride());
      if (gram) {
        const Index end = col + w, rows_n = std::min(d, end), rows_u = std::max<Index>(0, end - d);
        blas_gemm(true, false, 1.0, N.leftCols(rows_n), HB, 0.0, gram->block(0, col, rows_n, w));
        if (rows_u > 0) blas_gemm(true, false, 1.0, UD.leftCols(rows_u), HB, 0.0, gram->block(d, col, rows_u, w));
      }
      if (residual) {
        if (!in_n) HB -= D.middleCols(j, w);
        const MatD coef = CtC.solve(MatD(C.transpose() * HB));
        HB.noalias() -= C * coef;
        r1sq += HB.squaredNorm();
        MatD R2 = C.transpose() * Bj;
        if (in_n) R2.middleRows(j, w) -= MatD::Identity(w, w);
        r2sq += R2.squaredNorm();
      }
    }
  }
  if (gram) {
    const MatD upper = *gram;
    gram->triangularView<Eigen::StrictlyLower>() = upper.transpose();
  }
  if (residual) {
    const double bnorm = std::sqrt(N.squaredNorm() + UD.squaredNorm());
    // (Eigen asserts on the norm of a matrix with no columns: k = 0 is valid.)
    const double scale1 = H.norm() * bnorm + (D.cols() > 0 ? D.norm() : 0.0);
    const double scale2 = C.norm() * bnorm;
    const double r1 = scale1 > 0 ? std::sqrt(r1sq) / scale1 : std::sqrt(r1sq);
    const double r2 = scale2 > 0 ? std::sqrt(r2sq) / scale2 : std::sqrt(r2sq);
    *residual = std::max(r1, r2);
  }
}

// S as a dense matrix whose every page is written first, by the OpenMP
// threads. MatD(S) lets the compiler turn the allocation and the zero fill
// into one calloc, whose fresh pages the solve then reads before writing:
// each page is first mapped to the shared zero page, and the write that
// follows copies it and flushes the other threads' TLBs (an interrupt per
// page; about 1 s of CPU on 121k × 342 right-hand sides).
MatD dense_written(const SpD& S) {
  MatD out(S.rows(), S.cols());
#pragma omp parallel for schedule(static)
  for (Index j = 0; j < S.cols(); ++j) {
    out.col(j).setZero();
    for (SpD::InnerIterator it(S, j); it; ++it) out(it.row(), j) = it.value();
  }
  return out;
}

// Solves K·x = K·v for a fixed v and returns ‖x − v‖/‖v‖: a direct measure of
// whether the factorization can be trusted (near-singular factors that slipped
// through a tiny pivot give O(1) errors along their null vectors).
double probe_error(const SparseFactorization& factor, const SpD& K) {
  Eigen::VectorXd v(K.rows());
  for (Index i = 0; i < v.size(); ++i) v(i) = std::sin(1.0 + 0.7 * static_cast<double>(i));  // deterministic
  MatD x = K.selfadjointView<Eigen::Lower>() * v;
  if (factor.backend() == Backend::SparseLU) x = K * v;
  factor.solveInPlace(x, 1);
  const double err = (x.col(0) - v).norm() / v.norm();
  return std::isfinite(err) ? err : INFINITY;
}

void snap_selected_rows(const SpD& C, Index row_begin, MatD& N, MatD& UD) {
  const Index rows = N.rows();
  for (Index j = 0; j < C.cols(); ++j) {
    if (C.col(j).nonZeros() != 1) continue;
    const SpD::InnerIterator it(C, j);
    const Index r = it.row() - row_begin;
    if (it.value() == 0.0 || r < 0 || r >= rows) continue;
    N.row(r).setZero();
    N(r, j) = 1.0 / it.value();
    if (UD.cols() > 0) UD.row(r).setZero();
  }
}

double gershgorin_bound(const SpD& A) {
  double top = 0.0;
  for (Index j = 0; j < A.outerSize(); ++j) {
    double sum = 0.0;
    for (SpD::InnerIterator it(A, j); it; ++it) sum += std::abs(it.value());
    top = std::max(top, sum);
  }
  return top;
}

ScopedOmpThreads::ScopedOmpThreads(int threads) : previous_(omp_get_max_threads()) {
  if (threads > 0) omp_set_num_threads(threads);
}
ScopedOmpThreads::~ScopedOmpThreads() { omp_set_num_threads(previous_); }

MatD sparse_transpose_times(const SpD& S, const MatD& X) {
  const Index n = S.rows(), a = S.cols(), b = X.cols();
  assert(X.rows() == n);
  const double density = n > 0 && a > 0 ? static_cast<double>(S.nonZeros()) / (static_cast<double>(n) * a) : 0.0;
  // Below this density Eigen's sparse product (nnz·b) beats densifying.
  constexpr double kDenseFrom = 0.05;
  if (density < kDenseFrom || !S.isCompressed()) return MatD(S.transpose() * X);
  const Index blocks = (n + kRowBlock - 1) / kRowBlock;
  MatD result = MatD::Zero(a, b);
  const ScopedBlasThreads one_blas_thread(1);
#pragma omp parallel
  {
    MatD partial = MatD::Zero(a, b), dense(kRowBlock, a);
#pragma omp for schedule(static)
    for (Index blk = 0; blk < blocks; ++blk) {
      const Index r0 = blk * kRowBlock, len = std::min(kRowBlock, n - r0);
      dense.setZero();
      for (Index j = 0; j < a; ++j) {
        const int* rows = S.innerIndexPtr();
        const Index begin = S.outerIndexPtr()[j], end = S.outerIndexPtr()[j + 1];
        const int* first = std::lower_bound(rows + begin, rows + end, static_cast<int>(r0));
        for (Index t = first - rows; t < end && rows[t] < r0 + len; ++t) dense(rows[t] - r0, j) = S.valuePtr()[t];
      }
      blas_gemm(true, false, 1.0, dense.topRows(len), X.middleRows(r0, len), 1.0, partial);
    }
#pragma omp critical
    result += partial;
  }
  return result;
}

}  // namespace detail
void SubspaceSummary::add_details(Report* out) const {
  out->add("backend_used", backend_used)
      .add("n", n)
      .add("d", d)
      .add("k", k)
      .add("rho", rho)
      .add("factor_nonzeros", factor_nonzeros)
      .add("kkt_residual", kkt_residual)
      .add("probe_error", probe_error)
      .add("s_condition", s_condition)
      .add("ud_condition", ud_condition)
      .add("check_psd_seconds", check_psd_seconds)
      .add("factorize_seconds", factorize_seconds)
      .add("solve_seconds", solve_seconds)
      .add("total_seconds", total_seconds);
}

}  // namespace qpreduce
