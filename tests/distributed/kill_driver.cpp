// distributed_kill_driver <stage>: rank 1 of `mpirun -np 2` kills itself
// with SIGKILL at one stage of the collective subspace build while rank 0
// carries on into the next collective step and waits for it there:
//   analysis  before the build: rank 0 waits in MUMPS's analysis;
//   solves    at rank 1's first scatter of a solved block (solve_columns),
//             i.e. after the MUMPS factorization and the first block solve:
//             rank 0 waits in the next block solve or reduction;
//   reduce    at rank 1's first all-gather of B's columns for H_r = BᵀHB
//             (reduced_operators), i.e. after every solve and the Allreduce
//             of Dᵀ·UD: rank 0 waits in that all-gather.
// The mid-run stages are found without a hook in the library: this program
// defines MPI_Scatterv and MPI_Allgatherv itself (the MPI profiling
// interface), which the static qpreduce::distributed calls in place of the
// MPI library's, and forwards them to PMPI_*. MUMPS (Fortran) calls PMPI_*
// directly, and PT-Scotch works on its own communicators, so only the build's
// own calls on MPI_COMM_WORLD are counted.
// The test passes when the job ends within a bound with a non-zero exit,
// rank 1's message and mpirun's (expect_job_failure.cmake); rank 0 never
// prints "unexpectedly finished".
#include "qpreduce/distributed/mumps_subspace.h"
#include "qpreduce/problems/families.h"

#include <mpi.h>

#include <csignal>
#include <cstdio>
#include <cstring>
#include <string>

namespace {

std::string kill_stage;  // analysis, solves or reduce
int world_rank = -1;
int block_scatters = 0;  // MPI_Scatterv calls of the build seen on this rank

void die_at(const char* stage) {
  std::fprintf(stderr, "rank %d: killing itself (SIGKILL) at stage %s, after %d block scatter(s)\n", world_rank,
               stage, block_scatters);
  std::fflush(stderr);
  std::raise(SIGKILL);
}

bool on_world(MPI_Comm comm) {
  int same = MPI_UNEQUAL;
  MPI_Comm_compare(comm, MPI_COMM_WORLD, &same);
  return same == MPI_IDENT;
}

}  // namespace

int MPI_Scatterv(const void* sendbuf, const int sendcounts[], const int displs[], MPI_Datatype sendtype,
                 void* recvbuf, int recvcount, MPI_Datatype recvtype, int root, MPI_Comm comm) {
  if (world_rank == 1 && on_world(comm)) {
    ++block_scatters;
    if (kill_stage == "solves") die_at("solves");
  }
  return PMPI_Scatterv(sendbuf, sendcounts, displs, sendtype, recvbuf, recvcount, recvtype, root, comm);
}

int MPI_Allgatherv(const void* sendbuf, int sendcount, MPI_Datatype sendtype, void* recvbuf, const int recvcounts[],
                   const int displs[], MPI_Datatype recvtype, MPI_Comm comm) {
  // After the solves only: a gather before any block scatter is not the H·B pass.
  if (world_rank == 1 && kill_stage == "reduce" && block_scatters > 0 && on_world(comm)) die_at("reduce");
  return PMPI_Allgatherv(sendbuf, sendcount, sendtype, recvbuf, recvcounts, displs, recvtype, comm);
}

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  MPI_Comm_rank(MPI_COMM_WORLD, &world_rank);
  kill_stage = argc > 1 ? argv[1] : "";
  if (kill_stage != "analysis" && kill_stage != "solves" && kill_stage != "reduce") {
    if (world_rank == 0) std::fprintf(stderr, "usage: distributed_kill_driver analysis|solves|reduce\n");
    MPI_Finalize();
    return 2;
  }
  const auto f = qpreduce::families::make_family(qpreduce::families::Family::Gmrf, 10000, 1);
  const auto rows = qpreduce::distributed::owned_rows(f.H.rows(), MPI_COMM_WORLD);
  const qpreduce::SparseMatrix<double> H_rows = f.H.middleRows(rows.begin, rows.size());
  if (world_rank == 1 && kill_stage == "analysis") die_at("analysis");
  qpreduce::distributed::DistributedSubspace out;
  const auto summary =
      qpreduce::distributed::build_subspace_mumps(MPI_COMM_WORLD, H_rows, f.C, f.D, {}, {}, &out);
  std::printf("rank %d: unexpectedly finished: %s\n", world_rank, summary.brief_report().c_str());
  MPI_Finalize();
  return 0;
}
