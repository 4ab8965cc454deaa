// qpr — MPI for the length of a command (`qpr precompute`, `qpr qp --backend
// mumps`), built with QPREDUCE_WITH_MPI. A plain run is a one-rank job.
#pragma once

#include "guard.h"

#include <qpreduce/common.h>

#include <mpi.h>

#include <functional>

namespace qpr {

// MPI initialized here unless the caller has; rank and size of MPI_COMM_WORLD.
struct MpiSession {
  MpiSession() {
    int initialized = 0;
    MPI_Initialized(&initialized);
    if (!initialized) MPI_Init(nullptr, nullptr);
    MPI_Comm_rank(MPI_COMM_WORLD, &rank);
    MPI_Comm_size(MPI_COMM_WORLD, &size);
  }
  int rank = 0, size = 1;
};

// In place: M's entries summed over the ranks of MPI_COMM_WORLD, on every
// rank (the same shape everywhere).
inline void sum_over_ranks(qpreduce::Matrix<double>* M) {
  if (M->size() > 0) {
    MPI_Allreduce(MPI_IN_PLACE, M->data(), static_cast<int>(M->size()), MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  }
}

// run_guarded with MPI up. A rank that failed alone would leave the others
// waiting in a collective, so a failure with more than one rank ends the
// whole job (MPI_Abort, after the message).
inline void run_with_mpi(const char* name, const std::function<int(const MpiSession&)>& body,
                         std::initializer_list<int> verdicts = {}) {
  const MpiSession mpi;
  int code = 0;
  try {
    run_guarded(name, [&] { return body(mpi); }, verdicts);
  } catch (const CLI::RuntimeError& e) {
    code = e.get_exit_code();
  }
  if (code != 0 && mpi.size > 1) MPI_Abort(MPI_COMM_WORLD, code);
  MPI_Finalize();
  if (code != 0) throw CLI::RuntimeError(code);
}

}  // namespace qpr
