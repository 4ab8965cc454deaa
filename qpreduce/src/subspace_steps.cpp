// The public face of a subspace build's dense steps (subspace_steps.h).
#include "qpreduce/subspace_steps.h"

#include "dense.h"
#include "subspace_internal.h"

namespace qpreduce {

static_assert(kSubspaceRowBlock == detail::kRowBlock, "one row block for every backend");

Eigen::VectorXd symmetric_eigenvalues(const Matrix<double>& S) { return detail::symmetric_eigenvalues(S); }

Index numerical_rank(const Eigen::VectorXd& eigenvalues, double tolerance) {
  return detail::numerical_rank(eigenvalues, tolerance);
}

void snap_selected_rows(const SparseMatrix<double>& C, Index row_begin, Matrix<double>& N, Matrix<double>& UD) {
  detail::snap_selected_rows(C, row_begin, N, UD);
}

}  // namespace qpreduce
