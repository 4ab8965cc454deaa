// Conformance of the variational subspace and the reduced solver over every
// backend and both scalars, plus the error paths.
#include <catch2/catch.hpp>

#include "qpreduce/factorization.h"
#include "qpreduce/full_solve.h"
#include "qpreduce/problems/generators.h"
#include "qpreduce/subspace_solver.h"

#include <Eigen/Dense>
#include <omp.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

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

TEST_CASE("a constraint orthogonal to the subspace is dropped honestly", "[solver][drop]") {
  // a ⊥ Span(B) up to round-off: its row of A_r = AᵀB is round-off, all of it
  // below drop_tolerance, so it becomes zero and the set is rank deficient.
  const Problem p = in_span_problem(12, 12, 0.0, 9);
  SubspaceSolver<double> solver;
  REQUIRE(solver.precompute(p.H, p.C, p.D).ok());
  const Index n = p.H.rows();
  Matrix<double> B(n, solver.p());
  B << solver.subspace().N, solver.subspace().UD;
  const Eigen::HouseholderQR<Matrix<double>> qr(B);
  const Matrix<double> Q = qr.householderQ() * Matrix<double>::Identity(n, solver.p());
  Vector<double> a = gen::gaussian_vector(n, 81);
  for (int pass = 0; pass < 2; ++pass) a -= Q * (Q.transpose() * a);
  a /= a.norm();
  const std::vector<Index> rows = gen::random_subset(n, 3, 82);
  Matrix<double> Ad = Matrix<double>(gen::selection(n, rows));
  Ad.conservativeResize(n, 4);
  Ad.col(3) = a;
  const SparseMatrix<double> A = Ad.sparseView();
  const Vector<double> b = gen::gaussian_vector(4, 83);
  for (const double tau : {ConstraintOptions{}.drop_tolerance, 0.0}) {
    for (const bool soft : {false, true}) {
      CAPTURE(tau, soft);
      ConstraintOptions o;
      o.drop_tolerance = tau;
      o.soft = soft;
      const ConstraintSummary cs = solver.set_constraints(A, o);
      INFO(cs.message);
      // (Soft constraints report the rank at ε, which a round-off row may pass.)
      if (tau > 0.0 || !soft) CHECK(cs.rank == 3);
      if (tau > 0.0) {
        CHECK(solver.reduced_constraints().row(3).isZero(0.0));
        CHECK(cs.dropped >= solver.p());
        CHECK_THAT(cs.message, Catch::Contains("no component in the subspace"));
      } else {
        CHECK(cs.dropped == 0);
      }
      if (!soft) {
        CHECK(cs.status == Status::ConstraintsLeastSquares);
        CHECK_THAT(cs.message, Catch::Contains("least-squares"));
      }
      Vector<double> w(solver.p());
      solver.solve_in_D(b, p.Y, w);
      REQUIRE(w.allFinite());
      // The other three constraints still hold (exactly for hard ones).
      const Vector<double> Aw = solver.reduced_constraints().topRows(3) * w;
      if (!soft) CHECK((Aw - b.head(3)).norm() <= 1e-10 * (1.0 + b.norm()));
    }
  }
  ConstraintOptions bad;
  bad.drop_tolerance = -1e-3;
  CHECK_THROWS_AS(solver.set_constraints(A, bad), std::invalid_argument);
  bad.drop_tolerance = 1.0;
  CHECK_THROWS_AS(solver.set_constraints(A, bad), std::invalid_argument);
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

// ---- performance paths: each must agree with the reference it replaces ----

TEST_CASE("set_constraints fast path agrees with the null-space method", "[solver][fast]") {
  const Index nx = 20, ny = 20, n = nx * ny;
  const SparseMatrix<double> H = gen::grid_laplacian_2d(nx, ny);  // PSD, constants in ker H
  const std::vector<Index> rows = gen::random_subset(n, 30, 31);
  const SparseMatrix<double> C = gen::selection(n, rows);
  const SparseMatrix<double> D = gen::grid_trend_basis(nx, ny, 6);
  SubspaceSolver<double> solver;
  REQUIRE(solver.precompute(H, C, D).ok());
  // The reduced Hessian is BᵀHB of the stored subspace.
  Matrix<double> B(n, solver.p());
  B << solver.subspace().N, solver.subspace().UD;
  const Matrix<double> BtHB = B.transpose() * (H * B);
  CHECK((solver.reduced_hessian() - BtHB).norm() <= 1e-12 * BtHB.norm());

  struct Demand {
    const char* name;
    SparseMatrix<double> A;
    bool soft;
    Status expected;
    bool fast;  // whether the fast path is expected to take it
  };
  std::vector<Index> handles(rows.begin(), rows.begin() + 10);
  std::vector<Eigen::Triplet<double>> diff;  // e_i − e_j over C vertices: blind to constants
  for (Index c = 0; c < 5; ++c) {
    diff.emplace_back(rows[2 * c], c, 1.0);
    diff.emplace_back(rows[2 * c + 1], c, -1.0);
  }
  SparseMatrix<double> Adiff(n, 5);
  Adiff.setFromTriplets(diff.begin(), diff.end());
  std::vector<Index> repeated = handles;
  repeated.push_back(handles[0]);
  const std::vector<Demand> demands = {
      {"point handles", gen::selection(n, handles), false, Status::Success, true},
      {"dense combinations", (C * gen::gaussian_matrix(30, 7, 32)).sparseView(), false, Status::Success, true},
      {"soft point handles", gen::selection(n, handles), true, Status::Success, true},
      {"differences only (constant mode free)", Adiff, false, Status::Unbounded, false},
      {"repeated handle", gen::selection(n, repeated), false, Status::ConstraintsLeastSquares, false},
      {"no constraints (constant mode free)", SparseMatrix<double>(n, 0), false, Status::Unbounded, false},
  };
  for (const Demand& demand : demands) {
    CAPTURE(demand.name);
    const Index m = demand.A.cols();
    const Vector<double> b = gen::gaussian_vector(m, 33), Y = gen::gaussian_vector(6, 34);
    const Vector<double> q = gen::gaussian_vector(n, 35);
    Vector<double> q_r(solver.p());
    solver.reduce_linear_term(q, q_r);
    Vector<double> w[2], wY[2];
    for (int fast = 0; fast < 2; ++fast) {
      ConstraintOptions o;
      o.soft = demand.soft;
      o.delta = 1e2;
      o.fast_path = fast == 1;
      const ConstraintSummary cs = solver.set_constraints(demand.A, o);
      INFO(cs.message);
      CHECK(cs.status == demand.expected);
      CHECK(cs.fast_path == (fast == 1 && demand.fast));
      w[fast].resize(solver.p());
      wY[fast].resize(solver.p());
      solver.solve(b, q_r, w[fast]);
      solver.solve_in_D(b, Y, wY[fast]);
      REQUIRE(w[fast].allFinite());
    }
    if (demand.expected != Status::Unbounded) {  // otherwise the answer is not unique
      CHECK((w[1] - w[0]).norm() <= 1e-9 * w[0].norm());
      CHECK((wY[1] - wY[0]).norm() <= 1e-9 * wY[0].norm());
    }
  }
}

TEST_CASE("factored fast path agrees with the explicit one", "[solver][fast][factored]") {
  // ridge 0: H̄ has a lifted direction (ν = 1, constants); ridge > 0: ν = 0.
  const double ridge = GENERATE(0.0, 1e-2);
  CAPTURE(ridge);
  const Index nx = 20, ny = 20, n = nx * ny, d = 30, k = 6;
  const SparseMatrix<double> H = gen::grid_laplacian_2d(nx, ny, ridge);
  const SparseMatrix<double> C = gen::selection(n, gen::random_subset(n, d, 51));
  const SparseMatrix<double> D = gen::grid_trend_basis(nx, ny, k);
  SubspaceSolver<double> solver;
  REQUIRE(solver.precompute(H, C, D).ok());
  const Index p = solver.p();

  auto columns = [&](std::initializer_list<std::initializer_list<std::pair<Index, double>>> cols) {
    Matrix<double> Ac = Matrix<double>::Zero(d, static_cast<Index>(cols.size()));
    Index j = 0;
    for (const auto& col : cols) {
      for (const auto& [i, v] : col) Ac(i, j) = v;
      ++j;
    }
    return Ac;
  };
  struct Demand {
    const char* name;
    Matrix<double> Ac;
    bool soft;
    bool factored;  // whether the default options must keep M_q factored
  };
  const std::vector<Demand> demands = {
      {"selection", columns({{{0, 1.0}}, {{3, 1.0}}, {{7, 1.0}}, {{12, 1.0}}, {{20, 1.0}}}), false, true},
      {"sparse sums", columns({{{0, 1.0}, {1, 0.5}}, {{2, 1.0}, {9, -2.0}}, {{4, 1.0}, {5, 1.0}, {6, 1.0}}}), false,
       true},
      {"soft selection", columns({{{0, 1.0}}, {{3, 1.0}}, {{7, 1.0}}}), true, true},
      {"no constraints", Matrix<double>(d, 0), false, false},
      {"differences only", columns({{{0, 1.0}, {1, -1.0}}, {{2, 1.0}, {3, -1.0}}}), false, false},
      {"repeated", columns({{{0, 1.0}}, {{3, 1.0}}, {{0, 1.0}}}), false, false},
      {"dense combinations", gen::gaussian_matrix(d, 7, 52), false, false},
  };
  for (const Demand& demand : demands) {
    CAPTURE(demand.name);
    const Index m = demand.Ac.cols();
    const Vector<double> b = gen::gaussian_vector(m, 53), Y = gen::gaussian_vector(k, 54);
    Vector<double> q_r(p);
    solver.reduce_linear_term(gen::gaussian_vector(n, 55), q_r);
    ConstraintSummary cs[2];
    Vector<double> w[2], wY[2];
    for (int explicit_ops = 0; explicit_ops < 2; ++explicit_ops) {
      ConstraintOptions o;
      o.soft = demand.soft;
      o.delta = 1e2;
      o.explicit_operators = explicit_ops == 1;
      cs[explicit_ops] = solver.set_constraints_in_design(demand.Ac, o);
      INFO(cs[explicit_ops].message);
      w[explicit_ops].resize(p);
      wY[explicit_ops].resize(p);
      solver.solve(b, q_r, w[explicit_ops]);
      solver.solve_in_D(b, Y, wY[explicit_ops]);
      REQUIRE(w[explicit_ops].allFinite());
      REQUIRE(wY[explicit_ops].allFinite());
    }
    CHECK(cs[0].status == cs[1].status);
    CHECK(cs[0].rank == cs[1].rank);
    CHECK(cs[0].fast_path == cs[1].fast_path);
    CHECK(cs[0].condition == Approx(cs[1].condition).epsilon(1e-12));
    CHECK_FALSE(cs[1].factored);
    if (demand.factored) CHECK(cs[0].factored);
    if (cs[0].factored) CHECK(cs[0].fast_path);
    // Dense A_c: more than half of A_r's entries are nonzero.
    if (std::string(demand.name) == "dense combinations") CHECK_FALSE(cs[0].factored);
    if (cs[0].status != Status::Unbounded) {  // otherwise the answer is not unique
      CHECK((w[0] - w[1]).norm() <= 1e-10 * w[1].norm());
      CHECK((wY[0] - wY[1]).norm() <= 1e-10 * wY[1].norm());
    }
    if (std::string(demand.name) == "selection") {
      // Rank and condition read off a scaled selection, as the null-space
      // method's pivoted QR (diagonal R) reports them.
      ConstraintOptions o;
      o.fast_path = false;
      const ConstraintSummary ref = solver.set_constraints_in_design(demand.Ac, o);
      CHECK(ref.rank == cs[0].rank);
      CHECK(ref.condition == Approx(cs[0].condition).epsilon(1e-12));
      CHECK(cs[0].condition > 1.0);  // D_s scales differ
    }
    if (cs[0].status == Status::Success && !demand.soft) {
      const Vector<double> Aw = solver.reduced_constraints() * wY[0];
      CHECK((Aw - b).norm() <= 1e-10 * (1.0 + b.norm()));
    }
  }

  // The float solver always forms its operators (see subspace_solver.h).
  SubspaceSolver<float> single;
  REQUIRE(single.precompute(H.cast<float>(), C.cast<float>(), D.cast<float>()).ok());
  const ConstraintSummary cf = single.set_constraints_in_design(demands.front().Ac.cast<float>());
  CHECK(cf.fast_path);
  CHECK_FALSE(cf.factored);
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
  const int previous = omp_get_max_threads();
  omp_set_num_threads(threads);
  Matrix<double> X = B;
  factor->solveInPlace(X, block);
  omp_set_num_threads(previous);
  CHECK((X - expected).norm() <= 1e-12 * expected.norm());
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
