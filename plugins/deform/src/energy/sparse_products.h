// Internal: sparse × sparse products of the precompute's assembly, by
// column slices on the OpenMP threads (Eigen's sparse product is
// sequential), and the identity test that lets P·H·Pᵀ be skipped.
#pragma once

#include <qpreduce/common.h>

#include <omp.h>

#include <algorithm>
#include <cstring>
#include <vector>

namespace qpreduce::deform::detail {

// True when P is the identity (square, one unit entry per column on the
// diagonal): the control matrix of a mesh with every vertex free and no patch.
inline bool is_identity(const SparseMatrix<double>& P) {
  if (P.rows() != P.cols() || P.nonZeros() != P.cols()) return false;
  for (Index j = 0; j < P.cols(); ++j) {
    SparseMatrix<double>::InnerIterator it(P, j);
    if (!it || it.row() != j || it.value() != 1.0) return false;
  }
  return true;
}

// A·B, computed as [A·B(:, J_1) … A·B(:, J_T)] over T column slices J_t of
// B of about equal nonzero count, one per thread, then concatenated. Each
// column of the result is the one Eigen's sequential product gives (the same
// operations in the same order), so the two agree bitwise.
inline SparseMatrix<double> parallel_product(const SparseMatrix<double>& A, const SparseMatrix<double>& B) {
  const Index cols = B.cols();
  const int threads = omp_in_parallel() ? 1 : omp_get_max_threads();
  if (threads <= 1 || cols < 4 * threads || !B.isCompressed()) return SparseMatrix<double>(A * B);
  // Slice boundaries by B's nonzeros (a proxy for the work of each column).
  std::vector<Index> bound(static_cast<size_t>(threads) + 1, cols);
  bound[0] = 0;
  const Index nnz = B.nonZeros();
  for (int t = 1; t < threads; ++t) {
    const Index target = nnz * t / threads;
    const int* outer = B.outerIndexPtr();
    bound[static_cast<size_t>(t)] = std::lower_bound(outer, outer + cols, static_cast<int>(target)) - outer;
  }
  std::vector<SparseMatrix<double>> part(static_cast<size_t>(threads));
#pragma omp parallel for schedule(static, 1) num_threads(threads)
  for (int t = 0; t < threads; ++t) {
    const Index c0 = bound[static_cast<size_t>(t)], c1 = std::max(c0, bound[static_cast<size_t>(t) + 1]);
    part[static_cast<size_t>(t)] = A * B.middleCols(c0, c1 - c0);
    part[static_cast<size_t>(t)].makeCompressed();
  }
  Index total = 0;
  for (const auto& p : part) total += p.nonZeros();
  SparseMatrix<double> R(A.rows(), cols);
  R.resizeNonZeros(total);
  Index offset = 0, col = 0;
  for (auto& p : part) {
    for (Index j = 0; j < p.cols(); ++j) R.outerIndexPtr()[col + j] = static_cast<int>(offset + p.outerIndexPtr()[j]);
    if (p.nonZeros() > 0) {  // (an empty part, or an empty R, may have null storage)
      std::memcpy(R.innerIndexPtr() + offset, p.innerIndexPtr(), sizeof(int) * static_cast<size_t>(p.nonZeros()));
      std::memcpy(R.valuePtr() + offset, p.valuePtr(), sizeof(double) * static_cast<size_t>(p.nonZeros()));
    }
    offset += p.nonZeros();
    col += p.cols();
    p = SparseMatrix<double>();
  }
  R.outerIndexPtr()[cols] = static_cast<int>(offset);
  return R;
}

}  // namespace qpreduce::deform::detail
