// build_subspace_mumps (mumps_subspace.h): the row partition, the options,
// the agreed input checks and the entry points; the build's steps are
// MumpsBuild's (mumps_build.h, mumps_build.cpp).
#include "mumps_build.h"

#include "qpreduce/checks.h"

#include <Eigen/Cholesky>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <vector>

namespace qpreduce::distributed {

using SpD = SparseMatrix<double>;
using MatD = Matrix<double>;
using detail::MumpsSolver;
using detail::Symmetry;

RowRange owned_rows(Index n, int rank, int ranks) {
  return {n * rank / ranks, n * (rank + 1) / ranks};
}

RowRange owned_rows(Index n, MPI_Comm comm) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  return owned_rows(n, rank, size);
}

bool MumpsOptions::is_valid(std::string* why) const {
  if (workspace_percent < 0 || workspace_percent > 10000) {
    if (why) *why = fmt::format("workspace_percent must lie in [0, 10000], got {}", workspace_percent);
    return false;
  }
  if (gather_columns < 1) {
    if (why) *why = fmt::format("gather_columns must be at least 1, got {}", gather_columns);
    return false;
  }
  if (out_of_core_directory.size() > 255 || out_of_core_directory.find('\0') != std::string::npos) {
    if (why) *why = fmt::format("out_of_core_directory must be a path of at most 255 characters, got {} characters",
                                out_of_core_directory.size());
    return false;
  }
  return true;
}

namespace {

using detail::MumpsBuild;
using detail::all_true;
using detail::Counts;

// Input checks, agreed over the ranks so that every rank throws or none does.
void check_inputs(MPI_Comm comm, const SpD& H_rows, const SpD& C, const SpD& D_rows, const SubspaceOptions& options,
                  const MumpsOptions& mumps, const DistributedSubspace* out) {
  std::string why;
  try {
    if (!options.is_valid(&why)) throw std::invalid_argument("SubspaceOptions: " + why);
    if (!mumps.is_valid(&why)) throw std::invalid_argument("MumpsOptions: " + why);
    if (!mumps.out_of_core_directory.empty() && !std::filesystem::is_directory(mumps.out_of_core_directory)) {
      throw std::invalid_argument(fmt::format("MumpsOptions::out_of_core_directory: \"{}\" is not a directory here",
                                              mumps.out_of_core_directory));
    }
    if (out == nullptr) throw std::invalid_argument("build_subspace_mumps: output pointer is null");
    const Index n = C.rows();
    if (n == 0) throw std::invalid_argument("build_subspace_mumps: C has no rows (n = 0)");
    const RowRange rows = owned_rows(n, comm);
    check_size("build_subspace_mumps: H_rows rows (this rank's owned rows)", rows.size(), H_rows.rows());
    check_size("build_subspace_mumps: H_rows columns", n, H_rows.cols());
    check_size("build_subspace_mumps: D_rows rows (this rank's owned rows)", rows.size(), D_rows.rows());
    if (C.cols() == 0) throw std::invalid_argument("build_subspace_mumps: C has no columns (d = 0)");
    if (C.cols() > n) {
      throw std::invalid_argument(
          fmt::format("build_subspace_mumps: C has more columns ({}) than rows ({})", C.cols(), n));
    }
    check_finite("build_subspace_mumps: H rows", H_rows);
    check_finite("build_subspace_mumps: C", C);
    check_finite("build_subspace_mumps: D rows", D_rows);
    for (Index c : options.augment_columns) {
      if (c < 0 || c >= C.cols()) {
        throw std::invalid_argument(
            fmt::format("SubspaceOptions::augment_columns: column {} out of range [0, {})", c, C.cols()));
      }
    }
  } catch (const std::invalid_argument& e) {
    why = e.what();
  }
  // The lowest failing rank's message goes to every rank.
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  int first = why.empty() ? size : rank;
  MPI_Allreduce(MPI_IN_PLACE, &first, 1, MPI_INT, MPI_MIN, comm);
  if (first == size) return;
  int len = static_cast<int>(why.size());
  MPI_Bcast(&len, 1, MPI_INT, first, comm);
  why.resize(static_cast<size_t>(len));
  MPI_Bcast(why.data(), len, MPI_CHAR, first, comm);
  throw std::invalid_argument(first == rank ? why : fmt::format("{} (on MPI rank {})", why, first));
}

}  // namespace

