// Phase 1 with fixed coordinates (Eq. 16–17) and the alternating scheme.
#include <catch2/catch.hpp>

#include "qpreduce/alternating.h"
#include "qpreduce/generators.h"

#include <Eigen/Dense>

using namespace qpreduce;
namespace gen = qpreduce::generators;

namespace {

struct Fixture {
  Index nx = 14, ny = 11, n = nx * ny, d = 9, k = 4, m = 5;
  SparseMatrix<double> H = gen::grid_laplacian_2d(nx, ny);
  SparseMatrix<double> C = gen::selection(n, gen::random_subset(n, d, 5));
  SparseMatrix<double> D = gen::gaussian_sparse(n, k, 6);
  SubspaceSolver<double> solver;
  Fixture() { REQUIRE(solver.precompute(H, C, D).ok()); }
};

// Independent truth: minimise f(N z + UD·Y) with q = D·Y over z subject to
// Aᵀ(N z + UD·Y) = b, by a dense KKT solve in z.
Vector<double> dense_phase1(const Fixture& f, const SparseMatrix<double>& A, const Vector<double>& b,
                            const Vector<double>& Y) {
  const Matrix<double>& N = f.solver.subspace().N;
  const Matrix<double>& U = f.solver.subspace().UD;
  const Matrix<double> Hd(f.H);
  const Matrix<double> Ad(A);
  const Index d = N.cols(), m = A.cols();
  Matrix<double> K = Matrix<double>::Zero(d + m, d + m);
  K.topLeftCorner(d, d) = N.transpose() * Hd * N;
  K.topRightCorner(d, m) = N.transpose() * Ad;
  K.bottomLeftCorner(m, d) = Ad.transpose() * N;
  Vector<double> rhs(d + m);
  rhs.head(d) = N.transpose() * (Matrix<double>(f.D) * Y) - N.transpose() * Hd * U * Y;
  rhs.tail(m) = b - Ad.transpose() * U * Y;
  return K.fullPivLu().solve(rhs).head(d);
}

// Phase 2 stand-in: y ← y_target scaled to unit norm, plus a pull from z.
struct NormalizeProjection : Phase2Projection<double> {
  int calls = 0;
  double project(const Eigen::Ref<const Vector<double>>& z, Eigen::Ref<Vector<double>> y) override {
    ++calls;
    const Vector<double> old = y;
    y = (y + 0.01 * Vector<double>::Constant(y.size(), z.sum())).normalized();
    return (y - old).norm();
  }
};

}  // namespace

TEST_CASE("Phase 1 with fixed coordinates matches a dense solve in z", "[alternating]") {
  Fixture f;
  const bool soft = GENERATE(false, true);
  CAPTURE(soft);
  // A partly outside Span(C): selection of other vertices.
  const SparseMatrix<double> A = gen::selection(f.n, gen::random_subset(f.n, f.m, 17));
  ConstraintOptions o;
  o.soft = soft;
  o.delta = 1e9;
  FixedCoordinateSolver<double> phase1;
  const ConstraintSummary cs = phase1.set_constraints(f.solver, A, o);
  INFO(cs.message);
  REQUIRE(cs.status == Status::Success);
  const Vector<double> b = gen::gaussian_vector(f.m, 18), Y = gen::gaussian_vector(f.k, 19);
  Vector<double> z(f.d);
  phase1.solve(b, Y, z);
  const Vector<double> ref = dense_phase1(f, A, b, Y);
  CHECK((z - ref).norm() <= (soft ? 1e-5 : 1e-9) * (1 + ref.norm()));
}

TEST_CASE("alternate runs the requested rounds and ends with Phase 1", "[alternating]") {
  Fixture f;
  const SparseMatrix<double> A = gen::selection(f.n, gen::random_subset(f.n, f.m, 23));
  FixedCoordinateSolver<double> phase1;
  REQUIRE(phase1.set_constraints(f.solver, A).ok());
  NormalizeProjection proj;
  const Vector<double> b = gen::gaussian_vector(f.m, 24);
  Vector<double> z(f.d), y = gen::gaussian_vector(f.k, 25);
  AlternatingOptions opts;
  opts.iterations = 5;
  const AlternatingSummary s = alternate<double>(phase1, proj, b, opts, z, y);
  CHECK(s.iterations == 5);
  CHECK(proj.calls == 5);
  CHECK(y.norm() == Approx(1.0));
  // z is the Phase 1 answer for the returned y.
  Vector<double> z2(f.d);
  phase1.solve(b, y, z2);
  CHECK((z2 - z).norm() <= 1e-12 * (1 + z.norm()));

  // With a tolerance the loop stops once y settles.
  opts.iterations = 200;
  opts.tolerance = 1e-12;
  proj.calls = 0;
  const AlternatingSummary s2 = alternate<double>(phase1, proj, b, opts, z, y);
  CHECK(s2.iterations < 200);
  CHECK(s2.last_change <= 1e-12 * std::max(1.0, y.norm()));
}

