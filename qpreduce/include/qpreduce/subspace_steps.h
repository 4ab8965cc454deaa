// qpreduce — the dense steps of a subspace build (Eq. 4–5) for backends that
// solve the KKT columns with a solver of their own (qpreduce::distributed,
// MUMPS over MPI): the same rank tests and the same exact rows as
// build_subspace, so that every backend gives the same subspace.
#pragma once

#include "qpreduce/common.h"

#include <Eigen/Core>

namespace qpreduce {

// Eigenvalues of the symmetric S (d × d; its lower triangle is read),
// ascending. NaN entries when the eigensolver does not converge, which every
// comparison then refuses. LAPACK's dsyevd from 400 rows, Eigen below.
Eigen::VectorXd symmetric_eigenvalues(const Matrix<double>& S);

// The number of eigenvalues above tolerance · max|λ| (0 for an all-zero or
// empty matrix): the numerical rank build_subspace tests CᵀC and the
// reduced Hessians with (SubspaceOptions::rank_tolerance).
Index numerical_rank(const Eigen::VectorXd& eigenvalues, double tolerance);

// Rows of B = [N UD] that C fixes: a column j of C with one nonzero c, in
// row r, states N(r, :) = e_jᵀ/c and UD(r, :) = 0 (CᵀN = I, CᵀUD = 0); those
// rows are written exactly where the solves left them at round-off.
// Inputs:
//   C          n × d sparse design columns
//   row_begin  the first of the rows N and UD hold
// In/out:
//   N, UD      rows [row_begin, row_begin + N.rows()) of the basis (all n,
//              or one MPI rank's), d and k columns (UD may have none)
void snap_selected_rows(const SparseMatrix<double>& C, Index row_begin, Matrix<double>& N, Matrix<double>& UD);

// Rows per block of the row-blocked dense passes over N and UD.
inline constexpr Index kSubspaceRowBlock = 512;

}  // namespace qpreduce
