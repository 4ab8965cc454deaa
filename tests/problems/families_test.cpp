// The three QP families (families.h): in-design demands are
// reproduced exactly, Theorem 4.10 bounds every generated off-design demand,
// and the cached-Cholesky + Schur baseline agrees with the full solve.
#include <qpreduce/problems/families.h>
#include <qpreduce/full_solve.h>
#include <qpreduce/theorem.h>
#include <qpreduce/problems/schur_baseline.h>
#include <qpreduce/subspace_solver.h>

#include <catch2/catch.hpp>

#include <cmath>
#include <limits>

using namespace qpreduce;
using families::Family;

namespace {

// Small instances (the Theorem 4.10 analysis is dense).
families::QpFamily small_family(Family f, std::uint64_t seed) {
  switch (f) {
    case Family::Gmrf: {
      families::GmrfOptions o;
      o.nx = 18, o.ny = 16, o.candidates = 40, o.observed = 12, o.seed = seed;
      return families::make_gmrf(o);
    }
    case Family::Trajectory: {
      families::TrajectoryOptions o;
      o.samples = 150, o.stations = 20, o.waypoints = 6, o.modes = 3, o.seed = seed;
      return families::make_trajectory(o);
    }
    case Family::Portfolio: {
      families::PortfolioOptions o;
      o.assets = 240, o.factors = 5, o.sectors = 8, o.neutral = 3, o.seed = seed;
      return families::make_portfolio(o);
    }
  }
  throw std::logic_error("family");
}

// Whether every column of C has one nonzero (a selection of unknowns, as the
// GMRF's candidate sites): the build then sets CᵀN = I and CᵀUD = 0 exactly
// on those rows (subspace_build.cpp), so in-design rows of A_r carry no
// round-off to drop.
bool selects_unknowns(const SparseMatrix<double>& C) {
  for (Index j = 0; j < C.cols(); ++j)
    if (C.col(j).nonZeros() != 1) return false;
  return true;
}

// A solver precomputed on the family with its recommended options.
SubspaceSolver<double> precomputed_solver(const families::QpFamily& fam) {
  SubspaceSolver<double> solver;
  const SubspaceSummary s = solver.precompute(fam.H, fam.C, fam.D, families::recommended_options(fam));
  INFO(s.brief_report());
  REQUIRE(s.ok());
  return solver;
}

Vector<double> reduced_answer(SubspaceSolver<double>& solver, const families::QpDemand& dem, bool in_D) {
  const ConstraintSummary cs = solver.set_constraints(dem.A);
  REQUIRE(cs.status == Status::Success);
  Vector<double> w(solver.p()), X(solver.n());
  if (in_D) {
    solver.solve_in_D(dem.b, dem.Y, w);
  } else {
    Vector<double> qr(solver.p());
    solver.reduce_linear_term(dem.q, qr);
    solver.solve(dem.b, qr, w);
  }
  solver.reconstruct(w, X);
  return X;
}

}  // namespace

TEST_CASE("QP families: in-design demands are reproduced exactly", "[qp][families]") {
  const Family f = GENERATE(Family::Gmrf, Family::Trajectory, Family::Portfolio);
  const std::uint64_t seed = GENERATE(1u, 7u);
  INFO(families::to_string(f) << " seed " << seed);
  const families::QpFamily fam = families::make_family(f, 3000, seed);
  SubspaceSolver<double> solver;
  const SubspaceOptions options = families::recommended_options(fam);
  const SubspaceSummary s = solver.precompute(fam.H, fam.C, fam.D, options);
  REQUIRE(s.ok());
  for (std::uint64_t i = 0; i < 4; ++i) {
    const families::QpDemand dem = families::make_demand(fam, i);
    REQUIRE(dem.in_design);
    REQUIRE(dem.A.rows() == fam.n());
    REQUIRE((fam.D * dem.Y - dem.q).norm() <= 1e-14 * (1.0 + dem.q.norm()));
    Vector<double> X_full;
    const FullSolveSummary fs = solve_full(fam.H, dem.A, dem.b, dem.q, &X_full, options);
    REQUIRE(fs.ok());
    for (bool in_D : {true, false}) {
      const Vector<double> X = reduced_answer(solver, dem, in_D);
      CHECK((X - X_full).norm() <= 1e-10 * X_full.norm());
      CHECK((dem.A.transpose() * X - dem.b).norm() <= 1e-10 * (1.0 + dem.b.norm()));
    }
    // Constraints given in design coordinates: A = C·A_c exactly, same answer.
    REQUIRE(dem.A_c.rows() == fam.d());
    CHECK((Matrix<double>(fam.C * dem.A_c) - Matrix<double>(dem.A)).norm() == 0.0);
    REQUIRE(solver.set_constraints_in_design(dem.A_c).status == Status::Success);
    Vector<double> w(solver.p()), X(fam.n());
    solver.solve_in_D(dem.b, dem.Y, w);
    solver.reconstruct(w, X);
    CHECK((X - X_full).norm() <= 1e-10 * X_full.norm());
  }
}