namespace {
// A Phase 2 whose input is linear in (z, y): g = G_z z + G_y y, y ← g/‖g‖.
struct LinearInput {
  Matrix<double> Gz, Gy;
};
struct NormalizeZ : Phase2Projection<double> {
  const LinearInput* in;
  double project(const Eigen::Ref<const Vector<double>>& z, Eigen::Ref<Vector<double>> y) override {
    const Vector<double> old = y;
    y = (in->Gz * z + in->Gy * y).normalized();
    return (y - old).norm();
  }
};
struct NormalizeG : InputProjection<double> {
  double project(const Eigen::Ref<const Vector<double>>& g, Eigen::Ref<Vector<double>> y) override {
    const Vector<double> old = y;
    y = g.normalized();
    return (y - old).norm();
  }
};
}  // namespace

TEST_CASE("fused alternation gives the iterates of the plain one", "[alternating]") {
  Fixture f;
  const SparseMatrix<double> A = gen::selection(f.n, gen::random_subset(f.n, f.m, 31));
  FixedCoordinateSolver<double> phase1;
  REQUIRE(phase1.set_constraints(f.solver, A).ok());
  LinearInput in{0.3 * gen::gaussian_matrix(f.k, f.d, 32), gen::gaussian_matrix(f.k, f.k, 33)};
  NormalizeZ plain;
  plain.in = &in;
  NormalizeG fused_proj;
  FusedAlternation<double> fused;
  fused.set(phase1, in.Gz, in.Gy);
  const Vector<double> b = gen::gaussian_vector(f.m, 34);
  Vector<double> z1(f.d), z2(f.d), y1 = gen::gaussian_vector(f.k, 35), y2 = y1;
  AlternatingOptions opts;
  opts.iterations = 6;
  alternate<double>(phase1, plain, b, opts, z1, y1);
  const AlternatingSummary s = fused.run(phase1, fused_proj, b, opts, z2, y2);
  CHECK(s.iterations == 6);
  CHECK((y1 - y2).norm() <= 1e-12 * (1 + y1.norm()));
  CHECK((z1 - z2).norm() <= 1e-12 * (1 + z1.norm()));
  CHECK_THROWS_WITH(fused.set(phase1, Matrix<double>(f.k, f.d + 1), in.Gy), Catch::Contains("G_z columns"));

  // Mixed precision: F_y·y in float changes the iterates only at float
  // round-off, and Phase 1's final z = M_b·b + M_Y·y is still in double.
  opts.float_products = true;
  Vector<double> z3(f.d), y3 = gen::gaussian_vector(f.k, 35);
  fused.run(phase1, fused_proj, b, opts, z3, y3);
  const double yerr = (y3 - y1).norm() / (1 + y1.norm());
  CHECK(yerr <= 1e-5);
  CHECK(yerr > 0.0);  // the float path did run
  Vector<double> z_expected(f.d);
  phase1.solve(b, y3, z_expected);
  CHECK((z3 - z_expected).norm() <= 1e-13 * (1 + z3.norm()));
}

TEST_CASE("alternating scheme rejects bad input", "[alternating][errors]") {
  Fixture f;
  FixedCoordinateSolver<double> phase1;
  SubspaceSolver<double> not_ready;
  CHECK_THROWS_WITH(phase1.set_constraints(not_ready, SparseMatrix<double>(f.n, 1)),
                    Catch::Contains("not ready"));
  CHECK_THROWS_WITH(phase1.set_constraints(f.solver, SparseMatrix<double>(3, 1)),
                    Catch::Contains("expected " + std::to_string(f.n) + ", got 3"));
  AlternatingOptions o;
  o.iterations = 0;
  std::string why;
  CHECK_FALSE(o.is_valid(&why));
  CHECK_THAT(why, Catch::Contains("iterations"));
}
