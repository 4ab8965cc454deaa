// Builds against the installed qpreduce::distributed: every rank builds the
// subspace of one small grid problem with MUMPS, collectively, and checks the
// summary and Cᵀ·N = I (summed over the ranks' rows).
#include <qpreduce/distributed/mumps_subspace.h>
#include <qpreduce/problems/generators.h>

#include <mpi.h>

#include <cstdio>

int main(int argc, char** argv) {
  using namespace qpreduce;
  MPI_Init(&argc, &argv);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  const SparseMatrix<double> H = generators::grid_laplacian_2d(10, 10);
  const SparseMatrix<double> C = generators::selection(100, {0, 45, 99});
  const SparseMatrix<double> D = generators::grid_trend_basis(10, 10, 2);
  const distributed::RowRange rows = distributed::owned_rows(H.rows(), MPI_COMM_WORLD);
  const SparseMatrix<double> H_rows = H.middleRows(rows.begin, rows.size());
  distributed::DistributedSubspace part;
  const distributed::DistributedSummary s =
      distributed::build_subspace_mumps(MPI_COMM_WORLD, H_rows, C, D, {}, {}, &part);
  int failed = s.ok() ? 0 : 1;
  if (!failed) {
    Matrix<double> CtN = Matrix<double>(C.middleRows(rows.begin, rows.size()).transpose()) * part.N_rows;
    MPI_Allreduce(MPI_IN_PLACE, CtN.data(), static_cast<int>(CtN.size()), MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
    const double err = (CtN - Matrix<double>::Identity(3, 3)).norm();
    failed = err < 1e-10 ? 0 : 1;
    if (rank == 0) std::printf("distributed_consumer: %d rank(s), |C'N - I| = %.2e\n", s.ranks, err);
  }
  if (failed) std::fprintf(stderr, "distributed_consumer: rank %d: %s\n", rank, s.brief_report().c_str());
  MPI_Finalize();
  return failed;
}