TEST_CASE("QP families: factored and explicit operators agree on every generated demand", "[qp][families][factored]") {
  const Family f = GENERATE(Family::Gmrf, Family::Trajectory, Family::Portfolio);
  const bool soft = GENERATE(false, true);
  INFO(families::to_string(f) << (soft ? " soft" : " hard"));
  const families::QpFamily fam = families::make_family(f, 3000, 3);
  SubspaceSolver<double> solver = precomputed_solver(fam);
  const Index p = solver.p();
  for (std::uint64_t i = 0; i < 6; ++i) {
    const families::QpDemand dem = families::make_demand(fam, i);
    Vector<double> q_r(p);
    solver.reduce_linear_term(dem.q + 0.1 * Vector<double>::Ones(fam.n()), q_r);  // q ∉ Span(D) too
    Vector<double> w[2], wY[2];
    for (int explicit_ops = 0; explicit_ops < 2; ++explicit_ops) {
      ConstraintOptions o;
      o.soft = soft;
      o.explicit_operators = explicit_ops == 1;
      const ConstraintSummary cs = solver.set_constraints_in_design(dem.A_c, o);
      INFO(cs.message);
      REQUIRE(cs.status == Status::Success);
      CHECK(cs.fast_path);
      CHECK(cs.factored == (explicit_ops == 0));  // A_c: a selection or a few sums
      w[explicit_ops].resize(p);
      wY[explicit_ops].resize(p);
      solver.solve(dem.b, q_r, w[explicit_ops]);
      solver.solve_in_D(dem.b, dem.Y, wY[explicit_ops]);
    }
    CHECK((w[0] - w[1]).norm() <= 1e-10 * w[1].norm());
    CHECK((wY[0] - wY[1]).norm() <= 1e-10 * wY[1].norm());
  }
}

