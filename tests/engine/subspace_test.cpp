// Conformance of the variational subspace and the reduced solver over every
// backend and both scalars, plus the error paths.
#include <catch2/catch.hpp>

#include "qpreduce/full_solve.h"
#include "qpreduce/generators.h"
#include "qpreduce/subspace_solver.h"

#include <Eigen/Dense>

#include <limits>
#include <string>

using namespace qpreduce;
namespace gen = qpreduce::generators;

namespace {

// A demand that lies in the design spaces: A = C·A_c, q = D·Y.
struct Problem {
  SparseMatrix<double> H, C, D, A;
  Vector<double> b, q, Y;
};

Problem in_span_problem(Index nx, Index ny, double ridge, std::uint64_t seed) {
  Problem p;
  const Index n = nx * ny;
  p.H = gen::grid_laplacian_2d(nx, ny, ridge);
  p.C = gen::selection(n, gen::random_subset(n, 12, seed));
  p.D = gen::grid_trend_basis(nx, ny, 4);
  const Matrix<double> Ac = gen::gaussian_matrix(12, 5, seed + 1);
  p.A = (p.C * Ac).sparseView();
  p.Y = gen::gaussian_vector(4, seed + 2);
  p.q = p.D * p.Y;
  p.b = gen::gaussian_vector(5, seed + 3);
  return p;
}

// Dense KKT solve of Eq. 1, the independent truth for small problems.
Vector<double> dense_kkt_solve(const SparseMatrix<double>& H, const SparseMatrix<double>& A,
                               const Vector<double>& b, const Vector<double>& q) {
  const Index n = H.rows(), m = A.cols();
  Matrix<double> K = Matrix<double>::Zero(n + m, n + m);
  K.topLeftCorner(n, n) = Matrix<double>(H);
  K.topRightCorner(n, m) = Matrix<double>(A);
  K.bottomLeftCorner(m, n) = Matrix<double>(A).transpose();
  Vector<double> rhs(n + m);
  rhs << q, b;
  return K.fullPivLu().solve(rhs).head(n);
}


template <typename Scalar>
double tolerance();
template <>
double tolerance<double>() { return 1e-10; }
template <>
double tolerance<float>() { return 2e-3; }

}  // namespace

TEMPLATE_TEST_CASE("reduced solve reproduces the full solution when the demand lies in Span(C), Span(D)",
                   "[subspace][conformance]", double, float) {
  using S = TestType;
  const Backend backend = GENERATE(Backend::Cholmod, Backend::SimplicialLDLT, Backend::SparseLU);
  const double ridge = GENERATE(0.0, 0.1);
  CAPTURE(to_string(backend), ridge);
  const Problem p = in_span_problem(17, 13, ridge, 42);
  const Vector<double> X_true = dense_kkt_solve(p.H, p.A, p.b, p.q);

  SubspaceOptions opts;
  opts.backend = backend;
  SubspaceSolver<S> solver;
  const SubspaceSummary sub = solver.precompute(p.H.cast<S>(), p.C.cast<S>(), p.D.cast<S>(), opts);
  INFO(sub.report());
  REQUIRE(sub.ok());
  REQUIRE(sub.backend_used == (backend == Backend::SparseLU ? Backend::SparseLU : backend));
  CHECK(sub.kkt_residual < 50 * std::numeric_limits<S>::epsilon());

  const ConstraintSummary cs = solver.set_constraints(p.A.cast<S>());
  INFO(cs.message);
  REQUIRE(cs.status == Status::Success);
  CHECK(cs.rank == 5);

  Vector<S> w(solver.p()), X(solver.n());
  solver.solve_in_D(p.b.cast<S>(), p.Y.cast<S>(), w);
  solver.reconstruct(w, X);
  const Vector<double> Xd = X.template cast<double>();
  const double rel = (Xd - X_true).norm() / X_true.norm();
  CHECK(rel <= tolerance<S>());

  // The general linear-term path agrees with the in-D path.
  Vector<S> qr(solver.p()), w2(solver.p());
  solver.reduce_linear_term(p.q.cast<S>(), qr);
  solver.solve(p.b.cast<S>(), qr, w2);
  CHECK((w2 - w).norm() <= tolerance<S>() * (1 + w.norm()));

  // Constraints hold.
  const Vector<double> res = Matrix<double>(p.A).transpose() * Xd - p.b;
  CHECK(res.norm() <= tolerance<S>() * (1 + p.b.norm()) * 10);
}

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

