// The MUMPS subspace build against the single-process CHOLMOD/SparseLU one:
// N, UD (owned rows), H_r and BᵀD agree to 1e-8 relative on each QP family
// and route; failures give the same status on every rank; bad input throws
// on every rank. Run under mpirun -np 1 and -np 2 (tests/distributed/CMakeLists.txt).
#include <catch2/catch.hpp>

#include "relative_difference.h"
#include "qpreduce/distributed/mumps_subspace.h"
#include "qpreduce/problems/families.h"
#include "qpreduce/problems/generators.h"
#include "qpreduce/subspace_solver.h"

#include <mpi.h>

#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

namespace {

using namespace qpreduce;
using distributed::build_subspace_mumps;
using distributed::DistributedSubspace;
using distributed::MumpsOptions;
using distributed::owned_rows;
using SpD = SparseMatrix<double>;
using MatD = Matrix<double>;

constexpr double kTolerance = 1e-8;

double sum_over_ranks(double v) {
  MPI_Allreduce(MPI_IN_PLACE, &v, 1, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  return v;
}

// ‖A − B‖_F / ‖B‖_F over the whole matrix, A and B given by owned rows.
double relative_difference_by_rows(const MatD& A, const MatD& B) {
  const double diff = sum_over_ranks((A - B).squaredNorm());
  const double ref = sum_over_ranks(B.squaredNorm());
  return std::sqrt(diff / std::max(ref, 1e-300));
}

using testing_distributed::relative_difference;

// Every rank's status equals rank 0's.
bool same_status_everywhere(Status s) {
  int mine = static_cast<int>(s), lo = 0, hi = 0;
  MPI_Allreduce(&mine, &lo, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
  MPI_Allreduce(&mine, &hi, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  return lo == hi;
}

SpD owned_rows_of(const SpD& H) {
  const auto rows = owned_rows(H.rows(), MPI_COMM_WORLD);
  return H.middleRows(rows.begin, rows.size());
}

// The single-process build (CHOLMOD, or SparseLU on the KKT route) and the
// distributed one agree on N, UD, H_r and BᵀD.
void check_against_single_process(const SpD& H, const SpD& C, const SpD& D, const SubspaceOptions& options,
                                  const MumpsOptions& mumps = {}) {
  SubspaceSolver<double> reference;
  const SubspaceSummary ref = reference.precompute(H, C, D, options);
  REQUIRE(ref.ok());

  DistributedSubspace out;
  const auto summary = build_subspace_mumps(MPI_COMM_WORLD, owned_rows_of(H), C, D, options, mumps, &out);
  INFO(summary.brief_report() << " ordering: " << summary.ordering);
  REQUIRE(summary.ok());
  CHECK(same_status_everywhere(summary.status));
  CHECK(summary.kkt_route == (ref.backend_used == Backend::SparseLU));
  CHECK(summary.kkt_residual < 1e-8);
  const auto rows = out.rows;
  const MatD N_ref = reference.subspace().N.middleRows(rows.begin, rows.size());
  const MatD UD_ref = reference.subspace().UD.middleRows(rows.begin, rows.size());
  CHECK(relative_difference_by_rows(out.N_rows, N_ref) < kTolerance);
  if (D.cols() > 0) CHECK(relative_difference_by_rows(out.UD_rows, UD_ref) < kTolerance);
  CHECK(relative_difference(out.Hr, reference.reduced_hessian()) < kTolerance);

  // Gathered to rank 0 (what qpr precompute writes into the cache): bit for
  // bit the rows every rank owns.
  VariationalSubspace<double> whole;
  distributed::gather_subspace(MPI_COMM_WORLD, out, 0, &whole);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  if (rank != 0) {
    CHECK(whole.N.size() == 0);
    whole.N.resize(H.rows(), C.cols());
    whole.UD.resize(H.rows(), D.cols());
  }
  MPI_Bcast(whole.N.data(), static_cast<int>(whole.N.size()), MPI_DOUBLE, 0, MPI_COMM_WORLD);
  MPI_Bcast(whole.UD.data(), static_cast<int>(whole.UD.size()), MPI_DOUBLE, 0, MPI_COMM_WORLD);
  CHECK(whole.N.middleRows(rows.begin, rows.size()) == out.N_rows);
  CHECK(whole.UD.middleRows(rows.begin, rows.size()) == out.UD_rows);
  if (D.cols() > 0) CHECK(relative_difference(out.BtD, reference.reduced_linear_map()) < kTolerance);

  // The on-site products over the ranks' rows equal those with the whole B.
  const Index n = H.rows(), p = C.cols() + D.cols();
  MatD B(n, p);
  B << whole.N, whole.UD;
  std::vector<Eigen::Triplet<double>> t;
  for (Index j = 0; j < 3; ++j)
    for (Index i = j; i < n; i += 7) t.emplace_back(i, j, 1.0 + 0.1 * static_cast<double>(i % 5) - 0.3 * j);
  SpD A(n, 3);
  A.setFromTriplets(t.begin(), t.end());
  const Vector<double> q = Vector<double>::LinSpaced(n, -1.0, 2.0), w = Vector<double>::LinSpaced(p, 0.5, -0.25);
  CHECK(relative_difference(distributed::reduced_constraints(MPI_COMM_WORLD, out, A), MatD(A.transpose() * B)) < 1e-12);
  CHECK(relative_difference(distributed::reduced_linear_term(MPI_COMM_WORLD, out, q), MatD(B.transpose() * q)) < 1e-12);
  Vector<double> X;
  distributed::gather_solution(MPI_COMM_WORLD, out, w, 0, &X);
  if (rank == 0) CHECK(relative_difference(X, MatD(B * w)) < 1e-12);
  CHECK_THROWS_WITH(distributed::reduced_linear_term(MPI_COMM_WORLD, out, Vector<double>::Zero(n + 1)),
                    Catch::Contains("q size"));
}

}  // namespace

TEST_CASE("MUMPS subspace matches the single-process build on each QP family", "[distributed]") {
  const auto family = GENERATE(families::Family::Gmrf, families::Family::Trajectory, families::Family::Portfolio);
  INFO("family " << families::to_string(family));
  const auto f = families::make_family(family, 900, 7);
  check_against_single_process(f.H, f.C, f.D, families::recommended_options(f));
}

TEST_CASE("sum_over_ranks and gather_values: every rank's part, summed or in rank order", "[distributed]") {
  int size = 1, rank = 0;
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MatD M = MatD::Constant(2, 3, rank + 1.0);
  distributed::sum_over_ranks(MPI_COMM_WORLD, &M);
  CHECK(M == MatD::Constant(2, 3, 0.5 * size * (size + 1)));  // 1 + 2 + … + size, on every rank
  MatD empty;
  distributed::sum_over_ranks(MPI_COMM_WORLD, &empty);
  CHECK(empty.size() == 0);
  const std::vector<double> all = distributed::gather_values(MPI_COMM_WORLD, {10.0 * rank, 10.0 * rank + 1}, 0);
  if (rank == 0) {
    REQUIRE(all.size() == 2 * static_cast<size_t>(size));
    for (int r = 0; r < size; ++r) {
      CHECK(all[2 * static_cast<size_t>(r)] == 10.0 * r);
      CHECK(all[2 * static_cast<size_t>(r) + 1] == 10.0 * r + 1);
    }
  } else {
    CHECK(all.empty());
  }
}

TEST_CASE("stream_rows_to_root: every rank's rows on root, in row order, in chunks", "[distributed]") {
  int size = 1, rank = 0;
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  const Index n = 23, cols = 3;  // chunks of 4 rows: uneven blocks and a short last chunk
  const auto entry = [](Index row, Index col) { return static_cast<float>(10 * row + col); };
  const distributed::RowRange mine = distributed::owned_rows(n, MPI_COMM_WORLD);
  int made = 0;  // chunks this rank made
  const distributed::MakeRows make = [&](Index first, Index count, distributed::FloatRows* rows) {
    CHECK(first >= mine.begin);
    CHECK(first + count <= mine.end);
    rows->resize(count, cols);
    for (Index i = 0; i < count; ++i)
      for (Index c = 0; c < cols; ++c) (*rows)(i, c) = entry(first + i, c);
    ++made;
  };
  for (const int root : {0, size - 1}) {
    made = 0;
    const distributed::NextRows next = distributed::stream_rows_to_root(MPI_COMM_WORLD, root, mine, cols, make, 4);
    if (rank != root) {
      CHECK_FALSE(next);
      CHECK(made == (mine.size() + 3) / 4);
      continue;
    }
    REQUIRE(next);
    Index expected_first = 0;
    Index first = -1;
    distributed::FloatRows rows;
    while (next(&first, &rows)) {
      CHECK(first == expected_first);  // rank 0's rows first, then the next rank's
      CHECK(rows.rows() <= 4);
      REQUIRE(rows.cols() == cols);
      for (Index i = 0; i < rows.rows(); ++i)
        for (Index c = 0; c < cols; ++c) CHECK(rows(i, c) == entry(first + i, c));
      expected_first += rows.rows();
    }
    CHECK(expected_first == n);
    CHECK(made == (mine.size() + 3) / 4);  // root's own rows made in place
  }
  CHECK_THROWS_WITH(distributed::stream_rows_to_root(MPI_COMM_WORLD, size, mine, cols, make),
                    Catch::Contains("root " + std::to_string(size) + " outside"));
  CHECK_THROWS_WITH(distributed::stream_rows_to_root(MPI_COMM_WORLD, 0, mine, 0, make),
                    Catch::Contains("cols must be ≥ 1"));
}

TEST_CASE("MUMPS subspace with the factor out of core matches the single-process build", "[distributed]") {
  // One directory per rank count (both ctest entries may run at once);
  // MUMPS deletes its files when the build ends.
  int size = 1, rank = 0;
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("qpreduce_ooc_test_np" + std::to_string(size));
  std::filesystem::create_directories(dir);
  MPI_Barrier(MPI_COMM_WORLD);
  MumpsOptions mumps;
  mumps.out_of_core_directory = dir.string();
  for (const auto family : {families::Family::Gmrf, families::Family::Trajectory}) {
    INFO("family " << families::to_string(family));
    const auto f = families::make_family(family, 900, 11);
    check_against_single_process(f.H, f.C, f.D, families::recommended_options(f), mumps);
  }
  MPI_Barrier(MPI_COMM_WORLD);
  CHECK(std::filesystem::is_empty(dir));  // no factor files left behind
  MPI_Barrier(MPI_COMM_WORLD);
  if (rank == 0) std::filesystem::remove_all(dir);
}

TEST_CASE("MUMPS: a column of C that picks one unknown makes its rows of N and UD exact", "[distributed]") {
  // As in the single-process build (engine subspace test): N(r, :) = e_jᵀ/c
  // and UD(r, :) = 0 to the bit in the rows each rank owns, on both routes,
  // beside a column of C that is not a selection.
  namespace gen = qpreduce::generators;
  const Index nx = 12, ny = 10, n = nx * ny;
  const SpD H = gen::grid_laplacian_2d(nx, ny);
  const std::vector<Index> picked = gen::random_subset(n, 6, 21);
  SpD C(n, 7);
  std::vector<Eigen::Triplet<double>> t;
  for (Index j = 0; j < 6; ++j) t.emplace_back(picked[static_cast<size_t>(j)], j, j == 2 ? -3.0 : 1.0);
  for (Index i = 0; i < n; i += 3) t.emplace_back(i, 6, 1.0 + 0.01 * static_cast<double>(i));
  C.setFromTriplets(t.begin(), t.end());
  const SpD D = gen::gaussian_sparse(n, 3, 22);
  for (Backend backend : {Backend::Auto, Backend::SparseLU}) {
    CAPTURE(to_string(backend));
    SubspaceOptions options;
    options.backend = backend;
    DistributedSubspace out;
    const auto summary = build_subspace_mumps(MPI_COMM_WORLD, owned_rows_of(H), C, D, options, {}, &out);
    REQUIRE(summary.ok());
    CHECK(summary.kkt_route == (backend == Backend::SparseLU));
    for (Index j = 0; j < 6; ++j) {
      const Index r = picked[static_cast<size_t>(j)] - out.rows.begin;
      if (r < 0 || r >= out.rows.size()) continue;  // another rank's row
      CAPTURE(j, r);
      Vector<double> expected = Vector<double>::Zero(7);
      expected(j) = 1.0 / (j == 2 ? -3.0 : 1.0);
      CHECK((out.N_rows.row(r).transpose() - expected).cwiseAbs().maxCoeff() == 0.0);
      CHECK(out.UD_rows.row(r).cwiseAbs().maxCoeff() == 0.0);
    }
    check_against_single_process(H, C, D, options);
  }
}

TEST_CASE("MUMPS subspace on the KKT route matches SparseLU", "[distributed]") {
  const auto f = families::make_family(families::Family::Gmrf, 400, 3);
  SubspaceOptions options;
  options.backend = Backend::SparseLU;
  check_against_single_process(f.H, f.C, f.D, options);
}

TEST_CASE("A singular KKT gives SingularKKT on every rank", "[distributed]") {
  // The GMRF with κ² = 0 has ker H = constants; factoring H itself
  // (augment = false) must fail, with the same status everywhere.
  const auto f = families::make_family(families::Family::Gmrf, 400, 5);
  REQUIRE_FALSE(f.positive_definite());
  SubspaceOptions options;
  options.augment = false;
  DistributedSubspace out;
  const auto summary = build_subspace_mumps(MPI_COMM_WORLD, owned_rows_of(f.H), f.C, f.D, options, {}, &out);
  INFO(summary.message);
  CHECK(summary.status == Status::SingularKKT);
  CHECK(same_status_everywhere(summary.status));
  CHECK(out.N_rows.size() == 0);
}

TEST_CASE("An indefinite H gives IndefiniteH on every rank", "[distributed]") {
  const auto f = families::make_family(families::Family::Trajectory, 400, 5);
  SpD H = f.H;
  H.coeffRef(3, 3) = -10.0 * H.coeff(3, 3);  // one strongly negative direction
  for (const bool augment : {true, false}) {
    SubspaceOptions options;
    options.augment = augment;
    DistributedSubspace out;
    const auto summary = build_subspace_mumps(MPI_COMM_WORLD, owned_rows_of(H), f.C, f.D, options, {}, &out);
    INFO("augment " << augment << ": " << summary.message);
    CHECK(summary.status == Status::IndefiniteH);
    CHECK(same_status_everywhere(summary.status));
    CHECK(out.N_rows.size() == 0);
  }
}

TEST_CASE("Bad input throws on every rank, naming the problem", "[distributed]") {
  const auto f = families::make_family(families::Family::Gmrf, 400, 5);
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  DistributedSubspace out;
  // The last rank alone passes the wrong rows: every rank must throw.
  SpD H_rows = owned_rows_of(f.H);
  if (rank == size - 1) H_rows = f.H.topRows(H_rows.rows() + 1);
  CHECK_THROWS_WITH(build_subspace_mumps(MPI_COMM_WORLD, H_rows, f.C, f.D, {}, {}, &out),
                    Catch::Contains("H_rows rows"));
  MumpsOptions bad;
  bad.workspace_percent = -1;
  CHECK_THROWS_WITH(build_subspace_mumps(MPI_COMM_WORLD, owned_rows_of(f.H), f.C, f.D, {}, bad, &out),
                    Catch::Contains("workspace_percent"));
  MumpsOptions nowhere;  // the last rank alone cannot see the directory: every rank must throw
  nowhere.out_of_core_directory = rank == size - 1 ? "/nonexistent/qpreduce_ooc" : std::string(".");
  CHECK_THROWS_WITH(build_subspace_mumps(MPI_COMM_WORLD, owned_rows_of(f.H), f.C, f.D, {}, nowhere, &out),
                    Catch::Contains("out_of_core_directory"));
}