TEST_CASE("QP families: in-design demands passed as a sparse A take the factored path", "[qp][families][drop]") {
  // A_r = AᵀB equals [A_cᵀ 0] only to round-off (CᵀN = I, CᵀUD = 0 hold to the
  // build's residual); drop_tolerance zeroes that round-off (subspace_solver.h).
  const Family f = GENERATE(Family::Gmrf, Family::Trajectory, Family::Portfolio);
  const bool soft = GENERATE(false, true);
  INFO(families::to_string(f) << (soft ? " soft" : " hard"));
  const families::QpFamily fam = families::make_family(f, 3000, 3);
  SubspaceSolver<double> solver = precomputed_solver(fam);
  const Index p = solver.p(), d = solver.d();
  for (std::uint64_t i = 0; i < 4; ++i) {
    const families::QpDemand dem = families::make_demand(fam, i);
    Vector<double> q_r(p);
    solver.reduce_linear_term(dem.q + 0.1 * Vector<double>::Ones(fam.n()), q_r);  // q ∉ Span(D) too
    ConstraintOptions o;
    o.soft = soft;
    // Reference: the same constraints in design coordinates.
    const ConstraintSummary ref = solver.set_constraints_in_design(dem.A_c, o);
    REQUIRE(ref.status == Status::Success);
    REQUIRE(ref.factored);
    CHECK(ref.dropped == 0);
    Vector<double> w_ref(p), wY_ref(p);
    solver.solve(dem.b, q_r, w_ref);
    solver.solve_in_D(dem.b, dem.Y, wY_ref);
    Index nnz_kept = 0;  // nonzeros of A_r with every entry kept
    for (const double tau : {0.0, ConstraintOptions{}.drop_tolerance}) {
      INFO("drop_tolerance " << tau);
      o.drop_tolerance = tau;
      const ConstraintSummary cs = solver.set_constraints(dem.A, o);
      INFO(cs.message);
      REQUIRE(cs.status == Status::Success);
      CHECK(cs.fast_path);
      CHECK(cs.rank == ref.rank);
      const Matrix<double>& Ar = solver.reduced_constraints();
      const Index nnz = (Ar.array() != 0.0).count(), nnz_design = (dem.A_c.array() != 0.0).count();
      if (tau > 0.0) {
        // Exactly the pattern of [A_cᵀ 0], and the factored path as for A_c.
        CHECK(cs.factored);
        CHECK(nnz == nnz_design);
        CHECK(cs.dropped == nnz_kept - nnz_design);
        CHECK(((Ar.leftCols(d).array() != 0.0) == (dem.A_c.transpose().array() != 0.0)).all());
        CHECK(Ar.rightCols(p - d).isZero(0.0));
      } else if (selects_unknowns(fam.C)) {
        // Every entry kept, and nothing to keep beyond [A_cᵀ 0]: the build
        // made those rows exact.
        CHECK(cs.dropped == 0);
        CHECK(cs.factored);
        CHECK(nnz == nnz_design);
        CHECK(Ar.rightCols(p - d).isZero(0.0));
        nnz_kept = nnz;
      } else {
        // The old behaviour: every entry kept, A_r dense to round-off.
        CHECK(cs.dropped == 0);
        CHECK_FALSE(cs.factored);
        CHECK(nnz > nnz_design);
        nnz_kept = nnz;
      }
      Vector<double> w(p), wY(p);
      solver.solve(dem.b, q_r, w);
      solver.solve_in_D(dem.b, dem.Y, wY);
      CHECK((w - w_ref).norm() <= 1e-10 * w_ref.norm());
      CHECK((wY - wY_ref).norm() <= 1e-10 * wY_ref.norm());
    }
  }
}

TEST_CASE("QP families: generators are deterministic and validate their options", "[qp][families]") {
  const Family f = GENERATE(Family::Gmrf, Family::Trajectory, Family::Portfolio);
  const families::QpFamily a = families::make_family(f, 500, 3), b = families::make_family(f, 500, 3);
  CHECK((a.H - b.H).norm() == 0.0);
  CHECK((a.C - b.C).norm() == 0.0);
  const families::QpDemand da = families::make_demand(a, 5, {2, 0.1}), db = families::make_demand(b, 5, {2, 0.1});
  CHECK((da.A - db.A).norm() == 0.0);
  CHECK(da.b == db.b);
  CHECK(da.q == db.q);
  CHECK_FALSE(da.in_design);
  CHECK(da.A_c.size() == 0);
  CHECK_THROWS_AS(SubspaceSolver<double>().set_constraints_in_design(Matrix<double>::Identity(2, 1)),
                  std::invalid_argument);
  const families::QpDemand other = families::make_demand(a, 6);
  CHECK(((other.A - families::make_demand(a, 5).A).norm() > 0.0 || other.b != da.b));
  // H symmetric, and the stated kernel is in ker H.
  CHECK((a.H - SparseMatrix<double>(a.H.transpose())).norm() == 0.0);
  if (a.kernel.cols() > 0) CHECK((a.H * a.kernel).norm() <= 1e-12 * a.H.norm());

  families::GmrfOptions g;
  g.observed = g.candidates + 1;
  CHECK_THROWS_AS(families::make_gmrf(g), std::invalid_argument);
  families::TrajectoryOptions t;
  t.lambda = 0.0;
  CHECK_THROWS_AS(families::make_trajectory(t), std::invalid_argument);
  families::PortfolioOptions p;
  p.neutral = p.sectors;
  CHECK_THROWS_AS(families::make_portfolio(p), std::invalid_argument);
  CHECK_THROWS_AS(families::make_demand(a, 0, {-1, 0.0}), std::invalid_argument);
  CHECK_THROWS_AS(families::parse_family("kriging"), std::invalid_argument);
  CHECK(families::parse_family("portfolio") == Family::Portfolio);
}

