// Phase 1 with fixed coordinates (Eq. 16–17) and the alternating scheme.
#include <catch2/catch.hpp>

#include "alternation_parts.h"
#include "qpreduce/problems/generators.h"

#include "alternation_fixtures.h"

#include <Eigen/Dense>

#include <algorithm>
#include <limits>

using namespace qpreduce;
using namespace qpreduce::testing_alternation;
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

// The plain alternation, the reference for FusedAlternation: Phase 2 sees
// (z, y) itself rather than an input g linear in them.
struct Phase2Projection {
  virtual ~Phase2Projection() = default;
  // Overwrites y in place and returns ‖y_new − y_old‖.
  virtual double project(const Eigen::Ref<const Vector<double>>& z, Eigen::Ref<Vector<double>> y) = 0;
};

// Runs Phase 1 then Phase 2, `options.iterations` times from the given y,
// and ends with a Phase 1, so z is optimal for the returned y.
AlternationResults reference_alternate(const FixedCoordinateSolver<double>& phase1, Phase2Projection& phase2,
                                       const Eigen::Ref<const Vector<double>>& b, const AlternationSettings& options,
                                       Eigen::Ref<Vector<double>> z, Eigen::Ref<Vector<double>> y) {
  AlternationResults summary;
  double change = 0.0;
  for (int it = 0; it < options.iterations; ++it) {
    phase1.solve(b, y, z);
    change = phase2.project(z, y);
    summary.iterations = it + 1;
    if (options.tolerance > 0 && change <= options.tolerance * std::max(1.0, static_cast<double>(y.norm()))) break;
  }
  phase1.solve(b, y, z);
  summary.last_change = change;
  summary.status = Status::Success;
  return summary;
}

// Phase 2 stand-in: y ← y_target scaled to unit norm, plus a pull from z.
struct NormalizeProjection : Phase2Projection {
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
  AlternationSettings opts;
  opts.iterations = 5;
  const AlternationResults s = reference_alternate(phase1, proj, b, opts, z, y);
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
  const AlternationResults s2 = reference_alternate(phase1, proj, b, opts, z, y);
  CHECK(s2.iterations < 200);
  CHECK(s2.last_change <= 1e-12 * std::max(1.0, y.norm()));
}

