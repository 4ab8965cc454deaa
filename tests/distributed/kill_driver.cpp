// Rank 1 kills itself with SIGKILL while rank 0 is inside the collective
// subspace build (waiting for it in MUMPS's analysis). The test passes when
// mpirun reports the killed rank and ends the job, within the CTest timeout.
#include "qpreduce/distributed/mumps_subspace.h"
#include "qpreduce/problems/families.h"

#include <mpi.h>

#include <csignal>
#include <cstdio>

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  const auto f = qpreduce::families::make_family(qpreduce::families::Family::Gmrf, 10000, 1);
  const auto rows = qpreduce::distributed::owned_rows(f.H.rows(), MPI_COMM_WORLD);
  const qpreduce::SparseMatrix<double> H_rows = f.H.middleRows(rows.begin, rows.size());
  if (rank == 1) std::raise(SIGKILL);
  qpreduce::distributed::DistributedSubspace out;
  const auto summary =
      qpreduce::distributed::build_subspace_mumps(MPI_COMM_WORLD, H_rows, f.C, f.D, {}, {}, &out);
  std::printf("rank %d: unexpectedly finished: %s\n", rank, summary.brief_report().c_str());
  MPI_Finalize();
  return 0;
}
