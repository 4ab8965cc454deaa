// Private to the engine: products a subspace build computes anyway (or can
// compute in the same pass) and the reduced solver needs.
#pragma once

#include "qpreduce/factorization.h"
#include "qpreduce/subspace.h"

namespace qpreduce::detail {

struct SubspaceExtras {
  // H_r = BᵀHB for B = [N UD] as built (p × p, symmetric), computed in the
  // same blocked pass as the KKT residual (one H·B). Computed from the
  // rounded B rather than from the multipliers of Eq. 4 (H·B = [0 D] − CΛ,
  // which would give it for free): the reduced problem is then exact for the
  // subspace actually stored, which keeps ill-conditioned demands accurate.
  Matrix<double> Hr;
  // BᵀD (p × k), in double.
  Matrix<double> BtD;
};

// build_subspace, also filling `extras` (when not null) on success.
template <typename Scalar>
SubspaceSummary build_subspace_with_extras(const SparseMatrix<Scalar>& H, const SparseMatrix<Scalar>& C,
                                           const SparseMatrix<Scalar>& D, const SubspaceOptions& options,
                                           VariationalSubspace<Scalar>* out, SubspaceExtras* extras);

// Sets this thread's OpenMP team size for the scope (omp_set_num_threads
// changes only the calling thread's setting), restoring it afterwards. Eigen's
// dense products read it through omp_get_max_threads().
class ScopedOmpThreads {
 public:
  explicit ScopedOmpThreads(int threads);
  ~ScopedOmpThreads();
  ScopedOmpThreads(const ScopedOmpThreads&) = delete;
  ScopedOmpThreads& operator=(const ScopedOmpThreads&) = delete;

 private:
  int previous_ = 0;
};

// Rows per block for the row-blocked dense passes (N = G·S⁻¹, Dᵀ·X): a
// 512 × 300 double block is 1.2 MB, a few L2-sized panels for the GEMM kernel.
constexpr Index kRowBlock = 512;

// ---- Steps of a subspace build (subspace.cpp, used by subspace_build.cpp) ----

// The KKT matrix [[H, C], [Cᵀ, 0]] of Eq. 4, (n + d) × (n + d).
SparseMatrix<double> kkt_matrix(const SparseMatrix<double>& H, const SparseMatrix<double>& C);

// One pass over column blocks B_j of B = [N UD] (OpenMP over blocks, so no
// n × p temporary), each with one sparse product H·B_j, computing
//   * `residual` (when not null): the relative residual of Eq. 4, see
//     SubspaceSummary::kkt_residual — H·B_j, projected off Span(C);
//   * `gram` (when not null): H_r = BᵀHB (p × p), the blocks on and above the
//     diagonal as B(:, :j_end)ᵀ·(H·B_j), mirrored below.
void blocked_pass(const SparseMatrix<double>& H, const SparseMatrix<double>& C, const SparseMatrix<double>& D,
                  const Matrix<double>& N, const Matrix<double>& UD, double* residual, Matrix<double>* gram);

// S (n × a) as a dense matrix whose every page is first written by the
// OpenMP threads (no zero-page faults in the solve that follows).
Matrix<double> dense_written(const SparseMatrix<double>& S);

// Solves K·x = K·v for a fixed v and returns ‖x − v‖/‖v‖ (+inf if not
// finite): whether the factorization of K can be trusted.
double probe_error(const SparseFactorization& factor, const SparseMatrix<double>& K);

// Rows of B = [N UD] that C fixes: a column j of C with one nonzero c, in
// row r, states N(r, :) = e_jᵀ/c and UD(r, :) = 0 (CᵀN = I, CᵀUD = 0);
// those rows are written exactly, where the solves left them at round-off.
// A proxy that is one unknown (a vertex coordinate) is then met to the bit
// by any Y, and constraints on such unknowns are exact selections of z
// (phase_one.h). N (rows × d) and UD (rows × k) hold rows
// [row_begin, row_begin + rows) of the whole basis (all n rows, or one MPI
// rank's); UD may have no columns.
void snap_selected_rows(const SparseMatrix<double>& C, Index row_begin, Matrix<double>& N, Matrix<double>& UD);

// Gershgorin bound on λ_max of a symmetric sparse matrix: max column sum of |a_ij|.
double gershgorin_bound(const SparseMatrix<double>& A);

// Sᵀ·X for sparse S (n × a) and dense X (n × b): row-blocked dense products
// when S is mostly full (Gaussian or polynomial design columns), Eigen's
// sparse product otherwise. OpenMP over row blocks.
Matrix<double> sparse_transpose_times(const SparseMatrix<double>& S, const Matrix<double>& X);

}  // namespace qpreduce::detail