void gather_subspace(MPI_Comm comm, const DistributedSubspace& part, int root, VariationalSubspace<double>* whole) {
  int rank = 0, ranks = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &ranks);
  std::vector<RowRange> parts;
  for (int r = 0; r < ranks; ++r) parts.push_back(owned_rows(part.n, r, ranks));
  const Counts counts(parts);
  const auto gather = [&](const MatD& mine, MatD* out) {
    if (rank == root) out->resize(part.n, mine.cols());
    for (Index j = 0; j < mine.cols(); ++j) {  // one column at a time, straight into place
      MPI_Gatherv(mine.col(j).data(), static_cast<int>(mine.rows()), MPI_DOUBLE,
                  rank == root ? out->col(j).data() : nullptr, counts.count.data(), counts.offset.data(),
                  MPI_DOUBLE, root, comm);
    }
  };
  whole->N.resize(0, 0);
  whole->UD.resize(0, 0);
  gather(part.N_rows, &whole->N);
  gather(part.UD_rows, &whole->UD);
}

DistributedSummary build_subspace_mumps_rows(MPI_Comm comm, const SpD& H_rows, const SpD& C, const SpD& D_rows,
                                             const SubspaceOptions& options, const MumpsOptions& mumps,
                                             DistributedSubspace* out) {
  check_inputs(comm, H_rows, C, D_rows, options, mumps, out);
  *out = DistributedSubspace{};
  return MumpsBuild(comm, H_rows, C, D_rows, options, mumps, out).run();
}

DistributedSummary build_subspace_mumps(MPI_Comm comm, const SpD& H_rows, const SpD& C, const SpD& D,
                                        const SubspaceOptions& options, const MumpsOptions& mumps,
                                        DistributedSubspace* out) {
  if (D.rows() != C.rows()) {  // agreed: the same whole matrices on every rank
    throw std::invalid_argument(fmt::format("build_subspace_mumps: D has {} rows, C {}", D.rows(), C.rows()));
  }
  const RowRange rows = owned_rows(C.rows(), comm);
  return build_subspace_mumps_rows(comm, H_rows, C, SpD(D.middleRows(rows.begin, rows.size())), options, mumps, out);
}

DistributedSummary build_subspace_mumps_on_root(MPI_Comm comm, const SpD& H, const SpD& C, const SpD& D,
                                                const SubspaceOptions& options, const MumpsOptions& mumps, int root,
                                                VariationalSubspace<double>* B, MatD* Hr, MatD* BtD) {
  if (B == nullptr || Hr == nullptr || BtD == nullptr) {
    throw std::invalid_argument("build_subspace_mumps_on_root: an output pointer is null");
  }
  const RowRange rows = owned_rows(H.rows(), comm);
  if (H.rows() != C.rows()) {  // agreed: the same whole matrices on every rank
    throw std::invalid_argument(fmt::format("build_subspace_mumps_on_root: H has {} rows, C {}", H.rows(), C.rows()));
  }
  DistributedSubspace part;
  const DistributedSummary summary =
      build_subspace_mumps(comm, H.middleRows(rows.begin, rows.size()), C, D, options, mumps, &part);
  *B = VariationalSubspace<double>{};
  if (!summary.ok()) return summary;
  gather_subspace(comm, part, root, B);
  *Hr = std::move(part.Hr);
  *BtD = std::move(part.BtD);
  return summary;
}

Matrix<double> reduced_constraints(MPI_Comm comm, const DistributedSubspace& part, const SpD& A) {
  check_size("reduced_constraints: A rows", part.n, A.rows());
  const SpD At = A.middleRows(part.rows.begin, part.rows.size()).transpose();
  Matrix<double> Ar(A.cols(), part.d + part.k);
  Ar.leftCols(part.d) = At * part.N_rows;
  Ar.rightCols(part.k) = At * part.UD_rows;
  detail::allreduce_sum(comm, Ar);
  return Ar;
}

Vector<double> reduced_linear_term(MPI_Comm comm, const DistributedSubspace& part, const Vector<double>& q) {
  check_size("reduced_linear_term: q size", part.n, q.size());
  Vector<double> qr(part.d + part.k);
  const auto mine = q.segment(part.rows.begin, part.rows.size());
  qr.head(part.d) = part.N_rows.transpose() * mine;
  qr.tail(part.k) = part.UD_rows.transpose() * mine;
  detail::allreduce_sum(comm, qr);
  return qr;
}

