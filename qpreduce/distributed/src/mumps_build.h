// Private to qpreduce::distributed: the steps of build_subspace_mumps
// (mumps_subspace.cpp) as the collective member functions of MumpsBuild
// (mumps_build.cpp), and the MPI reductions they share.
#pragma once

#include "qpreduce/distributed/mumps_subspace.h"

#include "mumps_solver.h"
#include "qpreduce/subspace_steps.h"

#include "qpreduce/util/timer.h"

#include <Eigen/Cholesky>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <optional>
#include <stdexcept>
#include <vector>

namespace qpreduce::distributed::detail {

using SpD = SparseMatrix<double>;
using MatD = Matrix<double>;
inline constexpr Index kRowBlock = kSubspaceRowBlock;

// Sums a dense matrix or vector of doubles over the ranks, in place.
template <typename Derived>
void allreduce_sum(MPI_Comm comm, Eigen::PlainObjectBase<Derived>& M) {
  if (M.size() > 0) MPI_Allreduce(MPI_IN_PLACE, M.data(), static_cast<int>(M.size()), MPI_DOUBLE, MPI_SUM, comm);
}
inline double allreduce(MPI_Comm comm, double v, MPI_Op op) {
  MPI_Allreduce(MPI_IN_PLACE, &v, 1, MPI_DOUBLE, op, comm);
  return v;
}
// True on every rank iff true on all.
inline bool all_true(MPI_Comm comm, bool v) {
  int x = v ? 1 : 0;
  MPI_Allreduce(MPI_IN_PLACE, &x, 1, MPI_INT, MPI_MIN, comm);
  return x == 1;
}

// Row counts and offsets of a row partition, as MPI ints: one column of an
// n-row column-major matrix moves in one Scatterv/Gatherv without packing.
struct Counts {
  std::vector<int> count, offset;
  explicit Counts(const std::vector<RowRange>& parts) {
    for (const RowRange& r : parts) {
      count.push_back(static_cast<int>(r.size()));
      offset.push_back(static_cast<int>(r.begin));
    }
  }
};

// The distributed build. Every member function is collective.
class MumpsBuild {
 public:
  MumpsBuild(MPI_Comm comm, const SpD& H_rows, const SpD& C, const SpD& D_rows, const SubspaceOptions& options,
             const MumpsOptions& mumps, DistributedSubspace* out)
      : comm(comm), H_rows(H_rows), C(C), D_rows(D_rows), options(options), mumps(mumps), out(out),
        n(C.rows()), d(C.cols()), k(D_rows.cols()) {
    MPI_Comm_rank(comm, &rank);
    MPI_Comm_size(comm, &ranks);
    for (int r = 0; r < ranks; ++r) parts.push_back(owned_rows(n, r, ranks));
    rows = parts[static_cast<size_t>(rank)];
    C_rows = C.middleRows(rows.begin, rows.size());
    D_norm = std::sqrt(allreduce(comm, D_rows.squaredNorm(), MPI_SUM));
    summary.n = n;
    summary.d = d;
    summary.k = k;
    summary.ranks = ranks;
    const double diag_max = allreduce(comm, local_diagonal().cwiseAbs().maxCoeff(), MPI_MAX);
    tau = options.psd_shift * std::max(diag_max, 1e-300);
  }

  DistributedSummary run();

 private:
  Vector<double> local_diagonal() const {
    Vector<double> diag = Vector<double>::Zero(std::max<Index>(rows.size(), 1));
    for (Index j = rows.begin; j < rows.end; ++j) diag(j - rows.begin) = H_rows.coeff(j - rows.begin, j);
    return diag;
  }
  bool fail(Status status, std::string message);
  bool fail_mumps(const MumpsSolver& solver, const std::string& what);
  bool check_rank_of_C();
  std::vector<Index> augmented_columns() const;
  bool factor_and_probe(MumpsSolver& solver, const SpD& K_rows, Index K_begin, Index K_order, const char* what);
  bool solve_columns(MumpsSolver& solver, Index K_order, Index columns,
                     const std::function<void(Index, MatD&)>& fill, MatD* owned);
  bool solve_columns_of_D(MumpsSolver& solver, Index K_order, MatD* owned);
  bool solve_blocks(MumpsSolver& solver, Index K_order, Index columns, const std::function<void(Index, MatD&)>& fill,
                    const SpD* top_rows, MatD* owned);
  bool augmented_route(const std::vector<Index>& aug);
  bool kkt_route();
  bool psd_by_factorization();
  bool check_ud_rank(const MatD& DtUD);
  void reduced_operators();

  MPI_Comm comm;
  const SpD& H_rows;
  const SpD& C;
  const SpD& D_rows;  // rows × k: this rank's rows of D
  const SubspaceOptions& options;
  const MumpsOptions& mumps;
  DistributedSubspace* out;
  const Index n, d, k;
  int rank = 0, ranks = 1;
  std::vector<RowRange> parts;
  RowRange rows;
  SpD C_rows;
  double D_norm = 0.0;  // ‖D‖_F
  double tau = 0.0;
  MatD G, F;  // owned rows of G, F, then of N, UD
  DistributedSummary summary;
  const Timer total;
};

}  // namespace qpreduce::distributed::detail