TEST_CASE("QP families: the gmrf rows made alone are those of the whole family", "[qp][families][rows]") {
  families::GmrfOptions g;
  g.nx = 23;
  g.ny = 17;
  g.ridge = GENERATE(0.0, 0.25);
  const families::QpFamily whole = families::make_gmrf(g);
  const Index n = whole.n();
  // Three blocks tiling the rows, one of them empty, as ranks would own them.
  for (const auto& [first, end] : {std::pair<Index, Index>{0, 150}, {150, 150}, {150, n}}) {
    const families::GmrfRows rows = families::make_gmrf_rows(g, first, end);
    REQUIRE(rows.H.rows() == end - first);
    REQUIRE(rows.H.cols() == n);
    CHECK((rows.H - SparseMatrix<double>(whole.H.middleRows(first, end - first))).norm() == 0.0);
    CHECK((rows.D - SparseMatrix<double>(whole.D.middleRows(first, end - first))).norm() == 0.0);
  }
  CHECK((families::make_gmrf_design(g) - whole.C).norm() == 0.0);
  CHECK_THROWS_WITH(families::make_gmrf_rows(g, 10, n + 1), Catch::Contains("outside [0, 391)"));
  CHECK_THROWS_WITH(families::make_gmrf_rows(g, 10, 9), Catch::Contains("outside"));
  g.candidates = 0;
  CHECK_THROWS_AS(families::make_gmrf_rows(g, 0, 1), std::invalid_argument);
}

TEST_CASE("QP families: the Theorem 4.10 bound holds on every generated demand", "[qp][families][theorem]") {
  const Family f = GENERATE(Family::Gmrf, Family::Trajectory, Family::Portfolio);
  INFO(families::to_string(f));
  const families::QpFamily fam = small_family(f, 5);
  REQUIRE(fam.n() <= 400);
  TheoremChecker checker;
  const TheoremSetupSummary setup = checker.precompute(fam.H, fam.C, fam.D);
  REQUIRE(setup.ok());
  // ker H (constants, for the grid) lies in the design: the bound covers X*.
  REQUIRE(checker.design().kernel_in_design());
  int applies = 0, trials = 0;
  for (Index outside : {0, 1, 3})
    for (double q_noise : {0.0, 1e-3, 0.1})
      for (std::uint64_t i = 0; i < 3; ++i) {
        const families::QpDemand dem = families::make_demand(fam, 100 + i, {outside, q_noise});
        const TheoremCheck c = checker.check(dem.A, dem.b, dem.q);
        INFO("outside " << outside << " q_noise " << q_noise << " demand " << i << ": " << c.message);
        REQUIRE((c.status == TheoremStatus::Applies || c.status == TheoremStatus::DoesNotApply));
        CHECK(c.practical_covered);
        CHECK_FALSE(c.practical_violation());
        CHECK_FALSE(c.theorem_violation());
        if (c.bound.applies()) {
          ++applies;
          CHECK(c.practical_error <= c.bound.bound + c.slack);
        }
        if (dem.in_design) CHECK(c.practical_error <= c.slack);
        ++trials;
      }
  // The bound is not vacuous: it applies to the in-design and mildly perturbed demands at least.
  CHECK(applies >= 3);
  CHECK(trials == 27);
}

