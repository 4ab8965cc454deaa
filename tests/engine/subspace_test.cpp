// The variational subspace (Eq. 4, 14–15) over every backend: agreement of
// the backends, Eq. 4 column by column, the full-space reference, the PSD
// certificate, blocked and ordered builds, and the error paths.
#include <catch2/catch.hpp>

#include "subspace_test_util.h"

#include "qpreduce/factorization.h"
#include "qpreduce/full_solve.h"

#include <Eigen/Dense>
#include <omp.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

using namespace qpreduce;
using namespace subspace_test;

TEST_CASE("all backends produce the same subspace", "[subspace][conformance]") {
  const Problem p = in_span_problem(20, 20, 0.0, 7);
  VariationalSubspace<double> ref;
  SubspaceOptions opts;
  opts.backend = Backend::Cholmod;
  REQUIRE(build_subspace(p.H, p.C, p.D, opts, &ref).ok());
  for (Backend b : {Backend::SimplicialLDLT, Backend::SparseLU}) {
    CAPTURE(to_string(b));
    VariationalSubspace<double> other;
    opts.backend = b;
    REQUIRE(build_subspace(p.H, p.C, p.D, opts, &other).ok());
    CHECK((other.N - ref.N).norm() <= 1e-10 * ref.N.norm());
    CHECK((other.UD - ref.UD).norm() <= 1e-10 * ref.UD.norm());
  }
}

TEST_CASE("subspace satisfies Eq. 4 column by column", "[subspace]") {
  const Problem p = in_span_problem(15, 15, 0.0, 3);
  VariationalSubspace<double> s;
  REQUIRE(build_subspace(p.H, p.C, p.D, {}, &s).ok());
  // CᵀN = I, CᵀUD = 0.
  const Matrix<double> CtN = p.C.transpose() * s.N;
  const Matrix<double> CtU = p.C.transpose() * s.UD;
  CHECK((CtN - Matrix<double>::Identity(12, 12)).norm() < 1e-10);
  CHECK(CtU.norm() < 1e-10);
  // H·N ∈ Span(C) and H·UD − D ∈ Span(C): zero after projecting out Span(C).
  const Matrix<double> Cd(p.C);
  const Matrix<double> proj = Cd * (Cd.transpose() * Cd).ldlt().solve(Cd.transpose());
  const Matrix<double> I = Matrix<double>::Identity(p.H.rows(), p.H.rows());
  CHECK(((I - proj) * (p.H * s.N)).norm() < 1e-9);
  CHECK(((I - proj) * (p.H * s.UD - Matrix<double>(p.D))).norm() < 1e-9);
}

TEST_CASE("a column of C that picks one unknown makes its rows of N and UD exact", "[subspace][selection]") {
  // CᵀN = I and CᵀUD = 0 state, for a column with one nonzero c in row r,
  // N(r, :) = e_jᵀ/c and UD(r, :) = 0: exact to the bit on every backend,
  // beside a column that is not a selection (and shares some of their rows).
  const Index nx = 12, ny = 10, n = nx * ny;
  const SparseMatrix<double> H = gen::grid_laplacian_2d(nx, ny);
  const std::vector<Index> rows = gen::random_subset(n, 6, 21);
  SparseMatrix<double> C(n, 7);
  std::vector<Eigen::Triplet<double>> t;
  for (Index j = 0; j < 6; ++j) t.emplace_back(rows[static_cast<size_t>(j)], j, j == 2 ? -3.0 : 1.0);
  for (Index i = 0; i < n; i += 3) t.emplace_back(i, 6, 1.0 + 0.01 * static_cast<double>(i));
  C.setFromTriplets(t.begin(), t.end());
  const SparseMatrix<double> D = gen::gaussian_sparse(n, 3, 22);
  for (Backend backend : {Backend::Cholmod, Backend::SimplicialLDLT, Backend::SparseLU}) {
    CAPTURE(to_string(backend));
    SubspaceOptions opts;
    opts.backend = backend;
    VariationalSubspace<double> s;
    REQUIRE(build_subspace(H, C, D, opts, &s).ok());
    for (Index j = 0; j < 6; ++j) {
      const Index r = rows[static_cast<size_t>(j)];
      CAPTURE(j, r);
      Vector<double> expected = Vector<double>::Zero(7);
      expected(j) = 1.0 / (j == 2 ? -3.0 : 1.0);
      CHECK((s.N.row(r).transpose() - expected).cwiseAbs().maxCoeff() == 0.0);
      CHECK(s.UD.row(r).cwiseAbs().maxCoeff() == 0.0);
    }
    CHECK((Matrix<double>(C.transpose() * s.N) - Matrix<double>::Identity(7, 7)).norm() < 1e-10);
  }
}

