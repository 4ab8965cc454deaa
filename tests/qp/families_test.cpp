// The three QP families of issue 7 (families.h): in-design demands are
// reproduced exactly, Theorem 4.10 bounds every generated off-design demand,
// and the cached-Cholesky + Schur baseline agrees with the full solve.
#include <qpreduce/families.h>
#include <qpreduce/full_solve.h>
#include <qpreduce/quotient.h>
#include <qpreduce/schur_baseline.h>
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
  SubspaceSolver<double> solver;
  REQUIRE(solver.precompute(fam.H, fam.C, fam.D, families::recommended_options(fam)).ok());
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
