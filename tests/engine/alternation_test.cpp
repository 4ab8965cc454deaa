// The engine's public Alternation (alternation.h): one setup per constraint
// set, then solve; checked against its private parts driven by hand in the
// order they need, against a dense Phase 1 with right-hand sides that follow
// y, and for its refusals.
#include <catch2/catch.hpp>

#include "alternation_fixtures.h"
#include "alternation_parts.h"

#include <Eigen/Dense>

#include <limits>

using namespace qpreduce;
using namespace qpreduce::testing_alternation;

namespace {

// A plain projection with no energy terms: y ← g scaled into the unit ball.
struct Ball : InputProjection<double> {
  double project(const Eigen::Ref<const Vector<double>>& g, Eigen::Ref<Vector<double>> y) override {
    const Vector<double> old = y;
    y = g / std::max(1.0, g.norm());
    return (y - old).norm();
  }
};

}  // namespace

TEST_CASE("Alternation: one setup gives the iterates of its parts set by hand, for every strategy",
          "[alternation]") {
  SphereModel s;
  const bool fast_path = GENERATE(true, false);
  CAPTURE(fast_path);
  AlternationSetup setup;
  setup.constraints.fast_path = fast_path;
  // The parts in the order Alternation::setup keeps for them.
  FixedCoordinateSolver<double> phase1;
  REQUIRE(phase1.set_constraints(s.solver, s.A, setup.constraints).ok());
  phase1.form_energy_terms(s.solver);
  FusedAlternation<double> fused;
  fused.set_proximal_block_size(UnitBlocks::kBlock);
  fused.set(phase1, s.Gz, s.Gy);

  UnitBlocks proj;
  Alternation<double> alt;
  const ConstraintSummary cs = alt.setup(s.solver, s.A, s.Gz, s.Gy, proj, setup);
  REQUIRE(cs.ok());
  REQUIRE(alt.ready());
  CHECK(alt.energy_terms());
  CHECK(alt.constrained_y() == fused.constrained_y());
  CHECK(alt.proximal_weights() == fused.proximal_weights());
  CHECK(alt.Mb() == phase1.Mb());

  AlternationSettings plain, accelerated, to_tolerance;
  plain.iterations = 7;
  accelerated.iterations = 7;
  accelerated.anderson_window = 3;
  to_tolerance.iterations = 400;
  to_tolerance.tolerance = 1e-10;
  to_tolerance.second_order = false;
  for (const AlternationSettings& settings : {plain, accelerated, to_tolerance}) {
    Vector<double> z1(s.d), z2(s.d), y1 = s.start(), y2 = y1;
    const AlternationResults r1 = fused.run(phase1, proj, s.b, settings, z1, y1);
    const AlternationResults r2 = alt.solve(proj, s.b, settings, z2, y2);
    CAPTURE(settings.anderson_window, settings.tolerance, r1.iterations);
    CHECK(r1.iterations == r2.iterations);
    CHECK(r1.stop == r2.stop);
    CHECK(y1 == y2);  // the same operations: bit for bit
    CHECK(z1 == z2);
    if (settings.anderson_window > 0) CHECK(r1.energy == r2.energy);
  }

  // prepare, then setups without G's: the same model again.
  Alternation<double> prepared;
  prepared.prepare(s.solver, s.Gz, s.Gy, proj);
  CHECK_FALSE(prepared.ready());
  const Matrix<double> Az = Matrix<double>(s.A.transpose()) * s.solver.subspace().N;
  const Matrix<double> Ay = Matrix<double>(s.A.transpose()) * s.solver.subspace().UD;
  REQUIRE(prepared.setup(s.solver, Az, Ay, proj, setup).ok());
  Vector<double> z1(s.d), z2(s.d), y1 = s.start(), y2 = y1;
  alt.solve(proj, s.b, accelerated, z1, y1);
  prepared.solve(proj, s.b, accelerated, z2, y2);
  CHECK((y1 - y2).norm() <= 1e-12 * (1 + y1.norm()));
  CHECK((z1 - z2).norm() <= 1e-12 * (1 + z1.norm()));
}

