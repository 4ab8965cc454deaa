// Private to the engine: products a subspace build computes anyway (or can
// compute in the same pass) and the reduced solver needs.
#pragma once

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

// Sᵀ·X for sparse S (n × a) and dense X (n × b): row-blocked dense products
// when S is mostly full (Gaussian or polynomial design columns), Eigen's
// sparse product otherwise. OpenMP over row blocks.
Matrix<double> sparse_transpose_times(const SparseMatrix<double>& S, const Matrix<double>& X);

}  // namespace qpreduce::detail