namespace {
// A Phase 2 whose input is linear in (z, y): g = G_z z + G_y y, y ← g/‖g‖.
struct LinearInput {
  Matrix<double> Gz, Gy;
};
struct NormalizeZ : Phase2Projection {
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
  AlternationSettings opts;
  opts.iterations = 6;
  reference_alternate(phase1, plain, b, opts, z1, y1);
  const AlternationResults s = fused.run(phase1, fused_proj, b, opts, z2, y2);
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

namespace {
// Phase 2 acting block by block (blocks of 3): y_j ← the nearest point of
// the unit ball to g_j, so the rounds may split the blocks between threads
// (and with ‖F_y‖ < 1 the rounds contract).
struct BallBlocks : InputProjection<double> {
  static constexpr Index kBlock = 3;
  double project(const Eigen::Ref<const Vector<double>>& g, Eigen::Ref<Vector<double>> y) override {
    return std::sqrt(project_blocks(g, y, 0, g.size() / kBlock));
  }
  Index block_size() const override { return kBlock; }
  double project_blocks(const Eigen::Ref<const Vector<double>>& g, Eigen::Ref<Vector<double>> y, Index first,
                        Index last) override {
    double change2 = 0.0;
    for (Index j = first; j < last; ++j) {
      const Vector<double> next = g.segment(kBlock * j, kBlock) / std::max(1.0, g.segment(kBlock * j, kBlock).norm());
      change2 += (next - y.segment(kBlock * j, kBlock)).squaredNorm();
      y.segment(kBlock * j, kBlock) = next;
    }
    return change2;
  }
};
}  // namespace

TEST_CASE("fused alternation: the factored form and parallel rounds give the explicit serial iterates",
          "[alternating][fast]") {
  // q = k = 12 (four blocks of 3), so that the rounds can be split.
  const Index n = 14 * 11, d = 9, k = 12, m = 5;
  const SparseMatrix<double> H = gen::grid_laplacian_2d(14, 11);
  SubspaceSolver<double> solver;
  REQUIRE(solver.precompute(H, gen::selection(n, gen::random_subset(n, d, 5)), gen::gaussian_sparse(n, k, 6)).ok());
  const SparseMatrix<double> A = gen::selection(n, gen::random_subset(n, m, 71));
  FixedCoordinateSolver<double> phase1;
  REQUIRE(phase1.set_constraints(solver, A).fast_path);
  const Matrix<double> Gz = 0.3 * gen::gaussian_matrix(k, d, 72), Gy = gen::gaussian_matrix(k, k, 73);
  const Vector<double> b = gen::gaussian_vector(m, 74), y0 = gen::gaussian_vector(k, 75);
  BallBlocks proj;

  struct Run {
    Vector<double> z, y;
    AlternationResults s;
  };
  // scale < 1 makes the rounds a contraction (g is dominated by F_b·b).
  auto run = [&](FusedForm form, bool float_products, int threads, double tolerance, int iterations = 6,
                 double scale = 1.0, FusedPrecision precision = FusedPrecision::Double) {
    FusedAlternation<double> fused;
    fused.set(phase1, scale * Gz, scale * Gy, 1, form, precision);
    CHECK(fused.factored() == (form == FusedForm::Factored));
    CHECK(fused.float_set() == (form == FusedForm::Factored && precision == FusedPrecision::Float));
    AlternationSettings o;
    o.iterations = iterations;
    o.float_products = float_products;
    o.threads = threads;
    o.parallel_min_entries = 0;
    o.tolerance = tolerance;
    Run r{Vector<double>(d), y0, {}};
    r.s = fused.run(phase1, proj, b, o, r.z, r.y);
    return r;
  };
  const Run ref = run(FusedForm::Explicit, false, 1, 0.0);
  REQUIRE(ref.s.iterations == 6);
  auto close = [](const Run& a, const Run& r, double tol) {
    CHECK(a.s.iterations == r.s.iterations);
    CHECK((a.y - r.y).norm() <= tol * (1 + r.y.norm()));
    CHECK((a.z - r.z).norm() <= tol * (1 + r.z.norm()));
  };
  for (int threads : {1, 2}) {
    INFO("threads " << threads);
    close(run(FusedForm::Explicit, false, threads, 0.0), ref, 1e-12);
    close(run(FusedForm::Factored, false, threads, 0.0), ref, 1e-12);
    // Float products: float round-off only; z from Phase 1 in double.
    const Run f = run(FusedForm::Factored, true, threads, 0.0);
    close(f, ref, 1e-5);
    Vector<double> z(d);
    phase1.solve(b, f.y, z);
    CHECK((f.z - z).norm() <= 1e-13 * (1 + z.norm()));
    // A Float set (G_z·T and F_b in float): float round-off only, and Phase
    // 1's z in double still.
    const Run fs = run(FusedForm::Factored, true, threads, 0.0, 6, 1.0, FusedPrecision::Float);
    close(fs, ref, 1e-5);
    CHECK((fs.y - f.y).norm() > 0.0);  // G_z·T did change precision
    phase1.solve(b, fs.y, z);
    CHECK((fs.z - z).norm() <= 1e-13 * (1 + z.norm()));
    // To a tight tolerance the float rounds stop at the double rounds' fixed
    // point: their products are relative to a double reference, so float
    // round-off neither moves the fixed point nor leaves a residual floor.
    const Run dd = run(FusedForm::Factored, false, threads, 1e-12, 2000, 0.05);
    const Run ff = run(FusedForm::Factored, true, threads, 1e-12, 2000, 0.05);
    CHECK(dd.s.stop == RoundStop::Tolerance);
    CHECK(ff.s.stop == RoundStop::Tolerance);
    CHECK(ff.s.iterations <= dd.s.iterations + 2);
    CHECK((ff.y - dd.y).norm() <= 1e-9 * (1 + dd.y.norm()));
    // Early exit: the same round on every thread count.
    const Run e1 = run(FusedForm::Factored, false, 1, 1e-9, 200, 0.05);
    const Run e2 = run(FusedForm::Factored, false, threads, 1e-9, 200, 0.05);
    INFO("last change " << e1.s.last_change);
    CHECK(e1.s.iterations < 200);
    close(e2, e1, 1e-12);
  }

  // Double rounds after a Float set are refused; the explicit form ignores
  // the precision.
  {
    FusedAlternation<double> fused;
    fused.set(phase1, Gz, Gy, 1, FusedForm::Factored, FusedPrecision::Float);
    AlternationSettings o;
    Vector<double> z(d), y = y0;
    CHECK_THROWS_WITH(fused.run(phase1, proj, b, o, z, y), Catch::Contains("float_products"));
    CHECK(y == y0);
    fused.set(phase1, Gz, Gy, 1, FusedForm::Explicit, FusedPrecision::Float);
    CHECK_FALSE(fused.float_set());
    CHECK_NOTHROW(fused.run(phase1, proj, b, o, z, y));
  }

  // set(phase1) reuses the last G_z, G_y: the same rounds for a new set.
  {
    FusedAlternation<double> reuse, fresh;
    CHECK_THROWS_WITH(reuse.set(phase1), Catch::Contains("no G_z"));
    reuse.set(phase1, Gz, Gy, 1, FusedForm::Factored);
    FixedCoordinateSolver<double> other;
    REQUIRE(other.set_constraints(solver, gen::selection(n, gen::random_subset(n, m, 76))).fast_path);
    reuse.set(other, 1, FusedForm::Factored);
    fresh.set(other, Gz, Gy, 1, FusedForm::Explicit);
    AlternationSettings o;
    Vector<double> z1(d), z2(d), y1 = y0, y2 = y0;
    reuse.run(other, proj, b, o, z1, y1);
    fresh.run(other, proj, b, o, z2, y2);
    CHECK((y1 - y2).norm() <= 1e-12 * (1 + y2.norm()));
    CHECK((z1 - z2).norm() <= 1e-12 * (1 + z2.norm()));
  }

  // prepare(): the per-solver parts ahead of the first constraint set, with
  // the same operators and rounds as without it.
  {
    FixedCoordinateSolver<double> early;
    early.prepare(solver);
    CHECK_FALSE(early.ready());
    FusedAlternation<double> fused, plain;
    fused.prepare(early, Gz, Gy, FusedPrecision::Float);
    CHECK_FALSE(fused.ready());
    REQUIRE(early.set_constraints(solver, A).fast_path);
    CHECK((early.Mb() - phase1.Mb()).norm() == 0.0);
    CHECK((early.MY() - phase1.MY()).norm() == 0.0);
    fused.set(early, 1, FusedForm::Factored, FusedPrecision::Float);  // the prepared G_z, G_y
    plain.set(phase1, Gz, Gy, 1, FusedForm::Factored, FusedPrecision::Float);
    AlternationSettings o;
    o.float_products = true;
    Vector<double> z1(d), z2(d), y1 = y0, y2 = y0;
    fused.run(early, proj, b, o, z1, y1);
    plain.run(phase1, proj, b, o, z2, y2);
    CHECK(y1 == y2);
    CHECK(z1 == z2);
    CHECK_THROWS_WITH(fused.prepare(early, Matrix<double>(k, d + 1), Gy), Catch::Contains("G_z columns"));
    // prepare resets the last set: run refuses until the next one.
    fused.prepare(early, Gz, Gy, FusedPrecision::Float);
    CHECK_THROWS_WITH(fused.run(early, proj, b, o, z1, y1), Catch::Contains("not set"));
    fused.set(early, 1, FusedForm::Factored, FusedPrecision::Float);
    Vector<double> short_b(m - 1), long_y(k + 1), short_z(d - 1);
    CHECK_THROWS_WITH(fused.run(early, proj, short_b, o, z1, y1), Catch::Contains("b (m)"));
    CHECK_THROWS_WITH(fused.run(early, proj, b, o, z1, long_y), Catch::Contains("y (k)"));
    CHECK_THROWS_WITH(fused.run(early, proj, b, o, short_z, y1), Catch::Contains("z (d)"));
    CHECK_THROWS_WITH(fused.prepare(early, Gz, Matrix<double>(k + 1, k)), Catch::Contains("G_y rows"));
    Matrix<double> bad = Gy;
    bad(1, 2) = std::numeric_limits<double>::infinity();
    CHECK_THROWS_WITH(fused.prepare(early, Gz, bad), Catch::Contains("G_y"));
    SubspaceSolver<double> not_ready;
    CHECK_THROWS_WITH(early.prepare(not_ready), Catch::Contains("not ready"));
  }

  // A_r given directly: the operators of set_constraints.
  FixedCoordinateSolver<double> reduced;
  const Matrix<double> Az = A.transpose() * solver.subspace().N, Ay = A.transpose() * solver.subspace().UD;
  REQUIRE(reduced.set_reduced_constraints(solver, Az, Ay).ok());
  CHECK((reduced.Mb() - phase1.Mb()).norm() <= 1e-14 * phase1.Mb().norm());
  CHECK((reduced.MY() - phase1.MY()).norm() <= 1e-14 * phase1.MY().norm());
  CHECK_THROWS_WITH(reduced.set_reduced_constraints(solver, Az, Matrix<double>(m, k + 1)),
                    Catch::Contains("A_y columns"));
  CHECK_THROWS_WITH(reduced.set_reduced_constraints(solver, Az, Matrix<double>(m + 1, k)),
                    Catch::Contains("A_y rows"));
  Matrix<double> bad = Az;
  bad(0, 0) = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(reduced.set_reduced_constraints(solver, bad, Ay), Catch::Contains("A_z"));
  AlternationSettings o;
  o.threads = -1;
  std::string why;
  CHECK_FALSE(o.is_valid(&why));
  CHECK_THAT(why, Catch::Contains("threads"));
}

TEST_CASE("alternating scheme rejects bad input", "[alternating][errors]") {
  Fixture f;
  FixedCoordinateSolver<double> phase1;
  SubspaceSolver<double> not_ready;
  CHECK_THROWS_WITH(phase1.set_constraints(not_ready, SparseMatrix<double>(f.n, 1)),
                    Catch::Contains("not ready"));
  CHECK_THROWS_WITH(phase1.set_constraints(f.solver, SparseMatrix<double>(3, 1)),
                    Catch::Contains("expected " + std::to_string(f.n) + ", got 3"));
  AlternationSettings o;
  o.iterations = 0;
  std::string why;
  CHECK_FALSE(o.is_valid(&why));
  CHECK_THAT(why, Catch::Contains("iterations"));
}

// ---- Phase 1's range-space fast path against the null-space method --------

namespace {

double rel_diff(const Matrix<double>& a, const Matrix<double>& b) {
  return (a - b).norm() / std::max(1.0, b.norm());
}

// A fixture whose H_zz is positive definite (ridge > 0), so that even an
// empty constraint set has a unique Phase 1 answer; the plain Fixture's grid
// Laplacian has the constants in its kernel (ν = 1 lifted direction).
struct RidgeFixture {
  Index n = 14 * 11, d = 9, k = 4;
  SparseMatrix<double> H = gen::grid_laplacian_2d(14, 11, 0.05);
  SparseMatrix<double> C = gen::selection(n, gen::random_subset(n, d, 5));
  SparseMatrix<double> D = gen::gaussian_sparse(n, k, 6);
  SubspaceSolver<double> solver;
  RidgeFixture() { REQUIRE(solver.precompute(H, C, D).ok()); }
};

// Phase 1's operators for soft constraints, solved in long double:
// (H_zz + 2δA_zᵀA_z)·z = G·Y + 2δA_zᵀ(b − A_y·Y).
struct ExactOperators {
  Matrix<double> Mb, MY;
};
ExactOperators exact_soft_phase1(const SubspaceSolver<double>& s, const SparseMatrix<double>& A, double delta) {
  using ML = Eigen::Matrix<long double, Eigen::Dynamic, Eigen::Dynamic>;
  const Index d = s.d(), k = s.k();
  const ML Hr = s.reduced_hessian().cast<long double>();
  const ML G = s.reduced_linear_map().topRows(d).cast<long double>() - Hr.topRightCorner(d, k);
  const ML Az = Matrix<double>(A.transpose() * s.subspace().N).cast<long double>();
  const ML Ay = Matrix<double>(A.transpose() * s.subspace().UD).cast<long double>();
  const long double two_delta = 2.0L * static_cast<long double>(delta);
  const ML K = Hr.topLeftCorner(d, d) + two_delta * Az.transpose() * Az;
  const Eigen::FullPivLU<ML> lu(K);
  const ML Mb = lu.solve(ML(two_delta * Az.transpose()));
  const ML MY = lu.solve(ML(G - two_delta * Az.transpose() * Ay));
  return {Mb.cast<double>(), MY.cast<double>()};
}

// The fused alternation of `phase1` (already set with G_z, G_y) and one set
// up from the reference Phase 1 give the same iterates (4 rounds).
void check_fused_agree(FusedAlternation<double>& fused, const FixedCoordinateSolver<double>& phase1,
                       const FixedCoordinateSolver<double>& ref, const Matrix<double>& Gz, const Matrix<double>& Gy,
                       double tol = 1e-10) {
  FusedAlternation<double> fref;
  fref.set(ref, Gz, Gy);
  NormalizeG proj;
  const Vector<double> b = gen::gaussian_vector(phase1.m(), 64);
  AlternationSettings opts;
  opts.iterations = 4;
  Vector<double> z1(phase1.d()), z2(phase1.d()), y1 = gen::gaussian_vector(phase1.k(), 65), y2 = y1;
  fused.run(phase1, proj, b, opts, z1, y1);
  fref.run(ref, proj, b, opts, z2, y2);
  CHECK((y1 - y2).norm() <= tol * std::max(1.0, y2.norm()));
  CHECK((z1 - z2).norm() <= tol * std::max(1.0, z2.norm()));
}

// Phase 1 and its fused alternation on the fast path and on the null-space
// method; returns the fast path's summary after checking both agree.
ConstraintSummary check_paths_agree(const SubspaceSolver<double>& solver, const SparseMatrix<double>& A,
                                    ConstraintOptions o, double tol) {
  o.fast_path = true;
  FixedCoordinateSolver<double> fast;
  const ConstraintSummary fs = fast.set_constraints(solver, A, o);
  o.fast_path = false;
  FixedCoordinateSolver<double> ref;
  const ConstraintSummary rs = ref.set_constraints(solver, A, o);
  INFO(fs.message << " | " << rs.message);
  CHECK_FALSE(rs.fast_path);
  CHECK(fs.status == rs.status);
  CHECK(fs.rank == rs.rank);
  CHECK(rel_diff(fast.Mb(), ref.Mb()) <= tol);
  CHECK(rel_diff(fast.MY(), ref.MY()) <= tol);
  CHECK(fast.Mb().allFinite());
  CHECK(fast.MY().allFinite());

  // The fused alternation built on each: the same iterates.
  const Index q = 2 * solver.k() + 3;
  FusedAlternation<double> ffast;
  const Matrix<double> Gz = 0.3 * gen::gaussian_matrix(q, solver.d(), 41);
  const Matrix<double> Gy = gen::gaussian_matrix(q, solver.k(), 42);
  ffast.set(fast, Gz, Gy);
  check_fused_agree(ffast, fast, ref, Gz, Gy, tol);
  return fs;
}

}  // namespace

TEST_CASE("Phase 1 fast path gives the null-space method's operators", "[alternating][fast]") {
  Fixture f;
  RidgeFixture r;
  const SparseMatrix<double> A = gen::selection(f.n, gen::random_subset(f.n, f.m, 51));
  ConstraintOptions o;

  SECTION("hard, full rank (ker H_zz lifted)") {
    const ConstraintSummary s = check_paths_agree(f.solver, A, o, 1e-10);
    CHECK(s.fast_path);
    CHECK(s.status == Status::Success);
  }
  SECTION("hard, full rank, positive definite H_zz") {
    CHECK(check_paths_agree(r.solver, A, o, 1e-10).fast_path);
  }
  SECTION("soft") {
    o.soft = true;
    o.delta = GENERATE(1.0, 1e3);
    CAPTURE(o.delta);
    CHECK(check_paths_agree(f.solver, A, o, 1e-10).fast_path);
    CHECK(check_paths_agree(r.solver, A, o, 1e-10).fast_path);
  }
  SECTION("very stiff soft constraints") {
    // cond(H_zz + 2δA_zᵀA_z) ≈ 1e9 here: the null-space method (a Cholesky
    // of that matrix) loses about cond·ε, the range-space path (whose Σ
    // carries 1/(2δ) on its diagonal) less. Both agree to that accuracy, and
    // the fast path is at least as close as the old one to the exact answer.
    o.soft = true;
    o.delta = 1e9;
    CHECK(check_paths_agree(f.solver, A, o, 1e-6).fast_path);
    FixedCoordinateSolver<double> fast, ref;
    fast.set_constraints(f.solver, A, o);
    o.fast_path = false;
    ref.set_constraints(f.solver, A, o);
    const ExactOperators ex = exact_soft_phase1(f.solver, A, o.delta);
    const double err_fast = rel_diff(fast.MY(), ex.MY), err_ref = rel_diff(ref.MY(), ex.MY);
    CAPTURE(err_fast, err_ref);
    CHECK(err_fast <= std::max(1e-10, 2.0 * err_ref));
    CHECK(rel_diff(fast.Mb(), ex.Mb) <= std::max(1e-10, 2.0 * rel_diff(ref.Mb(), ex.Mb)));
  }
  SECTION("no constraints") {
    const SparseMatrix<double> none(f.n, 0);
    // Singular H_zz: neither path has a unique answer; the fast one declines.
    const ConstraintSummary s = check_paths_agree(f.solver, none, o, 1e-10);
    CHECK_FALSE(s.fast_path);
    CHECK(s.status == Status::Unbounded);
    // Positive definite H_zz: z = H_zz⁻¹·G·Y, on the fast path.
    const ConstraintSummary t = check_paths_agree(r.solver, none, o, 1e-10);
    CHECK(t.fast_path);
    CHECK(t.status == Status::Success);
  }
  SECTION("dependent constraints: least squares through the null-space method") {
    std::vector<Index> rows = gen::random_subset(f.n, f.m, 52);
    rows.push_back(rows.front());  // the same row twice
    const SparseMatrix<double> Adup = gen::selection(f.n, rows);
    const ConstraintSummary s = check_paths_agree(f.solver, Adup, o, 1e-12);
    CHECK_FALSE(s.fast_path);
    CHECK(s.status == Status::ConstraintsLeastSquares);
  }
  SECTION("more constraints than the subspace has linear coordinates") {
    const SparseMatrix<double> Amany = gen::selection(f.n, gen::random_subset(f.n, f.d + 2, 53));
    const ConstraintSummary s = check_paths_agree(f.solver, Amany, o, 1e-12);
    CHECK_FALSE(s.fast_path);
    CHECK(s.status == Status::ConstraintsLeastSquares);
  }
}

TEST_CASE("Phase 1 fast path follows its solver through restore, and C0 its G_z", "[alternating][fast]") {
  Fixture f;
  const SparseMatrix<double> A = gen::selection(f.n, gen::random_subset(f.n, f.m, 61));
  ConstraintOptions slow;
  slow.fast_path = false;
  FixedCoordinateSolver<double> phase1, ref;
  REQUIRE(phase1.set_constraints(f.solver, A).fast_path);
  REQUIRE(ref.set_constraints(f.solver, A, slow).ok());
  const Index q = 7;
  Matrix<double> Gz = gen::gaussian_matrix(q, f.d, 62), Gy = gen::gaussian_matrix(q, f.k, 63);
  FusedAlternation<double> fused;
  fused.set(phase1, Gz, Gy);
  check_fused_agree(fused, phase1, ref, Gz, Gy);

  // G_z, G_y changed in place (same objects, same addresses), Phase 1 not:
  // C0 = G_z·P0 is formed again.
  Gz *= -0.5;
  Gy(0, 0) += 1.0;
  fused.set(phase1, Gz, Gy);
  check_fused_agree(fused, phase1, ref, Gz, Gy);
  // And a second handle set with unchanged G_z, G_y (C0 reused).
  const SparseMatrix<double> A2 = gen::selection(f.n, gen::random_subset(f.n, f.m - 1, 66));
  FixedCoordinateSolver<double> ref2;
  REQUIRE(phase1.set_constraints(f.solver, A2).fast_path);
  REQUIRE(ref2.set_constraints(f.solver, A2, slow).ok());
  fused.set(phase1, Gz, Gy);
  check_fused_agree(fused, phase1, ref2, Gz, Gy);

  // The same solver object, restored with another H_r (twice the energy):
  // Phase 1 must not use what it prepared from the old one.
  const Matrix<double> Hr2 = 2.0 * f.solver.reduced_hessian();
  const Matrix<double> BtD = f.solver.reduced_linear_map();
  f.solver.restore(f.solver.subspace(), Hr2, BtD);
  SubspaceSolver<double> fresh;
  fresh.restore(f.solver.subspace(), Hr2, BtD);
  FixedCoordinateSolver<double> ref3;
  REQUIRE(ref3.set_constraints(fresh, A, slow).ok());
  const ConstraintSummary s = phase1.set_constraints(f.solver, A);
  CHECK(s.fast_path);
  CHECK(rel_diff(phase1.Mb(), ref3.Mb()) <= 1e-10);
  CHECK(rel_diff(phase1.MY(), ref3.MY()) <= 1e-10);
  CHECK(rel_diff(phase1.MY(), ref.MY()) > 1e-3);  // the restore did change the answer
  fused.set(phase1, Gz, Gy);
  check_fused_agree(fused, phase1, ref3, Gz, Gy);

  // NaN in G_y is refused, also when only G_y changed.
  Gy(1, 1) = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(fused.set(phase1, Gz, Gy), Catch::Contains("G_y"));
  CHECK_FALSE(fused.ready());
}

namespace {

// Phase 1 for s.A with its energy terms, and the fused rounds on it.
void set_up_rounds(const SphereModel& s, FixedCoordinateSolver<double>* phase1, FusedAlternation<double>* fused) {
  REQUIRE(phase1->set_constraints(s.solver, s.A).ok());
  phase1->form_energy_terms(s.solver);
  fused->set_proximal_block_size(UnitBlocks::kBlock);
  fused->set(*phase1, s.Gz, s.Gy);
}

// Five plain and five accelerated rounds of `a` (on Phase 1 `pa`) and of
// `r` (on `pr`) from s.start(): the same iterates, and the same energy.
void check_rounds_agree(const SphereModel& s, FusedAlternation<double>& a, const FixedCoordinateSolver<double>& pa,
                        FusedAlternation<double>& r, const FixedCoordinateSolver<double>& pr, const Vector<double>& b) {
  UnitBlocks proj;
  AlternationSettings plain, accelerated;
  plain.iterations = 5;
  accelerated.iterations = 5;
  accelerated.anderson_window = 3;
  for (const AlternationSettings& opts : {plain, accelerated}) {
    Vector<double> z1(s.d), z2(s.d), y1 = s.start(), y2 = y1;
    const AlternationResults r1 = a.run(pa, proj, b, opts, z1, y1);
    const AlternationResults r2 = r.run(pr, proj, b, opts, z2, y2);
    CHECK((y1 - y2).norm() <= 1e-8 * std::max(1.0, y2.norm()));
    CHECK((z1 - z2).norm() <= 1e-8 * std::max(1.0, z2.norm()));
    if (opts.anderson_window > 0) CHECK(r1.energy == Approx(r2.energy).epsilon(1e-8));
  }
}

}  // namespace

TEST_CASE("constraints on y: the rounds descend on E(y) and stop at its stationary points", "[alternating][constrained_y]") {
  SphereModel s;
  FixedCoordinateSolver<double> phase1;
  FusedAlternation<double> fused;
  set_up_rounds(s, &phase1, &fused);
  REQUIRE(fused.constrained_y());
  CHECK(fused.proximal_weights().size() == s.k / UnitBlocks::kBlock);
  UnitBlocks proj;
  Vector<double> z(s.d);

  // Plain rounds, one at a time: E(y) never rises (majorise–minimise).
  AlternationSettings one;
  one.iterations = 1;
  Vector<double> y = s.start();
  double previous = s.energy(y);
  for (int round = 0; round < 60; ++round) {
    fused.run(phase1, proj, s.b, one, z, y);
    const double e = s.energy(y);
    CAPTURE(round, e, previous);
    CHECK(e <= previous + 1e-10 * std::abs(previous));
    previous = e;
  }

  // Accelerated to convergence: the reported energy is E(y), and y is a
  // stationary point of E on the spheres (central differences along each
  // block's tangent directions).
  AlternationSettings aa;
  aa.iterations = 2000;
  aa.tolerance = 1e-13;
  aa.anderson_window = 5;
  y = s.start();
  const AlternationResults sum = fused.run(phase1, proj, s.b, aa, z, y);
  CAPTURE(sum.iterations, sum.rejected, sum.last_change);
  REQUIRE(sum.last_change <= 1e-12);
  const double e_star = s.energy(y);
  CHECK(sum.energy == Approx(e_star).epsilon(1e-8));
  const double h = 1e-5;
  double slope = 0.0;
  for (Index j = 0; j < s.k / UnitBlocks::kBlock; ++j) {
    const Eigen::Vector3d yj = y.segment<3>(3 * j);
    const Eigen::Vector3d t1 = yj.unitOrthogonal(), t2 = yj.cross(t1);
    for (const Eigen::Vector3d& t : {t1, t2}) {
      Vector<double> yp = y, ym = y;
      yp.segment<3>(3 * j) = (yj + h * t).normalized();
      ym.segment<3>(3 * j) = (yj - h * t).normalized();
      slope = std::max(slope, std::abs(s.energy(yp) - s.energy(ym)) / (2 * h));
    }
  }
  CAPTURE(e_star, slope);
  CHECK(slope <= 1e-6 * (1.0 + std::abs(e_star)));

  // The rounds without the energy terms (the input the paper's Phase 2
  // sees) stop elsewhere: a point with a clear slope and no lower energy.
  FixedCoordinateSolver<double> uncorrected;
  REQUIRE(uncorrected.set_constraints(s.solver, s.A).ok());
  FusedAlternation<double> old;
  old.set(uncorrected, s.Gz, s.Gy);
  CHECK_FALSE(old.constrained_y());
  AlternationSettings plain;
  plain.iterations = 2000;
  Vector<double> y_old = s.start();
  old.run(uncorrected, proj, s.b, plain, z, y_old);
  CHECK(s.energy(y_old) >= e_star - 1e-9 * std::abs(e_star));
  CHECK((y_old - y).norm() > 1e-4);
}

TEST_CASE("accelerated rounds report E(y) whichever form its constraint term takes", "[alternating][anderson]") {
  // Constraints at proxies: A_y = AᵀUD vanishes (to round-off: the rounds
  // are corrected then, or not when it is exactly zero) and the energy's
  // constraint term is affine in y; at vertices away from them it is not,
  // and without the energy-term correction the term is the full product.
  SphereModel s;
  const bool at_proxies = GENERATE(true, false);
  CAPTURE(at_proxies);
  if (at_proxies) s.A = gen::selection(s.n, std::vector<Index>(s.proxies.begin(), s.proxies.begin() + s.m));
  FixedCoordinateSolver<double> phase1;
  FusedAlternation<double> fused;
  set_up_rounds(s, &phase1, &fused);
  UnitBlocks proj;
  Vector<double> z(s.d);
  AlternationSettings aa;
  aa.anderson_window = 5;
  for (const int rounds : {1, 3, 40}) {
    aa.iterations = rounds;
    Vector<double> y = s.start();
    const AlternationResults sum = fused.run(phase1, proj, s.b, aa, z, y);
    CAPTURE(rounds, sum.iterations, sum.rejected);
    // The energy of the last accepted iterate, whose plain step y is: no
    // higher than E at y itself (the plain step is majorise–minimise).
    CHECK(std::isfinite(sum.energy));
    CHECK(s.energy(y) <= sum.energy + 1e-9 * std::abs(sum.energy));
  }
  aa.iterations = 3000;
  aa.tolerance = 1e-13;
  Vector<double> y = s.start();
  const AlternationResults sum = fused.run(phase1, proj, s.b, aa, z, y);
  CAPTURE(sum.iterations, sum.rejected, sum.last_change);
  REQUIRE(sum.last_change <= 1e-12);
  CHECK(sum.energy == Approx(s.energy(y)).epsilon(1e-8));
}

TEST_CASE("constraints on y: the fast path's multipliers and curvature test give the null-space rounds",
          "[alternating][constrained_y][fast]") {
  // On the fast path the multipliers come from Σ⁻¹ (λ = K·(R·y − [b; 0])),
  // the correction is folded into the rank-μ factor (F_y′ = F₀ − U·R) and
  // the weights are zero whenever the curvature test finds λ_max(Q) ≤ ε;
  // the null-space method forms Λ from a pseudo-inverse and asks Lanczos.
  // Both must give the same weights and rounds, hard or soft, on sets that
  // need weights and on sets that do not: this model's sets all need them
  // (F₀ is indefinite), so half the sets run with G_y + c·I, c = ‖G_y‖_F
  // (Q − c·I: F₀ + c·I positive definite, and Q ⪯ 0 on some sets).
  SphereModel s;
  ConstraintOptions o;
  o.soft = GENERATE(false, true);
  o.delta = 10.0;
  CAPTURE(o.soft);
  int stiff = 0, free = 0;
  for (std::uint64_t seed = 60; seed < 76; ++seed) {
    const Matrix<double> Gy =
        seed % 2 == 0 ? s.Gy : Matrix<double>(s.Gy + s.Gy.norm() * Matrix<double>::Identity(s.k, s.k));
    const Index m = 2 + static_cast<Index>(seed % 5);
    std::vector<Index> rows;
    for (Index v : gen::random_subset(s.n, 3 * m, seed))
      if (std::find(s.proxies.begin(), s.proxies.end(), v) == s.proxies.end() && static_cast<Index>(rows.size()) < m)
        rows.push_back(v);
    const SparseMatrix<double> A = gen::selection(s.n, rows);
    const Vector<double> b = 3.0 * gen::gaussian_vector(m, seed + 100);
    CAPTURE(seed, m);
    FixedCoordinateSolver<double> fast, ref;
    o.fast_path = true;
    const ConstraintSummary fs = fast.set_constraints(s.solver, A, o);
    REQUIRE(fs.fast_path);
    o.fast_path = false;
    REQUIRE(ref.set_constraints(s.solver, A, o).ok());
    fast.form_energy_terms(s.solver);
    ref.form_energy_terms(s.solver);
    FusedAlternation<double> f_fast, f_ref;
    f_fast.set_proximal_block_size(UnitBlocks::kBlock);
    f_ref.set_proximal_block_size(UnitBlocks::kBlock);
    f_fast.set(fast, s.Gz, Gy, 1, FusedForm::Explicit);
    f_ref.set(ref, s.Gz, Gy);
    REQUIRE(f_fast.constrained_y());
    REQUIRE(f_ref.constrained_y());
    const Vector<double>&w_fast = f_fast.proximal_weights(), &w_ref = f_ref.proximal_weights();
    CHECK((w_fast - w_ref).norm() <= 1e-8 * (1.0 + w_ref.norm()));
    (w_ref.maxCoeff() > 0.0 ? stiff : free) += 1;
    // The factored form decides the same (its weight, where there is one,
    // is the scalar λ_max(Q), not the block bound).
    FusedAlternation<double> f_factored;
    f_factored.set_proximal_block_size(UnitBlocks::kBlock);
    f_factored.set(fast, s.Gz, Gy, 1, FusedForm::Factored);
    CHECK((f_factored.proximal_weights().maxCoeff() > 0.0) == (w_ref.maxCoeff() > 0.0));

    check_rounds_agree(s, f_fast, fast, f_ref, ref, b);
  }
  CAPTURE(stiff, free);
  CHECK(stiff > 0);
  CHECK(free > 0);
}

TEST_CASE("Phase 1 eliminates a selection of z, with the null-space method's operators, multipliers and rounds",
          "[alternating][elimination]") {
  // Rows of A_z that each pick one linear coordinate (a handle on a proxy
  // itself) are met by eliminating those coordinates when that costs less
  // than the range-space path (6 or 8 of 9 here; 2 of 9 keep the fast path).
  // Operators, multipliers (with A_y ≠ 0) and rounds must be the null-space
  // method's; the selected coordinates come out exact.
  SphereModel s;
  const Index m = GENERATE(2, 6, 8);
  CAPTURE(m);
  const std::vector<Index> cols = gen::random_subset(s.d, m, 80 + static_cast<std::uint64_t>(m));
  Matrix<double> Az = Matrix<double>::Zero(m, s.d);
  for (Index i = 0; i < m; ++i) Az(i, cols[static_cast<size_t>(i)]) = (i % 2 ? -1.0 : 1.0) * (0.5 + 0.25 * i);
  const Matrix<double> Ay = gen::gaussian_matrix(m, s.k, 90);
  ConstraintOptions o;
  FixedCoordinateSolver<double> el, ref;
  el.prepare(s.solver);  // as the deformer does at precompute: the fast path's part is then free
  const ConstraintSummary es = el.set_reduced_constraints(s.solver, Az, Ay, o);
  o.fast_path = false;
  const ConstraintSummary rs = ref.set_reduced_constraints(s.solver, Az, Ay, o);
  INFO(es.message << " | " << rs.message);
  REQUIRE(es.status == Status::Success);
  REQUIRE(rs.status == Status::Success);
  CHECK(es.rank == m);
  const bool eliminated = es.message.find("eliminated") != std::string::npos;
  CHECK(eliminated == (m > 2));
  CHECK(es.fast_path == !eliminated);
  CHECK(rel_diff(el.Mb(), ref.Mb()) <= 1e-10);
  CHECK(rel_diff(el.MY(), ref.MY()) <= 1e-10);
  // z = M_b·b + M_Y·y meets A_z·z = b − A_y·y.
  const Vector<double> b = gen::gaussian_vector(m, 91), y = gen::gaussian_vector(s.k, 92);
  Vector<double> z(s.d);
  el.solve(b, y, z);
  CHECK((Az * z + Ay * y - b).norm() <= 1e-12 * (1.0 + b.norm()));

  el.form_energy_terms(s.solver);
  ref.form_energy_terms(s.solver);
  FusedAlternation<double> f_el, f_ref;
  f_el.set_proximal_block_size(UnitBlocks::kBlock);
  f_ref.set_proximal_block_size(UnitBlocks::kBlock);
  f_el.set(el, s.Gz, s.Gy);
  f_ref.set(ref, s.Gz, s.Gy);
  REQUIRE(f_el.constrained_y());
  CHECK((f_el.proximal_weights() - f_ref.proximal_weights()).norm() <= 1e-8 * (1.0 + f_ref.proximal_weights().norm()));
  check_rounds_agree(s, f_el, el, f_ref, ref, b);
}

TEST_CASE("constraints on y: misuse is refused with the words", "[alternating][constrained_y][errors]") {
  SphereModel s;
  FixedCoordinateSolver<double> phase1;
  REQUIRE(phase1.set_constraints(s.solver, s.A).ok());
  FusedAlternation<double> fused;
  fused.set(phase1, s.Gz, s.Gy);
  phase1.form_energy_terms(s.solver);  // after set: the rounds did not see them
  UnitBlocks proj;
  Vector<double> z(s.d), y = s.start();
  CHECK_THROWS_WITH(fused.run(phase1, proj, s.b, AlternationSettings{}, z, y), Catch::Contains("energy terms changed"));
  fused.set(phase1, s.Gz, s.Gy);  // blocks of 0 (one weight) for a projection with blocks of 3
  CHECK_THROWS_WITH(fused.run(phase1, proj, s.b, AlternationSettings{}, z, y), Catch::Contains("proximal blocks"));
  CHECK_THROWS_WITH(fused.set_proximal_block_size(-1), Catch::Contains("block size"));
}

namespace {
// A clock that advances one second at each reading (AlternationSettings::clock).
double fake_seconds = 0.0;
double fake_clock() { return fake_seconds += 1.0; }
}  // namespace

TEST_CASE("the time budget ends the rounds of every loop after the round that spends it", "[alternating][budget]") {
  // The budget's clock is read once at the start and once after each round:
  // with one second a reading and a budget of 3.5 s the rounds stop after
  // the fourth, at the iterates of four rounds without a budget.
  const Index n = 14 * 11, d = 9, k = 12, m = 5;
  const SparseMatrix<double> H = gen::grid_laplacian_2d(14, 11);
  SubspaceSolver<double> solver;
  REQUIRE(solver.precompute(H, gen::selection(n, gen::random_subset(n, d, 5)), gen::gaussian_sparse(n, k, 6)).ok());
  FixedCoordinateSolver<double> phase1;
  REQUIRE(phase1.set_constraints(solver, gen::selection(n, gen::random_subset(n, m, 71))).ok());
  const Matrix<double> Gz = 0.3 * gen::gaussian_matrix(k, d, 72), Gy = gen::gaussian_matrix(k, k, 73);
  const Vector<double> b = gen::gaussian_vector(m, 74), y0 = gen::gaussian_vector(k, 75);
  FusedAlternation<double> fused;
  fused.set(phase1, Gz, Gy);
  BallBlocks proj;
  for (int threads : {1, 2}) {
    INFO("threads " << threads);
    AlternationSettings o;
    o.threads = threads;
    o.parallel_min_entries = 0;
    o.iterations = 4;
    Vector<double> z(d), y4 = y0, y = y0;
    const AlternationResults four = fused.run(phase1, proj, b, o, z, y4);
    CHECK(four.stop == RoundStop::RoundLimit);
    o.iterations = 1000;
    o.time_budget = 3.5;
    o.clock = fake_clock;
    const AlternationResults s = fused.run(phase1, proj, b, o, z, y);
    CHECK(s.iterations == 4);
    CHECK(s.stop == RoundStop::TimeBudget);
    CHECK(std::string(to_string(s.stop)) == "time budget");
    CHECK((y - y4).norm() <= 1e-12 * (1 + y4.norm()));
    // The tolerance, when met first, ends them: the same rounds as without
    // a budget (scaled so that the rounds contract).
    FusedAlternation<double> contracting;
    contracting.set(phase1, 0.05 * Gz, 0.05 * Gy);
    o.time_budget = 1e9;
    o.tolerance = 1e-9;
    Vector<double> yt = y0, yn = y0;
    const AlternationResults t = contracting.run(phase1, proj, b, o, z, yt);
    o.time_budget = 0.0;
    const AlternationResults u = contracting.run(phase1, proj, b, o, z, yn);
    CHECK(t.iterations < 1000);
    CHECK(t.stop == RoundStop::Tolerance);
    CHECK(t.iterations == u.iterations);
    CHECK(yt == yn);
  }

  // Accelerated rounds (Anderson with the energy safeguard) on the spheres.
  SphereModel s;
  FixedCoordinateSolver<double> p1;
  FusedAlternation<double> rounds;
  set_up_rounds(s, &p1, &rounds);
  UnitBlocks unit;
  AlternationSettings aa;
  aa.anderson_window = 5;
  aa.iterations = 4;
  Vector<double> z(s.d), y4 = s.start(), y = s.start();
  rounds.run(p1, unit, s.b, aa, z, y4);
  aa.iterations = 1000;
  aa.time_budget = 3.5;
  aa.clock = fake_clock;
  const AlternationResults a = rounds.run(p1, unit, s.b, aa, z, y);
  CHECK(a.iterations == 4);
  CHECK(a.stop == RoundStop::TimeBudget);
  CHECK((y - y4).norm() <= 1e-12);

  // Options: a budget must be finite and ≥ 0.
  std::string why;
  aa.time_budget = -1.0;
  CHECK_FALSE(aa.is_valid(&why));
  CHECK_THAT(why, Catch::Contains("time_budget"));
  aa.time_budget = std::numeric_limits<double>::infinity();
  CHECK_FALSE(aa.is_valid(&why));
}
