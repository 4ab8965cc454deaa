// Private to qpreduce::distributed: one MUMPS instance (double, real) over an
// MPI communicator, fed distributed COO rows, solving centralized blocks.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/distributed/mumps_subspace.h"

#include <dmumps_c.h>
#include <mpi.h>

#include <string>

namespace qpreduce::distributed::detail {

enum class Symmetry { PositiveDefinite = 1, Indefinite = 2 };

class MumpsSolver {
 public:
  // Collective: JOB = −1 with PAR = 1 (the host also works), output silenced.
  MumpsSolver(MPI_Comm comm, Symmetry symmetry, const MumpsOptions& options);
  ~MumpsSolver();  // JOB = −2, collective
  MumpsSolver(const MumpsSolver&) = delete;
  MumpsSolver& operator=(const MumpsSolver&) = delete;

  // Collective analysis + factorization of the N × N symmetric matrix whose
  // rows [row_begin, row_begin + rows.rows()) this rank holds in `rows`
  // (rows.rows() × N); the entries with column ≤ row (the lower triangle) are
  // passed. Returns ok(); on failure message() names INFOG(1).
  bool factor(const SparseMatrix<double>& rows, Index row_begin, Index N);
  // INFOG(1) ≥ 0 after the last call (the same value on every rank).
  bool ok() const { return id_.infog[0] >= 0; }
  // INFOG(12): negative pivots of the last factorization.
  Index negative_pivots() const { return id_.infog[11]; }
  int infog1() const { return id_.infog[0]; }
  int infog2() const { return id_.infog[1]; }
  double megabytes_max() const { return id_.infog[20]; }
  double megabytes_total() const { return id_.infog[21]; }
  Index factor_nonzeros() const;
  std::string message() const;   // "MUMPS INFOG(1) = −10, INFOG(2) = …: numerically singular matrix"
  std::string ordering() const;  // which ordering the analysis used

  // Collective: on rank 0 `rhs` (N × b, column-major, contiguous) is
  // overwritten with A⁻¹·rhs; on other ranks it is not read.
  bool solve_on_root(Matrix<double>& rhs);

 private:
  void run(int job);
  static void one_scotch_thread_unless_mpi_allows();
  DMUMPS_STRUC_C id_{};
  int rank_ = 0, size_ = 1;
  bool parallel_ordering_ = false;
};

}  // namespace qpreduce::distributed::detail