void gather_solution(MPI_Comm comm, const DistributedSubspace& part, const Vector<double>& w, int root,
                     Vector<double>* X) {
  check_size("gather_solution: w size", part.d + part.k, w.size());
  const Vector<double> mine = part.N_rows * w.head(part.d) + part.UD_rows * w.tail(part.k);
  int rank = 0, ranks = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &ranks);
  std::vector<int> counts(static_cast<size_t>(ranks)), offsets(static_cast<size_t>(ranks));
  for (int q = 0; q < ranks; ++q) {
    const RowRange rows = owned_rows(part.n, q, ranks);
    counts[static_cast<size_t>(q)] = static_cast<int>(rows.size());
    offsets[static_cast<size_t>(q)] = static_cast<int>(rows.begin);
  }
  if (rank == root) X->resize(part.n);
  MPI_Gatherv(mine.data(), static_cast<int>(mine.size()), MPI_DOUBLE, rank == root ? X->data() : nullptr,
              counts.data(), offsets.data(), MPI_DOUBLE, root, comm);
}

void sum_over_ranks(MPI_Comm comm, Matrix<double>* M) { detail::allreduce_sum(comm, *M); }

std::vector<double> gather_values(MPI_Comm comm, const std::vector<double>& mine, int root) {
  int rank = 0, ranks = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &ranks);
  std::vector<double> all(rank == root ? mine.size() * static_cast<size_t>(ranks) : 0);
  MPI_Gather(mine.data(), static_cast<int>(mine.size()), MPI_DOUBLE, all.data(), static_cast<int>(mine.size()),
             MPI_DOUBLE, root, comm);
  return all;
}

NextRows stream_rows_to_root(MPI_Comm comm, int root, RowRange mine, Index cols, const MakeRows& make,
                             Index chunk_rows) {
  int rank = 0, ranks = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &ranks);
  if (cols < 1) throw std::invalid_argument(fmt::format("stream_rows_to_root: cols must be ≥ 1, got {}", cols));
  if (chunk_rows < 1)
    throw std::invalid_argument(fmt::format("stream_rows_to_root: chunk_rows must be ≥ 1, got {}", chunk_rows));
  if (root < 0 || root >= ranks)
    throw std::invalid_argument(fmt::format("stream_rows_to_root: root {} outside the {} ranks", root, ranks));
  constexpr int kHeaderTag = 0, kRowsTag = 1;
  if (rank != root) {  // a header (first row, rows), then the rows chunk by chunk
    const long long header[2] = {static_cast<long long>(mine.begin), static_cast<long long>(mine.size())};
    MPI_Send(header, 2, MPI_LONG_LONG, root, kHeaderTag, comm);
    FloatRows chunk;
    for (Index i = 0; i < mine.size(); i += chunk_rows) {
      make(mine.begin + i, std::min(chunk_rows, mine.size() - i), &chunk);
      MPI_Send(chunk.data(), static_cast<int>(chunk.size()), MPI_FLOAT, root, kRowsTag, comm);
    }
    return {};
  }
  struct Source {  // the rank whose rows come next, its block and how far it is
    int rank = -1;
    Index first = 0, count = 0, done = 0;
  };
  auto at = std::make_shared<Source>();
  return [comm, root, ranks, mine, cols, make, chunk_rows, at](Index* first, FloatRows* rows) {
    while (at->done == at->count) {  // the next rank's block
      if (++at->rank >= ranks) return false;
      at->done = 0;
      if (at->rank == root) {
        at->first = mine.begin;
        at->count = mine.size();
        continue;
      }
      long long header[2] = {0, 0};
      MPI_Recv(header, 2, MPI_LONG_LONG, at->rank, kHeaderTag, comm, MPI_STATUS_IGNORE);
      at->first = static_cast<Index>(header[0]);
      at->count = static_cast<Index>(header[1]);
    }
    const Index c = std::min(chunk_rows, at->count - at->done);
    if (at->rank == root) {
      make(at->first + at->done, c, rows);
    } else {
      rows->resize(c, cols);
      MPI_Recv(rows->data(), static_cast<int>(c * cols), MPI_FLOAT, at->rank, kRowsTag, comm, MPI_STATUS_IGNORE);
    }
    *first = at->first + at->done;
    at->done += c;
    return true;
  };
}

void DistributedSummary::add_details(Report* out) const {
  SubspaceSummary::add_details(out);
  out->add("ranks", ranks)
      .add("kkt_route", kkt_route)
      .add("ordering", ordering)
      .add("mumps_infog1", mumps_infog1)
      .add("mumps_infog2", mumps_infog2)
      .add("factor_megabytes_max", factor_megabytes_max)
      .add("factor_megabytes_total", factor_megabytes_total)
      .add("reduce_seconds", reduce_seconds);
}

}  // namespace qpreduce::distributed
