// The MUMPS instance of the distributed subspace build (mumps_solver.h).
#include "mumps_solver.h"

#include <fmt/format.h>

#include <cstdio>
#include <cstdlib>
#include <limits>
#include <stdexcept>
#include <vector>

namespace qpreduce::distributed::detail {

namespace {
// MUMPS's control and information arrays are 1-based in its documentation.
constexpr int icntl(int i) { return i - 1; }

const char* infog1_meaning(int code) {
  switch (code) {
    case -5: case -7: case -13: return "MUMPS could not allocate memory";
    case -6: return "the matrix is structurally singular";
    case -8: case -9: case -14: case -15: case -17: case -20:
      return "MUMPS's working space is too small (raise MumpsOptions::workspace_percent)";
    case -10: return "the matrix is numerically singular";
    case -16: return "the matrix order is out of range";
    case -79: case -89: case -90:
      return "MUMPS's out-of-core files failed (MumpsOptions::out_of_core_directory: missing, full or not writable)";
    default: return "MUMPS error (see the MUMPS manual, INFOG(1))";
  }
}
}  // namespace

MumpsSolver::MumpsSolver(MPI_Comm comm, Symmetry symmetry, const MumpsOptions& options) {
  MPI_Comm_rank(comm, &rank_);
  MPI_Comm_size(comm, &size_);
  id_.comm_fortran = static_cast<MUMPS_INT>(MPI_Comm_c2f(comm));
  id_.par = 1;
  id_.sym = static_cast<MUMPS_INT>(symmetry);
  run(-1);
  if (!ok()) throw std::runtime_error("MUMPS initialization failed: " + message());
  id_.icntl[icntl(1)] = -1;  // error messages
  id_.icntl[icntl(2)] = -1;  // diagnostics
  id_.icntl[icntl(3)] = -1;  // global information
  id_.icntl[icntl(4)] = 0;
  id_.icntl[icntl(5)] = 0;   // assembled matrix
  id_.icntl[icntl(18)] = 3;  // distributed COO entries
  id_.icntl[icntl(20)] = 0;  // dense centralized right-hand side
  id_.icntl[icntl(21)] = 0;  // centralized solution (scattered by the caller)
  id_.icntl[icntl(14)] = options.workspace_percent;
  if (!options.out_of_core_directory.empty()) {  // is_valid: at most 255 characters
    id_.icntl[icntl(22)] = 1;
    std::snprintf(id_.ooc_tmpdir, sizeof id_.ooc_tmpdir, "%s", options.out_of_core_directory.c_str());
    std::snprintf(id_.ooc_prefix, sizeof id_.ooc_prefix, "%s", "qpreduce_factor");
  }
#ifdef QPREDUCE_MUMPS_HAS_PTSCOTCH
  parallel_ordering_ = options.parallel_ordering && size_ > 1;
#endif
  if (parallel_ordering_) {
    id_.icntl[icntl(28)] = 2;  // parallel analysis
    id_.icntl[icntl(29)] = 1;  // PT-Scotch
    one_scotch_thread_unless_mpi_allows();
  } else {
    id_.icntl[icntl(28)] = 1;  // sequential analysis on the host
    id_.icntl[icntl(7)] = 7;   // automatic choice among the orderings built in
  }
}

// PT-Scotch 7 (Debian's) folds its distributed graphs on threads that call
// MPI concurrently, which needs MPI_THREAD_MULTIPLE: under a lower thread
// level (MPI_Init) OpenMPI's shared-memory transport crashed in
// hdgraphFold2 with 4 ranks on one node. Unless the caller set it, the
// ordering then runs on one thread per rank (SCOTCH_PTHREAD_NUMBER, read by
// Scotch when it orders).
void MumpsSolver::one_scotch_thread_unless_mpi_allows() {
  int level = MPI_THREAD_SINGLE;
  MPI_Query_thread(&level);
  if (level < MPI_THREAD_MULTIPLE) setenv("SCOTCH_PTHREAD_NUMBER", "1", /*overwrite=*/0);
}

MumpsSolver::~MumpsSolver() { run(-2); }

void MumpsSolver::run(int job) {
  id_.job = job;
  dmumps_c(&id_);
}

bool MumpsSolver::factor(const SparseMatrix<double>& rows, Index row_begin, Index N) {
  if (N > std::numeric_limits<MUMPS_INT>::max()) {
    throw std::invalid_argument(fmt::format("MUMPS: order {} exceeds its 32-bit index range", N));
  }
  // The lower triangle as MUMPS's distributed COO (1-based), for the
  // analysis and the factorization only.
  std::vector<MUMPS_INT> irn, jcn;
  std::vector<double> a;
  irn.reserve(static_cast<size_t>(rows.nonZeros() / 2 + rows.rows()));
  jcn.reserve(irn.capacity());
  a.reserve(irn.capacity());
  for (Index j = 0; j < rows.outerSize(); ++j) {
    for (SparseMatrix<double>::InnerIterator it(rows, j); it; ++it) {
      const Index i = row_begin + it.row();
      if (j > i || it.value() == 0.0) continue;
      irn.push_back(static_cast<MUMPS_INT>(i + 1));
      jcn.push_back(static_cast<MUMPS_INT>(j + 1));
      a.push_back(it.value());
    }
  }
  id_.n = static_cast<MUMPS_INT>(N);
  id_.nnz_loc = static_cast<MUMPS_INT8>(a.size());
  id_.irn_loc = irn.data();
  id_.jcn_loc = jcn.data();
  id_.a_loc = a.data();
  run(1);
  if (ok()) run(2);
  id_.irn_loc = id_.jcn_loc = nullptr;
  id_.a_loc = nullptr;
  return ok();
}

bool MumpsSolver::solve_on_root(Matrix<double>& rhs) {
  if (rank_ == 0) {
    id_.rhs = rhs.data();
    id_.nrhs = static_cast<MUMPS_INT>(rhs.cols());
    id_.lrhs = static_cast<MUMPS_INT>(rhs.rows());
  }
  run(3);
  id_.rhs = nullptr;
  return ok();
}

Index MumpsSolver::factor_nonzeros() const {
  // INFOG(29): entries in the factors; negative means millions.
  const long long v = id_.infog[28];
  return static_cast<Index>(v >= 0 ? v : -v * 1000000LL);
}

std::string MumpsSolver::message() const {
  return fmt::format("MUMPS INFOG(1) = {}, INFOG(2) = {}: {}", id_.infog[0], id_.infog[1],
                     infog1_meaning(id_.infog[0]));
}

std::string MumpsSolver::ordering() const {
  // INFOG(32): 1 sequential, 2 parallel analysis; INFOG(7): the ordering used.
  if (id_.infog[31] == 2) {
    return id_.infog[6] == 2 ? "ParMETIS (parallel)" : "PT-Scotch (parallel)";
  }
  switch (id_.infog[6]) {
    case 0: return "AMD (sequential)";
    case 2: return "AMF (sequential)";
    case 3: return "SCOTCH (sequential)";
    case 4: return "PORD (sequential)";
    case 5: return "METIS (sequential)";
    case 6: return "QAMD (sequential)";
    default: return fmt::format("MUMPS ordering INFOG(7) = {} (sequential)", id_.infog[6]);
  }
}

}  // namespace qpreduce::distributed::detail