TEST_CASE("QP families: off-design demands stay within the Theorem 4.10 bound with and without dropping",
          "[qp][families][theorem][drop]") {
  const Family f = GENERATE(Family::Gmrf, Family::Trajectory, Family::Portfolio);
  INFO(families::to_string(f));
  const families::QpFamily fam = small_family(f, 5);
  // The engine's answer X* with the default drop_tolerance and with none.
  TheoremChecker checker[2];
  QuotientOptions keep_all;
  keep_all.constraints.drop_tolerance = 0.0;
  REQUIRE(checker[0].precompute(fam.H, fam.C, fam.D).ok());
  REQUIRE(checker[1].precompute(fam.H, fam.C, fam.D, keep_all).ok());
  int applies = 0;
  for (Index outside : {1, 3})
    for (std::uint64_t i = 0; i < 3; ++i) {
      const families::QpDemand dem = families::make_demand(fam, 200 + i, {outside, 1e-3});
      REQUIRE_FALSE(dem.in_design);
      TheoremSolutions sol[2];
      TheoremCheck c[2];
      for (int j = 0; j < 2; ++j) {
        c[j] = checker[j].check(dem.A, dem.b, dem.q, &sol[j]);
        INFO("outside " << outside << " demand " << i << " drop " << (j == 0) << ": " << c[j].message);
        REQUIRE((c[j].status == TheoremStatus::Applies || c[j].status == TheoremStatus::DoesNotApply));
        CHECK_FALSE(c[j].practical_violation());
        if (c[j].bound.applies()) CHECK(c[j].practical_error <= c[j].bound.bound + c[j].slack);
      }
      applies += c[0].bound.applies();
      // Something was dropped: the in-design rows' round-off at least, unless
      // the build made those rows exact (C a selection: nothing to drop there).
      const auto zeros = [](const TheoremChecker& tc) {
        return (tc.solver().reduced_constraints().array() == 0.0).count();
      };
      if (selects_unknowns(fam.C)) {
        CHECK(zeros(checker[0]) >= zeros(checker[1]));
      } else {
        CHECK(zeros(checker[0]) > zeros(checker[1]));
      }
      // Only entries with cosine ≤ drop_tolerance go: the answers agree to within the change of A_r.
      CHECK(c[0].bound.applies() == c[1].bound.applies());
      CHECK((sol[0].X_star - sol[1].X_star).norm() <= 1e-8 * sol[1].X_star.norm());
    }
  CHECK(applies >= 1);
}

TEST_CASE("Cached Cholesky + Schur baseline equals the full solve", "[qp][baseline]") {
  const Family f = GENERATE(Family::Gmrf, Family::Trajectory, Family::Portfolio);
  INFO(families::to_string(f));
  const families::QpFamily fam = families::make_family(f, 2000, 2);
  // Bordered (one pinned site) when H is singular.
  CachedCholeskySchur base;
  REQUIRE(base.precompute(fam.H, families::baseline_bordering(fam)).ok());
  for (std::uint64_t i = 0; i < 3; ++i) {
    const families::QpDemand dem = families::make_demand(fam, i, {static_cast<Index>(i), 0.0});
    Vector<double> X, X_full;
    REQUIRE(solve_full(fam.H, dem.A, dem.b, dem.q, &X_full).ok());
    REQUIRE(base.solve(dem.A, dem.b, dem.q, &X).ok());
    CHECK((X - X_full).norm() <= 1e-10 * X_full.norm());
  }
  if (fam.kernel.cols() > 0) {
    // Without the bordering, a singular H cannot be factored: a status, not a crash.
    CachedCholeskySchur plain;
    CHECK(plain.precompute(fam.H, SparseMatrix<double>(fam.n(), 0)).status == Status::SingularKKT);
  }
  Vector<double> X;
  CHECK_THROWS_AS(base.solve(SparseMatrix<double>(fam.n() + 1, 1), Vector<double>::Zero(1),
                             Vector<double>::Zero(fam.n()), &X),
                  std::invalid_argument);
}

TEST_CASE("Subspace without augmentation (H PD) equals the augmented build", "[qp][families]") {
  const families::QpFamily traj = families::make_family(Family::Trajectory, 1200, 9);
  REQUIRE(traj.positive_definite());
  SubspaceOptions plain;
  plain.augment = false;
  VariationalSubspace<double> a, b;
  const SubspaceSummary sa = build_subspace(traj.H, traj.C, traj.D, plain, &a);
  const SubspaceSummary sb = build_subspace(traj.H, traj.C, traj.D, SubspaceOptions{}, &b);
  REQUIRE(sa.ok());
  REQUIRE(sb.ok());
  CHECK(sa.rho == 0.0);
  CHECK(sb.rho > 0.0);
  CHECK((a.N - b.N).norm() <= 1e-9 * b.N.norm());
  CHECK((a.UD - b.UD).norm() <= 1e-9 * b.UD.norm());
  // A singular H cannot be factored without augmentation: a status, no output.
  const families::QpFamily gmrf = families::make_family(Family::Gmrf, 400, 9);
  REQUIRE_FALSE(gmrf.positive_definite());
  CHECK(families::recommended_options(gmrf).augment);
  VariationalSubspace<double> c;
  const SubspaceSummary sc = build_subspace(gmrf.H, gmrf.C, gmrf.D, plain, &c);
  CHECK_FALSE(sc.ok());
  CHECK(c.N.size() == 0);
}
