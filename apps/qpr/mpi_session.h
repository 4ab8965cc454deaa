// qpr — MPI for the length of a command (`qpr precompute`, `qpr qp --backend
// mumps`), built with QPREDUCE_WITH_MPI. A plain run is a one-rank job.
#pragma once

#include "guard.h"
#include "rank_agreement.h"

#include <qpreduce/common.h>

#include <mpi.h>

#include <cstdint>
#include <cstdio>
#include <functional>
#include <string>
#include <vector>

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

// "" when every rank was given the same options and input files as rank 0
// (rank_agreement.h), else the message naming what differs; the same on
// every rank (a collective: every rank calls it).
inline std::string mismatch_across_ranks(const MpiSession& mpi, const CLI::App& command) {
  const auto mine = option_fingerprints(command);
  const int n = static_cast<int>(mine.size());
  std::vector<int> counts(static_cast<size_t>(mpi.size));
  MPI_Allgather(&n, 1, MPI_INT, counts.data(), 1, MPI_INT, MPI_COMM_WORLD);
  for (int r = 1; r < mpi.size; ++r) {
    if (counts[static_cast<size_t>(r)] != counts[0]) {
      return "the ranks were not given the same command (rank " + std::to_string(r) + " runs another subcommand " +
             "than rank 0); every rank must run the same command on the same files";
    }
  }
  std::vector<std::uint64_t> values, all(static_cast<size_t>(n) * static_cast<size_t>(mpi.size));
  std::vector<std::string> names;
  for (const auto& [name, value] : mine) {
    names.push_back(name);
    values.push_back(value);
  }
  MPI_Allgather(values.data(), n, MPI_UINT64_T, all.data(), n, MPI_UINT64_T, MPI_COMM_WORLD);
  std::vector<std::vector<std::uint64_t>> table(static_cast<size_t>(mpi.size));
  for (int r = 0; r < mpi.size; ++r) table[static_cast<size_t>(r)].assign(all.begin() + r * n, all.begin() + (r + 1) * n);
  return rank_mismatch(names, table);
}

// run_guarded with MPI up, once every rank has been found to have the same
// inputs (mismatch_across_ranks; otherwise every rank ends with exit 2, rank
// 0 saying what differs). A rank that failed alone would leave the others
// waiting in a collective, so a failure with more than one rank ends the
// whole job (MPI_Abort, after the message).
inline void run_with_mpi(const char* name, const CLI::App& command, const std::function<int(const MpiSession&)>& body,
                         std::initializer_list<int> verdicts = {}) {
  const MpiSession mpi;
  if (mpi.size > 1) {
    const std::string mismatch = mismatch_across_ranks(mpi, command);
    if (!mismatch.empty()) {
      if (mpi.rank == 0) std::fprintf(stderr, "qpr %s: error: %s\n", name, mismatch.c_str());
      MPI_Finalize();
      throw CLI::RuntimeError(2);
    }
  }
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