TEST_CASE("full-space solve matches a dense KKT solve, also with q in Span(A)", "[full]") {
  const Index n = 60;
  const SparseMatrix<double> H = gen::random_psd(n, 3, 11);
  const SparseMatrix<double> A = gen::gaussian_sparse(n, 8, 12);
  const Vector<double> b = gen::gaussian_vector(8, 13);
  for (int variant = 0; variant < 3; ++variant) {
    CAPTURE(variant);
    Vector<double> q = gen::gaussian_vector(n, 14);
    if (variant == 1) q = Matrix<double>(A) * gen::gaussian_vector(8, 15);  // q ∈ Span(A)
    if (variant == 2) q.setZero();
    Vector<double> X;
    const FullSolveSummary s = solve_full(H, A, b, q, &X);
    INFO(s.message);
    REQUIRE(s.ok());
    const Vector<double> ref = dense_kkt_solve(H, A, b, q);
    CHECK((X - ref).norm() <= 1e-8 * ref.norm());
  }
}

TEST_CASE("bad input is rejected with a message naming the problem", "[subspace][errors]") {
  const Problem p = in_span_problem(8, 8, 0.0, 5);
  VariationalSubspace<double> s;
  auto message_of = [&](auto&& f) -> std::string {
    try {
      f();
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "no exception";
  };

  SECTION("wrong sizes") {
    const SparseMatrix<double> Cbad(63, 3);
    const std::string msg = message_of([&] { build_subspace(p.H, Cbad, p.D, {}, &s); });
    CHECK_THAT(msg, Catch::Contains("C rows") && Catch::Contains("expected 64, got 63"));
  }
  SECTION("NaN in H") {
    SparseMatrix<double> H = p.H;
    H.coeffRef(3, 3) = std::numeric_limits<double>::quiet_NaN();
    CHECK_THAT(message_of([&] { build_subspace(H, p.C, p.D, {}, &s); }), Catch::Contains("NaN"));
  }
  SECTION("asymmetric H") {
    SparseMatrix<double> H = p.H;
    H.coeffRef(0, 1) += 0.5;
    CHECK_THAT(message_of([&] { build_subspace(H, p.C, p.D, {}, &s); }), Catch::Contains("not symmetric"));
  }
  SECTION("asymmetry measured exactly, mirror entry absent, compressed or not") {
    // H(0, 5) stored without H(5, 0): ‖H − Hᵀ‖_F = √2·e, so the rejection
    // threshold on symmetry_tolerance is √2·e/‖H‖_F.
    SparseMatrix<double> H = p.H;
    REQUIRE(H.coeff(5, 0) == 0.0);
    const double e = 1e-6;
    H.coeffRef(0, 5) = e;
    const double ratio = std::sqrt(2.0) * e / H.norm();
    for (const bool compressed : {true, false}) {
      if (compressed) H.makeCompressed(); else H.uncompress();
      SubspaceOptions below, above;
      below.symmetry_tolerance = 0.99 * ratio;
      above.symmetry_tolerance = 1.01 * ratio;
      CHECK_THAT(message_of([&] { build_subspace(H, p.C, p.D, below, &s); }), Catch::Contains("not symmetric"));
      CHECK_THAT(message_of([&] { build_subspace(H, p.C, p.D, above, &s); }), !Catch::Contains("not symmetric"));
    }
  }
  SECTION("no columns in C") {
    const SparseMatrix<double> C0(64, 0);
    CHECK_THAT(message_of([&] { build_subspace(p.H, C0, p.D, {}, &s); }), Catch::Contains("d = 0"));
  }
  SECTION("invalid options") {
    SubspaceOptions o;
    o.rho_scale = -1;
    CHECK_THAT(message_of([&] { build_subspace(p.H, p.C, p.D, o, &s); }), Catch::Contains("rho_scale"));
  }
  SECTION("solver used before precompute") {
    SubspaceSolver<double> solver;
    CHECK_THAT(message_of([&] { solver.set_constraints(p.A); }), Catch::Contains("precompute"));
  }
  SECTION("constraint matrix with the wrong row count") {
    SubspaceSolver<double> solver;
    REQUIRE(solver.precompute(p.H, p.C, p.D).ok());
    const SparseMatrix<double> A(10, 2);
    CHECK_THAT(message_of([&] { solver.set_constraints(A); }), Catch::Contains("expected 64, got 10"));
  }
}

TEST_CASE("numerical failures come back as a status, never NaN", "[subspace][errors]") {
  const Index nx = 8, ny = 8, n = nx * ny;
  const SparseMatrix<double> H = gen::grid_laplacian_2d(nx, ny);
  const SparseMatrix<double> D = gen::grid_trend_basis(nx, ny, 3);
  const Backend backend = GENERATE(Backend::Cholmod, Backend::SimplicialLDLT, Backend::SparseLU);
  CAPTURE(to_string(backend));
  SubspaceOptions opts;
  opts.backend = backend;
  VariationalSubspace<double> s;

  SECTION("rank-deficient C") {
    std::vector<Index> rows = {1, 5, 9, 5};  // column 3 repeats column 1
    const SubspaceSummary r = build_subspace(H, gen::selection(n, rows), D, opts, &s);
    CHECK(r.status == Status::RankDeficientC);
    CHECK_THAT(r.message, Catch::Contains("rank 3 < d = 4"));
    CHECK(s.N.size() == 0);
  }
  SECTION("D dependent on C") {
    const SparseMatrix<double> C = gen::selection(n, {2, 7, 30});
    SparseMatrix<double> Dbad(n, 2);
    Dbad.insert(7, 0) = 1.0;  // e_7 ∈ Span(C)
    Dbad.insert(11, 1) = 1.0;
    const SubspaceSummary r = build_subspace(H, C, Dbad, opts, &s);
    CHECK(r.status == Status::DependentCD);
    CHECK_THAT(r.message, Catch::Contains("linearly dependent"));
  }
  SECTION("singular KKT: H not positive definite on ker(Cᵀ)") {
    // Two disconnected grids; C only touches the first, so the second one's
    // constant mode is free.
    SparseMatrix<double> H2(2 * n, 2 * n);
    std::vector<Eigen::Triplet<double>> t;
    for (int c = 0; c < 2; ++c)
      for (Index j = 0; j < n; ++j)
        for (SparseMatrix<double>::InnerIterator it(H, j); it; ++it)
          t.emplace_back(it.row() + c * n, j + c * n, it.value());
    H2.setFromTriplets(t.begin(), t.end());
    const SparseMatrix<double> C = gen::selection(2 * n, {3, 40});
    const SparseMatrix<double> D0(2 * n, 0);
    const SubspaceSummary r = build_subspace(H2, C, D0, opts, &s);
    CHECK(r.status == Status::SingularKKT);
    CHECK_THAT(r.message, Catch::Contains("singular"));
    CHECK(s.N.size() == 0);
  }
  SECTION("indefinite H") {
    SparseMatrix<double> Hi = H;
    for (Index i = 0; i < n; i += 2) Hi.coeffRef(i, i) -= 3.0;
    const SubspaceSummary r = build_subspace(Hi, gen::selection(n, {1, 2}), D, opts, &s);
    CHECK(r.status == Status::IndefiniteH);
    CHECK_THAT(r.message, Catch::Contains("not positive semi-definite"));
  }
}

TEST_CASE("the PSD certificate decides like the factorization check", "[subspace][psd]") {
  const Index nx = 10, ny = 10, n = nx * ny;
  const SparseMatrix<double> L = gen::grid_laplacian_2d(nx, ny);
  const SparseMatrix<double> C = gen::selection(n, gen::random_subset(n, 20, 41));
  const SparseMatrix<double> D = gen::grid_trend_basis(nx, ny, 3);
  SparseMatrix<double> I(n, n);
  I.setIdentity();
  const Backend backend = GENERATE(Backend::Cholmod, Backend::SimplicialLDLT);
  const bool by_factorization = GENERATE(false, true);
  CAPTURE(to_string(backend), by_factorization);
  SubspaceOptions opts;
  opts.backend = backend;
  opts.psd_check_by_factorization = by_factorization;
  VariationalSubspace<double> s;
  // PSD with a null space: accepted.
  const SubspaceSummary ok = build_subspace(L, C, D, opts, &s);
  INFO(ok.brief_report());
  CHECK(ok.ok());
  // Slightly indefinite (λ_min = −10⁻³) while H + ρCCᵀ still factors: only a
  // PSD check can tell.
  const SparseMatrix<double> Hneg = L - 1e-3 * I;
  const SubspaceSummary bad = build_subspace(Hneg, C, D, opts, &s);
  INFO(bad.brief_report());
  CHECK(bad.status == Status::IndefiniteH);
  CHECK(s.N.size() == 0);
  // Without the check the same H builds (H_ρ is positive definite).
  opts.check_psd = false;
  CHECK(build_subspace(Hneg, C, D, opts, &s).ok());
}

TEST_CASE("blocked concurrent solves do not change the subspace", "[subspace][blocks]") {
  const Problem p = in_span_problem(23, 19, 0.0, 51);
  const Backend backend = GENERATE(Backend::Cholmod, Backend::SimplicialLDLT, Backend::SparseLU);
  CAPTURE(to_string(backend));
  SubspaceOptions opts;
  opts.backend = backend;
  opts.block_size = 1000;
  VariationalSubspace<double> ref;
  REQUIRE(build_subspace(p.H, p.C, p.D, opts, &ref).ok());
  for (Index block : {1, 3, 5}) {
    CAPTURE(block);
    opts.block_size = block;
    VariationalSubspace<double> s;
    REQUIRE(build_subspace(p.H, p.C, p.D, opts, &s).ok());
    CHECK((s.N - ref.N).norm() <= 1e-12 * ref.N.norm());
    CHECK((s.UD - ref.UD).norm() <= 1e-12 * ref.UD.norm());
  }
}

namespace {

// factor⁻¹·B solved in place in column blocks of `block`, on `threads` threads.
Matrix<double> solved_on(const SparseFactorization& factor, const Matrix<double>& B, int threads, Index block) {
  const int previous = omp_get_max_threads();
  omp_set_num_threads(threads);
  Matrix<double> X = B;
  factor.solveInPlace(X, block);
  omp_set_num_threads(previous);
  return X;
}

}  // namespace

TEST_CASE("CHOLMOD's in-place blocked solves match a dense solve", "[factorization][blocks]") {
  // A fill-reducing permutation that is far from the identity (2D grid), and
  // column blocks that do not divide the column count.
  const SparseMatrix<double> A = gen::grid_laplacian_2d(17, 13, 0.3);
  const Matrix<double> B = Matrix<double>::Random(A.rows(), 37);
  const Matrix<double> expected = Matrix<double>(A).llt().solve(B);
  // Ordered as is, or with the unknowns grouped in pairs (a quotient graph).
  const bool grouped = GENERATE(false, true);
  CAPTURE(grouped);
  auto factor = make_factorization(Backend::Cholmod);
  if (grouped) {
    std::vector<Index> pairs(static_cast<size_t>(A.rows()));
    for (Index i = 0; i < A.rows(); ++i) pairs[static_cast<size_t>(i)] = i / 2;
    factor->setOrderingGroups(pairs);
  }
  factor->compute(A);
  REQUIRE(factor->info() == Eigen::Success);
  const int threads = GENERATE(1, 2);
  const Index block = GENERATE(1, 8, 64);
  CAPTURE(threads, block);
  CHECK((solved_on(*factor, B, threads, block) - expected).norm() <= 1e-12 * expected.norm());
}

TEST_CASE("CHOLMOD's supernodal LLT refuses a singular positive semidefinite matrix, whichever side of 0 its last "
          "pivot lands", "[factorization]") {
  // A grid Laplacian without its ridge (constants in the kernel) factors to a
  // last pivot of round-off size, negative for some sizes (CHOLMOD stops:
  // not positive definite) and positive for others (the pivot-ratio test).
  // Both are refused, and a ridge of 10⁻⁶ is accepted.
  int by_ratio = 0, by_sign = 0;
  for (Index nx = 3; nx <= 40; ++nx) {
    CAPTURE(nx);
    auto factor = make_factorization(Backend::Cholmod);
    factor->compute(gen::grid_laplacian_2d(nx, nx + 3, 0.0));
    CHECK(factor->info() == Eigen::NumericalIssue);
    by_ratio += factor->message().find("numerically singular") != std::string::npos;
    by_sign += factor->message().find("not positive definite") != std::string::npos;
    auto ridged = make_factorization(Backend::Cholmod);
    ridged->compute(gen::grid_laplacian_2d(nx, nx + 3, 1e-6));
    CHECK(ridged->info() == Eigen::Success);
  }
  INFO(by_ratio << " refused by the pivot ratio, " << by_sign << " by a pivot ≤ 0");
  CHECK(by_ratio + by_sign == 38);  // which test refuses which size is the BLAS's rounding
}

TEST_CASE("CHOLMOD's simplicial LDLT solves match a dense solve and refuse a matrix that is not positive definite",
          "[factorization][blocks]") {
  const SparseMatrix<double> A = gen::grid_laplacian_2d(17, 13, 0.3);
  const Matrix<double> B = Matrix<double>::Random(A.rows(), 11);
  const Matrix<double> expected = Matrix<double>(A).llt().solve(B);
  auto factor = make_cholmod_simplicial_factorization();
  factor->compute(A);
  REQUIRE(factor->info() == Eigen::Success);
  CHECK(factor->backend() == Backend::Cholmod);
  CHECK(factor->factorNonZeros() > A.rows());
  // Blocks of one, three (a round's axes), more than CHOLMOD's four columns
  // at once, and all; on one thread and two.
  const int threads = GENERATE(1, 2);
  const Index block = GENERATE(1, 3, 5, 64);
  CAPTURE(threads, block);
  CHECK((solved_on(*factor, B, threads, block) - expected).norm() <= 1e-12 * expected.norm());

  // LDLT factors an indefinite matrix; the inertia of D refuses it, and a
  // singular one (the grid Laplacian without its ridge: constants in the kernel).
  const SparseMatrix<double> L = gen::grid_laplacian_2d(9, 7, 0.0);
  SparseMatrix<double> shifted = L;
  for (Index i = 0; i < L.rows(); ++i) shifted.coeffRef(i, i) -= 0.5;
  auto indefinite = make_cholmod_simplicial_factorization();
  indefinite->compute(shifted);
  CHECK(indefinite->info() == Eigen::NumericalIssue);
  CHECK_THAT(indefinite->message(), Catch::Contains("not positive definite"));
  auto singular = make_cholmod_simplicial_factorization();
  singular->compute(L);
  CHECK(singular->info() == Eigen::NumericalIssue);
  CHECK_THAT(singular->message(), Catch::Contains("CHOLMOD"));
}

TEST_CASE("ordering groups give the same subspace and reject bad groups", "[subspace][ordering]") {
  // Two coupled unknowns per grid node: H = L_grid ⊗ [[2, 0.5], [0.5, 1]].
  const SparseMatrix<double> L = gen::grid_laplacian_2d(21, 17, 0.0);
  const Index nodes = L.rows(), n = 2 * nodes;
  std::vector<Eigen::Triplet<double>> t;
  const Eigen::Matrix2d block = (Eigen::Matrix2d() << 2.0, 0.5, 0.5, 1.0).finished();
  for (Index j = 0; j < nodes; ++j)
    for (SparseMatrix<double>::InnerIterator it(L, j); it; ++it)
      for (int a = 0; a < 2; ++a)
        for (int b = 0; b < 2; ++b) t.emplace_back(2 * it.row() + a, 2 * j + b, it.value() * block(a, b));
  SparseMatrix<double> H(n, n);
  H.setFromTriplets(t.begin(), t.end());
  const SparseMatrix<double> C = gen::selection(n, gen::random_subset(n, 10, 7));
  const SparseMatrix<double> D = Matrix<double>::Random(n, 4).sparseView();
  SubspaceOptions opts;
  opts.backend = Backend::Cholmod;
  VariationalSubspace<double> plain, grouped;
  REQUIRE(build_subspace(H, C, D, opts, &plain).ok());
  opts.ordering_groups.resize(static_cast<size_t>(n));
  for (Index i = 0; i < n; ++i) opts.ordering_groups[static_cast<size_t>(i)] = i / 2;
  const SubspaceSummary summary = build_subspace(H, C, D, opts, &grouped);
  REQUIRE(summary.ok());
  CHECK((grouped.N - plain.N).norm() <= 1e-10 * plain.N.norm());
  CHECK((grouped.UD - plain.UD).norm() <= 1e-10 * plain.UD.norm());
  CHECK(summary.kkt_residual < 1e-12);

  auto message_of = [&](const SubspaceOptions& o) -> std::string {
    VariationalSubspace<double> s;
    try {
      build_subspace(H, C, D, o, &s);
    } catch (const std::invalid_argument& e) {
      return e.what();
    }
    return "no exception";
  };
  SubspaceOptions short_groups = opts;
  short_groups.ordering_groups.pop_back();
  CHECK_THAT(message_of(short_groups), Catch::Contains("ordering_groups size"));
  SubspaceOptions negative = opts;
  negative.ordering_groups[5] = -1;
  CHECK_THAT(message_of(negative), Catch::Contains("negative group -1"));
}
