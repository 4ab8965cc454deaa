// Constraints in the reduced solver (set_constraints): over-determined hard
// constraints, dropped rows, soft constraints (Eq. 18), and the fast and
// factored paths against the null-space method.
#include <catch2/catch.hpp>

#include "subspace_test_util.h"

#include <limits>
#include <string>
#include <vector>

using namespace qpreduce;
using namespace subspace_test;

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

TEST_CASE("the fast path prepared at the first set_constraints answers as one prepared at precompute",
          "[solver][fast]") {
  const Index nx = 16, ny = 16, n = nx * ny;
  const SparseMatrix<double> H = gen::grid_laplacian_2d(nx, ny);
  const std::vector<Index> rows = gen::random_subset(n, 24, 41);
  const SparseMatrix<double> C = gen::selection(n, rows), D = gen::grid_trend_basis(nx, ny, 6);
  SubspaceOptions deferred;
  deferred.prepare_constraint_path = false;
  SubspaceSolver<double> eager, lazy;
  REQUIRE(eager.precompute(H, C, D).ok());
  REQUIRE(lazy.precompute(H, C, D, deferred).ok());
  const std::vector<Index> handles(rows.begin(), rows.begin() + 8);
  const Vector<double> q = gen::gaussian_vector(n, 42), Y = gen::gaussian_vector(6, 43);
  for (const bool soft : {false, true}) {
    CAPTURE(soft);
    ConstraintOptions o;
    o.soft = soft;
    const SparseMatrix<double> A = gen::selection(n, handles);
    const Vector<double> b = gen::gaussian_vector(A.cols(), 44);
    const ConstraintSummary se = eager.set_constraints(A, o), sl = lazy.set_constraints(A, o);
    REQUIRE(se.status == Status::Success);
    CHECK(sl.status == se.status);
    CHECK(sl.fast_path == se.fast_path);
    CHECK(sl.fast_path);
    Vector<double> q_r(eager.p()), we(eager.p()), wl(lazy.p()), ye(eager.p()), yl(lazy.p());
    eager.reduce_linear_term(q, q_r);
    eager.solve(b, q_r, we);
    lazy.solve(b, q_r, wl);
    eager.solve_in_D(b, Y, ye);
    lazy.solve_in_D(b, Y, yl);
    CHECK(wl == we);  // the same arithmetic, only earlier or later
    CHECK(yl == ye);
  }
  // A restore without the preparation prepares at its first set_constraints too.
  SubspaceSolver<double> restored;
  restored.restore(lazy.subspace(), lazy.reduced_hessian(), lazy.reduced_linear_map(), deferred);
  const SparseMatrix<double> A = gen::selection(n, handles);
  const Vector<double> b = gen::gaussian_vector(A.cols(), 44);
  REQUIRE(restored.set_constraints(A).status == Status::Success);
  REQUIRE(eager.set_constraints(A).status == Status::Success);
  Vector<double> q_r(eager.p()), we(eager.p()), wr(restored.p());
  eager.reduce_linear_term(q, q_r);
  eager.solve(b, q_r, we);
  restored.solve(b, q_r, wr);
  CHECK((wr - we).norm() <= 1e-12 * we.norm());
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
