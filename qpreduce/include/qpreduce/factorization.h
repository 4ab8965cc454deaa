// qpreduce — sparse factorization backends behind one small interface.
//
// Every backend speaks Eigen's vocabulary: analyzePattern / factorize / info,
// plus a blocked multi-right-hand-side solve. Factorizations always run in
// double precision, whatever Scalar the caller uses for its results: CHOLMOD
// only supports double, and a float Cholesky of a 10⁵-row Laplacian loses
// every digit of the small eigen-directions the subspace depends on.
//
//   Backend::Cholmod        CHOLMOD supernodal LLᵀ (symmetric positive definite;
//                           BLAS-3 solves over whole right-hand-side blocks,
//                           in place; optional ordering of grouped unknowns).
//   Backend::SimplicialLDLT Eigen SimplicialLDLT with AMD ordering
//                           (symmetric positive definite; OpenMP over column
//                           blocks); reports the inertia of its pivots.
//   Backend::SparseLU       Eigen SparseLU with COLAMD (any nonsingular square
//                           matrix; used for the KKT matrix itself).
#pragma once

#include "qpreduce/common.h"

#include <memory>
#include <string>
#include <vector>

namespace qpreduce {

enum class Backend { Auto, Cholmod, SimplicialLDLT, SparseLU };

const char* to_string(Backend backend);

class SparseFactorization {
 public:
  virtual ~SparseFactorization() = default;

  // A is square; symmetric backends read its lower triangle only.
  virtual void analyzePattern(const SparseMatrix<double>& A) = 0;
  virtual void factorize(const SparseMatrix<double>& A) = 0;
  // Eigen::Success, or NumericalIssue with message() saying why.
  virtual Eigen::ComputationInfo info() const = 0;
  virtual const std::string& message() const = 0;
  // Overwrites B (rows = A.rows(), any column count) with A⁻¹B. Columns are
  // solved in blocks of `block_size`.
  virtual void solveInPlace(Matrix<double>& B, Index block_size) const = 0;
  virtual Backend backend() const = 0;
  // Number of structurally nonzero entries in the factor(s), for reports.
  virtual Index factorNonZeros() const = 0;

  // Optional, before analyzePattern: group[i] ∈ [0, g) for each of the n
  // unknowns. The fill-reducing ordering is then computed on the g-node
  // quotient graph (groups i ~ j when some A_ab ≠ 0 with a in i, b in j) and
  // each group's unknowns are eliminated together. For mesh problems (the
  // coordinates of a vertex) it makes the ordering cheaper at about the same
  // fill (measured in docs/performance.md). Backends without a separate ordering step ignore it (the
  // default); an empty vector restores ordering the unknowns themselves.
  virtual void setOrderingGroups(std::vector<Index> group) { (void)group; }

  void compute(const SparseMatrix<double>& A) {
    analyzePattern(A);
    if (info() == Eigen::Success) factorize(A);
  }
};

// Backend::Auto gives Cholmod. For SPD backends a matrix that is not positive
// definite gives NumericalIssue with a message naming the failure.
std::unique_ptr<SparseFactorization> make_factorization(Backend backend);

// CHOLMOD's simplicial LDLᵀ, for many solves of a few right-hand sides each
// (a local-global round's three axes): its solve sweeps the factor once for
// up to four columns together, where Eigen's SimplicialLDLT sweeps it once
// per column and CHOLMOD's supernodal solve spends more on its per-supernode
// BLAS calls than on the arithmetic. Symmetric positive definite (a matrix
// that is not gives NumericalIssue, as SimplicialLDLT's inertia test);
// backend() reports Backend::Cholmod.
std::unique_ptr<SparseFactorization> make_cholmod_simplicial_factorization();

}  // namespace qpreduce