TEST_CASE("Alternation: right-hand sides that follow y (follow_y) meet b + T·y at the fixed point",
          "[alternation][follow_y]") {
  SphereModel s;
  // Each constraint row i follows entry i of y, with a weight: b + T·y.
  SparseMatrix<double> T(s.m, s.k);
  for (Index i = 0; i < s.m; ++i) T.insert(i, (2 * i) % s.k) = 0.5 + 0.1 * static_cast<double>(i);
  T.makeCompressed();
  AlternationSetup setup;
  setup.follow_y = T;
  Ball proj;
  Alternation<double> alt;
  REQUIRE(alt.setup(s.solver, s.A, s.Gz, s.Gy, proj, setup).ok());
  CHECK_FALSE(alt.energy_terms());  // plain rounds only with T

  // z for a given y is Phase 1 with the right-hand side b + T·y.
  FixedCoordinateSolver<double> phase1;
  REQUIRE(phase1.set_constraints(s.solver, s.A).ok());
  const Vector<double> y0 = 0.3 * s.start();
  Vector<double> z(s.d), z_ref(s.d);
  alt.phase_one(s.b, y0, z);
  phase1.solve(s.b + T * y0, y0, z_ref);
  CHECK((z - z_ref).norm() <= 1e-10 * (1 + z_ref.norm()));
  // M_Y of the model carries M_b·T.
  CHECK((alt.MY() - (phase1.MY() + phase1.Mb() * Matrix<double>(T))).norm() <= 1e-10 * (1 + phase1.MY().norm()));

  // Rounds to a tight tolerance: y = Π(G_z·z + G_y·y) with the constraints
  // Aᵀ(N z + UD·y) = b + T·y.
  AlternationSettings settings;
  settings.iterations = 5000;
  settings.tolerance = 1e-13;
  Vector<double> y = y0;
  const AlternationResults r = alt.solve(proj, s.b, settings, z, y);
  CAPTURE(r.iterations, r.last_change);
  REQUIRE(r.stop == RoundStop::Tolerance);
  const Vector<double> X = s.solver.subspace().N * z + s.solver.subspace().UD * y;
  const Vector<double> residual = Vector<double>(s.A.transpose() * X) - (s.b + T * y);
  CHECK(residual.norm() <= 1e-9 * (1 + s.b.norm()));
  Vector<double> g = s.Gz * z + s.Gy * y, again = y;
  proj.project(g, again);
  CHECK((again - y).norm() <= 1e-11 * (1 + y.norm()));

  // A later setup without T is the plain set again (the kept G's are the
  // plain ones, not those with M_b·T folded in).
  AlternationSetup plain_setup;
  Alternation<double> fresh;
  REQUIRE(alt.setup(s.solver, s.A, s.Gz, s.Gy, proj, plain_setup).ok());
  REQUIRE(fresh.setup(s.solver, s.A, s.Gz, s.Gy, proj, plain_setup).ok());
  const Matrix<double> Az = Matrix<double>(s.A.transpose()) * s.solver.subspace().N;
  const Matrix<double> Ay = Matrix<double>(s.A.transpose()) * s.solver.subspace().UD;
  REQUIRE(alt.setup(s.solver, Az, Ay, proj, setup).ok());  // with T, from the kept G's
  REQUIRE(alt.setup(s.solver, Az, Ay, proj, plain_setup).ok());
  AlternationSettings few;
  few.iterations = 9;
  Vector<double> z1(s.d), z2(s.d), y1 = y0, y2 = y0;
  alt.solve(proj, s.b, few, z1, y1);
  fresh.solve(proj, s.b, few, z2, y2);
  CHECK((y1 - y2).norm() <= 1e-12 * (1 + y1.norm()));
  CHECK((z1 - z2).norm() <= 1e-12 * (1 + z1.norm()));
}

TEST_CASE("Alternation refuses misuse with the words, and a refused setup keeps the last model",
          "[alternation][errors]") {
  SphereModel s;
  UnitBlocks proj;
  Alternation<double> alt;
  Vector<double> z(s.d), y = s.start();
  AlternationSettings settings;
  CHECK_FALSE(alt.ready());
  CHECK_THROWS_WITH(alt.solve(proj, s.b, settings, z, y), Catch::Contains("call setup first"));
  const Matrix<double> Az = Matrix<double>(s.A.transpose()) * s.solver.subspace().N;
  const Matrix<double> Ay = Matrix<double>(s.A.transpose()) * s.solver.subspace().UD;
  CHECK_THROWS_WITH(alt.setup(s.solver, Az, Ay, proj), Catch::Contains("no G_z, G_y given yet"));

  REQUIRE(alt.setup(s.solver, s.A, s.Gz, s.Gy, proj).ok());
  Vector<double> z_before(s.d), y_before = s.start();
  alt.solve(proj, s.b, settings, z_before, y_before);

  // Bad inputs to setup: named, and the model stays the last one.
  Matrix<double> bad = s.Gz;
  bad(0, 0) = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(alt.setup(s.solver, s.A, bad, s.Gy, proj), Catch::Contains("G_z"));
  CHECK_THROWS_WITH(alt.setup(s.solver, s.A, Matrix<double>(s.k, s.d + 1), s.Gy, proj),
                    Catch::Contains("G_z columns"));
  AlternationSetup wrong;
  wrong.follow_y.resize(s.m + 1, s.k);
  CHECK_THROWS_WITH(alt.setup(s.solver, s.A, s.Gz, s.Gy, proj, wrong), Catch::Contains("follow_y rows"));
  REQUIRE(alt.ready());
  Vector<double> z_after(s.d), y_after = s.start();
  alt.solve(proj, s.b, settings, z_after, y_after);
  CHECK(y_after == y_before);
  CHECK(z_after == z_before);

  // Bad settings and sizes at solve.
  AlternationSettings zero;
  zero.iterations = 0;
  CHECK_THROWS_WITH(alt.solve(proj, s.b, zero, z, y), Catch::Contains("iterations must be at least 1"));
  Vector<double> short_y(s.k - 1);
  CHECK_THROWS_WITH(alt.solve(proj, s.b, settings, z, short_y), Catch::Contains("y (k)"));

  // Accelerated runs need the energy terms the setup was told not to form.
  AlternationSetup no_energy;
  no_energy.energy_terms = false;
  REQUIRE(alt.setup(s.solver, s.A, s.Gz, s.Gy, proj, no_energy).ok());
  CHECK_FALSE(alt.energy_terms());
  AlternationSettings accelerated;
  accelerated.anderson_window = 4;
  CHECK_THROWS_WITH(alt.solve(proj, s.b, accelerated, z, y), Catch::Contains("need the energy terms"));
  // ... and a projection without quadratic_term gets none either.
  Ball ball;
  REQUIRE(alt.setup(s.solver, s.A, s.Gz, s.Gy, ball).ok());
  CHECK_FALSE(alt.energy_terms());
}
