// qpreduce — full-space reference solve of Eq. 1, for comparisons.
//
//     min_X ½XᵀHX − qᵀX   s.t.  AᵀX = b,   H n×n PSD, A n×m, b m×1, q n×1.
//
// This is the variational subspace of the demand itself: with C = A and
// D = q (one column), Eq. 5 gives X* = N·b + UD·1 exactly. So the reference
// shares the engine's factorization code (one Cholesky of H + ρAAᵀ and m + 1
// solves, or SparseLU of the KKT matrix) and its checks: A must have full
// column rank and H must be positive definite on ker(Aᵀ).
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/subspace.h"

namespace qpreduce {

struct FullSolveSummary : Outcome {
  Backend backend_used = Backend::Auto;
  double kkt_residual = -1.0;  // as SubspaceSummary::kkt_residual, for [X]
  double seconds = 0.0;

 protected:
  void add_details(Report* out) const override;
};

// Throws std::invalid_argument on wrong sizes or NaN input. `X` is resized to n
// on success and left empty otherwise. `options.check_dependent_cd` is ignored
// (a linear term inside Span(A) is legitimate).
template <typename Scalar>
FullSolveSummary solve_full(const SparseMatrix<Scalar>& H, const SparseMatrix<Scalar>& A,
                            const Vector<Scalar>& b, const Vector<Scalar>& q, Vector<Scalar>* X,
                            const SubspaceOptions& options = {});

}  // namespace qpreduce