TEST_CASE("random PSD H with a null space: reduced equals full on in-span demands", "[subspace]") {
  for (std::uint64_t seed = 1; seed <= 20; ++seed) {
    CAPTURE(seed);
    const Index n = 40, d = 8, k = 3, m = 4;
    const SparseMatrix<double> H = gen::random_psd(n, 4, seed);
    const SparseMatrix<double> C = gen::gaussian_sparse(n, d, seed + 100);
    const SparseMatrix<double> D = gen::gaussian_sparse(n, k, seed + 200);
    SubspaceOptions opts;
    opts.backend = seed % 2 ? Backend::Cholmod : Backend::SparseLU;
    SubspaceSolver<double> solver;
    const SubspaceSummary sub = solver.precompute(H, C, D, opts);
    INFO(sub.report());
    REQUIRE(sub.ok());
    const SparseMatrix<double> A = (C * gen::gaussian_matrix(d, m, seed + 300)).sparseView();
    REQUIRE(solver.set_constraints(A).status == Status::Success);
    const Vector<double> Y = gen::gaussian_vector(k, seed + 400), b = gen::gaussian_vector(m, seed + 500);
    Vector<double> w(solver.p()), X(n);
    solver.solve_in_D(b, Y, w);
    solver.reconstruct(w, X);
    const Vector<double> ref = dense_kkt_solve(H, A, b, D * Y);
    CHECK((X - ref).norm() <= 1e-10 * ref.norm());
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

TEST_CASE("over-determined hard constraints fall back to least squares with a status", "[solver]") {
  const Problem p = in_span_problem(12, 12, 0.0, 9);
  SubspaceSolver<double> solver;
  REQUIRE(solver.precompute(p.H, p.C, p.D).ok());
  // 14 constraints in a 12 + 4 dimensional subspace, two of them repeated
  // with inconsistent right-hand sides.
  const Index n = p.H.rows();
  std::vector<Index> rows = gen::random_subset(n, 12, 77);
  rows.push_back(rows[0]);
  rows.push_back(rows[1]);
  const SparseMatrix<double> A = gen::selection(n, rows);
  const ConstraintSummary cs = solver.set_constraints(A);
  CHECK(cs.status == Status::ConstraintsLeastSquares);
  CHECK(cs.rank == 12);
  CHECK_THAT(cs.message, Catch::Contains("least-squares"));
  Vector<double> b = gen::gaussian_vector(14, 78);
  Vector<double> w(solver.p());
  solver.solve_in_D(b, p.Y, w);
  REQUIRE(w.allFinite());
  // The least-squares answer meets the repeated pair halfway.
  const Vector<double> Ab = solver.reduced_constraints() * w;
  CHECK(Ab(0) == Approx(0.5 * (b(0) + b(12))).margin(1e-8));
  CHECK(Ab(1) == Approx(0.5 * (b(1) + b(13))).margin(1e-8));
}

TEST_CASE("soft constraints approach the hard ones as delta grows", "[solver]") {
  const Problem p = in_span_problem(12, 12, 0.0, 21);
  SubspaceSolver<double> solver;
  REQUIRE(solver.precompute(p.H, p.C, p.D).ok());
  Vector<double> w_hard(solver.p()), w_soft(solver.p());
  REQUIRE(solver.set_constraints(p.A).ok());
  solver.solve_in_D(p.b, p.Y, w_hard);
  double previous = std::numeric_limits<double>::infinity();
  for (double delta : {1.0, 1e2, 1e4, 1e6}) {
    ConstraintOptions o;
    o.soft = true;
    o.delta = delta;
    REQUIRE(solver.set_constraints(p.A, o).status == Status::Success);
    solver.solve_in_D(p.b, p.Y, w_soft);
    const double gap = (w_soft - w_hard).norm();
    CHECK(gap < previous);
    previous = gap;
  }
  CHECK(previous < 1e-3 * w_hard.norm());
}
