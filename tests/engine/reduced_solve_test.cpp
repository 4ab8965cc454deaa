// The reduced solver over both scalars: reproduction of in-span demands,
// agreement with a dense solve of the reduced KKT system for any p, and a
// solver restored from its parts.
#include <catch2/catch.hpp>

#include "subspace_test_util.h"

#include <cstdint>
#include <limits>
#include <vector>

using namespace qpreduce;
using namespace subspace_test;

namespace {

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
  INFO(sub.brief_report());
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
    INFO(sub.brief_report());
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

TEMPLATE_TEST_CASE("solve matches a dense solve of the reduced KKT system for any p", "[solver][kernels]", double,
                   float) {
  using S = TestType;
  // p = d + k not a multiple of the SIMD width, so the kernels' tails run.
  const Index d = GENERATE(3, 9, 17, 30), k = GENERATE(0, 2, 7);
  CAPTURE(d, k);
  const Index nx = 15, ny = 13, n = nx * ny, m = std::min<Index>(d, 4);
  const std::vector<Index> rows = gen::random_subset(n, d, 61);
  const SparseMatrix<double> H = gen::grid_laplacian_2d(nx, ny, 0.05);
  const SparseMatrix<double> C = gen::selection(n, rows);
  const SparseMatrix<double> D = k > 0 ? gen::grid_trend_basis(nx, ny, k) : SparseMatrix<double>(n, 0);
  SubspaceSolver<S> solver;
  REQUIRE(solver.precompute(H.cast<S>(), C.cast<S>(), D.cast<S>()).ok());
  const SparseMatrix<double> A = gen::selection(n, std::vector<Index>(rows.begin(), rows.begin() + m));
  REQUIRE(solver.set_constraints(A.cast<S>()).status == Status::Success);
  const Index p = solver.p();
  const Vector<double> b = gen::gaussian_vector(m, 62), q_r = gen::gaussian_vector(p, 63);
  Vector<S> w(p);
  solver.solve(b.cast<S>(), q_r.cast<S>(), w);
  // [[H_r, A_rᵀ], [A_r, 0]]·[w; λ] = [q_r; b].
  const Matrix<double> Hr = solver.reduced_hessian().template cast<double>();
  const Matrix<double> Ar = solver.reduced_constraints().template cast<double>();
  Matrix<double> K = Matrix<double>::Zero(p + m, p + m);
  K.topLeftCorner(p, p) = Hr;
  K.topRightCorner(p, m) = Ar.transpose();
  K.bottomLeftCorner(m, p) = Ar;
  Vector<double> rhs(p + m);
  rhs << q_r, b;
  const Vector<double> ref = K.fullPivLu().solve(rhs).head(p);
  CHECK((w.template cast<double>() - ref).norm() <= tolerance<S>() * 10 * (1 + ref.norm()));
  if (k > 0) {
    const Vector<double> Y = gen::gaussian_vector(k, 64);
    Vector<S> wY(p), qY(p), w2(p);
    solver.solve_in_D(b.cast<S>(), Y.cast<S>(), wY);
    solver.reduce_linear_term_in_D(Y.cast<S>(), qY);
    solver.solve(b.cast<S>(), qY, w2);
    CHECK((wY - w2).norm() <= tolerance<S>() * 10 * (1 + w2.norm()));
  }
}

TEST_CASE("a solver without its basis solves reduced demands like the original and refuses the others",
          "[solver][restore]") {
  const Problem p = in_span_problem(14, 13, 0.0, 22);
  SubspaceSolver<double> original;
  REQUIRE(original.precompute(p.H, p.C, p.D).ok());
  REQUIRE(original.has_basis());
  const Matrix<double> Ac = gen::gaussian_matrix(original.d(), 3, 5);
  const Vector<double> b = gen::gaussian_vector(3, 6);

  SubspaceSolver<double> restored;
  restored.restore_without_basis(original.n(), original.d(), original.basis_norms(),
                                 Matrix<double>(original.reduced_hessian()),
                                 Matrix<double>(original.reduced_linear_map()));
  SubspaceSolver<double> released = original;
  released.release_basis();
  for (SubspaceSolver<double>* s : {&restored, &released}) {
    REQUIRE(s->ready());
    CHECK_FALSE(s->has_basis());
    CHECK(s->subspace().N.size() == 0);
    CHECK(s->n() == original.n());
    CHECK(s->d() == original.d());
    CHECK(s->k() == original.k());
    CHECK(s->basis_norms() == original.basis_norms());
  }
  Vector<double> w0(original.p()), w(original.p()), X(original.n()), qr(original.p());
  REQUIRE(original.set_constraints_in_design(Ac).ok());
  original.solve_in_D(b, p.Y, w0);
  for (SubspaceSolver<double>* s : {&restored, &released}) {
    REQUIRE(s->set_constraints_in_design(Ac).ok());
    s->solve_in_D(b, p.Y, w);
    CHECK((w - w0).norm() <= 1e-14 * w0.norm());
    CHECK_THROWS_WITH(s->set_constraints(p.A), Catch::Contains("holds no basis"));
    CHECK_THROWS_WITH(s->reconstruct(w, X), Catch::Contains("holds no basis"));
    CHECK_THROWS_WITH(s->reduce_linear_term(Vector<double>::Ones(original.n()), qr), Catch::Contains("holds no basis"));
  }
  // General constraints with A_r = AᵀB formed by the caller (as the ranks of
  // qpreduce::distributed sum it): the solution of set_constraints(A).
  const Matrix<double> Ar = Matrix<double>(p.A.transpose()) *
                            (Matrix<double>(original.n(), original.p()) << original.subspace().N,
                             original.subspace().UD)
                                .finished();
  REQUIRE(original.set_constraints(p.A).ok());
  original.solve_in_D(p.b, p.Y, w0);
  REQUIRE(restored.set_constraints_reduced(p.A, Ar).ok());
  restored.solve_in_D(p.b, p.Y, w);
  CHECK((w - w0).norm() <= 1e-12 * w0.norm());
  CHECK_THROWS_WITH(restored.set_constraints_reduced(p.A, Ar.leftCols(2)), Catch::Contains("A_r columns"));
  CHECK_THROWS_WITH(restored.set_constraints_reduced(p.A, Ar.topRows(1)), Catch::Contains("A_r rows"));
  // The copy released its basis, the original keeps its own.
  CHECK(original.has_basis());
  original.reconstruct(w0, X);

  SECTION("inconsistent parts are refused") {
    SubspaceSolver<double> bad;
    const Matrix<double> Hr = original.reduced_hessian();
    const Matrix<double> BtD = original.reduced_linear_map();
    const Vector<double> norms = original.basis_norms();
    CHECK_THROWS_WITH(bad.restore_without_basis(original.n(), original.d(), norms.head(2), Hr, BtD),
                      Catch::Contains("basis norms"));
    CHECK_THROWS_WITH(bad.restore_without_basis(original.n(), original.p() + 1, norms, Hr, BtD),
                      Catch::Contains("fewer than d"));
    CHECK_THROWS_WITH(bad.restore_without_basis(0, original.d(), norms, Hr, BtD), Catch::Contains("n ≥ 1"));
    CHECK_THROWS_WITH(bad.restore_without_basis(original.n(), original.d() - 1, norms, Hr, BtD),
                      Catch::Contains("BᵀD cols"));
    Vector<double> negative = norms;
    negative(0) = -1.0;
    CHECK_THROWS_WITH(bad.restore_without_basis(original.n(), original.d(), negative, Hr, BtD),
                      Catch::Contains("negative"));
    Matrix<double> asym = Hr;
    asym(0, 1) += 1.0;
    CHECK_THROWS_WITH(bad.restore_without_basis(original.n(), original.d(), norms, asym, BtD),
                      Catch::Contains("not symmetric"));
    CHECK_FALSE(bad.ready());
  }
}

TEST_CASE("a solver restored from its parts solves like the original", "[solver][restore]") {
  const Problem p = in_span_problem(14, 13, 0.0, 21);
  SubspaceSolver<double> original;
  REQUIRE(original.precompute(p.H, p.C, p.D).ok());
  SubspaceSolver<double> restored;
  restored.restore(original.subspace(), Matrix<double>(original.reduced_hessian()),
                   Matrix<double>(original.reduced_linear_map()));
  REQUIRE(restored.ready());
  CHECK(restored.n() == original.n());
  CHECK(restored.p() == original.p());
  for (SubspaceSolver<double>* s : {&original, &restored}) REQUIRE(s->set_constraints(p.A).ok());
  Vector<double> w0(original.p()), w1(restored.p());
  original.solve_in_D(p.b, p.Y, w0);
  restored.solve_in_D(p.b, p.Y, w1);
  CHECK((w1 - w0).norm() <= 1e-14 * w0.norm());

  SECTION("inconsistent parts are refused") {
    SubspaceSolver<double> bad;
    Matrix<double> Hr = original.reduced_hessian();
    Matrix<double> BtD = original.reduced_linear_map();
    CHECK_THROWS_WITH(bad.restore(original.subspace(), Hr.topLeftCorner(3, 3), BtD),
                      Catch::Contains("H_r rows"));
    CHECK_THROWS_WITH(bad.restore(original.subspace(), Hr, BtD.topRows(2)), Catch::Contains("BᵀD rows"));
    Matrix<double> asym = Hr;
    asym(0, 1) += 1.0;
    CHECK_THROWS_WITH(bad.restore(original.subspace(), asym, BtD), Catch::Contains("not symmetric"));
    VariationalSubspace<double> nan = original.subspace();
    nan.UD(3, 0) = std::numeric_limits<double>::quiet_NaN();
    CHECK_THROWS_AS(bad.restore(nan, Hr, BtD), std::invalid_argument);
    CHECK_FALSE(bad.ready());
  }
}
