// The full-space finish (refine.h): from the reduced pose and from rest it
// reaches the same classic ARAP energy, Anderson never raises the energy,
// a cancelled refine leaves a valid pose, the factorization is reused while
// only the targets move, bad settings throw clear errors; on the shared
// Botsch–Sorkine scenarios the refined shapes match the converged CGAL ones.
#include <catch2/catch.hpp>

#include "../reference/reference_test_util.h"
#include "../io/io_test_util.h"

#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/io/handles_io.h"
#include "qpreduce/deform/io/mesh_io.h"
#include "qpreduce/deform/io/tet_io.h"
#include "qpreduce/deform/mesh/geometry.h"
#include "qpreduce/deform/refine/refine.h"

#include <qpreduce/anderson.h>

#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

using namespace qpreduce;
using namespace qpreduce::deform;
using namespace qpreduce::deform::reference_test;

namespace {

// One reduced frame (a few rounds) of the deformer on `c`: the pose a
// refine starts from.
Vertices reduced_pose(const Case& c) {
  DeformerOptions options;
  options.linear_proxies = 6;
  Deformer deformer;
  REQUIRE(deformer.precompute(c.model, options).ok());
  REQUIRE(deformer.set_handles(c.handles).ok());
  Vertices V;
  REQUIRE(deformer.frame(c.targets, &V).ok());
  return V;
}

// A Refiner on c's model with this tolerance (relative energy change or
// fixed-point residual; no distance test) and Anderson window.
Refiner make_refiner(const Case& c, double tolerance, int window) {
  RefineOptions options;
  options.tolerance = tolerance;
  options.distance_tolerance = 0.0;
  options.anderson_window = window;
  Refiner refiner;
  refiner.precompute(c.model, options);
  return refiner;
}

// Solves from `start` with ro's Anderson window on *lg, then plain: both
// converge to the same pose (and Q, for E′) and energy, the accelerated one
// in fewer rounds and never raising the energy from one round to the next.
void check_accelerated_against_plain(const Case& c, const Vertices& start, ReferenceOptions ro, LocalGlobalArap* lg) {
  REQUIRE(ro.anderson_window > 0);
  lg->set_iteration_options(ro);
  ReferenceSolution fast, plain;
  const ReferenceSummary sf = lg->solve(c.targets, &fast, start);
  ro.anderson_window = 0;
  lg->set_iteration_options(ro);
  const ReferenceSummary sp = lg->solve(c.targets, &plain, start);
  CAPTURE(sf.iterations, sp.iterations, sf.rejected_steps);
  REQUIRE(sf.converged);
  REQUIRE(sp.converged);
  CHECK(sf.iterations < sp.iterations);
  CHECK(std::abs(sf.energy - sp.energy) <= 1e-8 * sp.energy);
  CHECK(max_distance(fast.V, plain.V) < 1e-5 * bounding_box_diagonal(c.model.V));
  CHECK((fast.Q - plain.Q).norm() <= 1e-5 * (1 + plain.Q.norm()));
  for (size_t k = 1; k < sf.round_energy.size(); ++k) CHECK(sf.round_energy[k] <= sf.round_energy[k - 1] * (1 + 1e-12));
}

}  // namespace

TEST_CASE("refine: from the reduced pose and from rest the same classic ARAP energy", "[reference][refine]") {
  const bool tet = GENERATE(false, true);
  const int window = GENERATE(0, 5);
  CAPTURE(tet, window);
  const Case c = bend_case(tet, 0.9);
  const Vertices reduced = reduced_pose(c);
  Refiner refiner = make_refiner(c, 1e-10, window);
  Vertices from_reduced, from_rest;
  const RefineSummary a = refiner.refine(c.handles, c.targets, reduced, &from_reduced);
  const RefineSummary b = refiner.refine(c.handles, c.targets, {}, &from_rest);
  INFO(a.message << " / " << b.message);
  REQUIRE(a.ok());
  REQUIRE(b.ok());
  CHECK(a.converged);
  CHECK(b.converged);
  CHECK(a.refactored);
  CHECK_FALSE(b.refactored);  // same handle set: the factorization is reused
  CHECK(std::abs(a.arap_energy - b.arap_energy) <= 1e-6 * b.arap_energy);
  // The reported energy is that of the returned pose, and the pose meets the
  // handles.
  CHECK(a.arap_energy == Approx(arap_energy(c.model.V, refiner.elements(), from_reduced)).epsilon(1e-12));
  CHECK(a.energy == Approx(a.arap_energy).epsilon(1e-12));
  const double diag = bounding_box_diagonal(c.model.V);
  CHECK(a.handle_residual < 1e-9 * diag);
  CHECK(b.handle_residual < 1e-9 * diag);
  // The reduced pose is a good start: fewer rounds than from rest, and the
  // distances reported are those between the two poses.
  CHECK(a.rounds < b.rounds);
  CHECK(a.initial_energy < b.arap_energy * 10);
  CHECK(a.rms_from_input == Approx(rms_distance(reduced, from_reduced) / diag).epsilon(1e-12));
  CHECK(a.max_from_input == Approx(max_distance(reduced, from_reduced) / diag).epsilon(1e-12));
  CHECK(a.rms_from_input <= a.max_from_input);
  // Against a converged plain reference.
  ReferenceSolution converged;
  const ReferenceSummary rs = solve_local_global(c.model, c.handles, c.targets, ReferenceOptions{}, &converged);
  REQUIRE(rs.converged);
  CHECK(std::abs(a.arap_energy - rs.energy) <= 1e-6 * rs.energy);
  CHECK(max_distance(from_reduced, converged.V) < 1e-3 * diag);
}

TEST_CASE("refine: the default stop is within its estimate of the converged shape", "[reference][refine]") {
  // The stop rule does not fire in a flat valley: the estimate divides the
  // step by the gap 1 − ρ of the slowest contraction seen, so the pose it
  // stops at is as close to the converged one as it says, from the reduced
  // pose and from rest, plain and accelerated, surfaces and tets.
  const bool tet = GENERATE(false, true);
  const int window = GENERATE(0, 5);
  CAPTURE(tet, window);
  const Case c = bend_case(tet, 0.9);
  const Vertices reduced = reduced_pose(c);
  const double diag = bounding_box_diagonal(c.model.V);
  RefineOptions options;
  options.anderson_window = window;
  CHECK(options.distance_tolerance == 1e-4);
  CHECK(options.tolerance == 0.0);
  Refiner refiner;
  refiner.precompute(c.model, options);
  Vertices converged;
  RefineOptions tight = options;
  tight.distance_tolerance = 0.0;  // to the reference test
  refiner.set_options(tight);
  REQUIRE(refiner.refine(c.handles, c.targets, reduced, &converged).converged);
  refiner.set_options(options);
  for (const bool from_rest : {false, true}) {
    CAPTURE(from_rest);
    Vertices out;
    const RefineSummary s = refiner.refine(c.handles, c.targets, from_rest ? Vertices() : reduced, &out);
    REQUIRE(s.ok());
    CAPTURE(s.rounds, s.estimated_distance);
    CHECK(s.converged);
    CHECK(s.estimated_distance <= options.distance_tolerance);
    const double rms = rms_distance(out, converged) / diag;
    CAPTURE(rms);
    CHECK(rms <= options.distance_tolerance);
    // The estimate does not claim much less than the distance, down to the
    // round-off where `converged` itself stopped (its reference test: moves
    // below 1e-10 of the diagonal); a run that also ends there is as close
    // as the comparison can tell.
    CHECK((s.estimated_distance >= 0.5 * rms || rms <= 1e-9));
  }
  options.distance_tolerance = -1.0;
  CHECK_THROWS_WITH(refiner.set_options(options), Catch::Contains("distance_tolerance must be finite and ≥ 0"));
}

TEST_CASE("refine: Anderson never raises the energy and reaches the plain fixed point in fewer rounds",
          "[reference][refine][anderson]") {
  // The surface and the tet case at three bends from the reduced pose, and
  // a half turn from rest: the safeguard must have refused steps in their
  // rounds taken together, so that the monotonicity below covers its
  // fallback too. It keeps an extrapolation whose energy is within
  // round-off (10⁻¹³, relative) of the accepted one, so from the reduced
  // pose these small meshes refuse none; the half turn from rest on the
  // surface refuses one.
  int rejected_total = 0;
  struct Start {
    double angle;
    bool tet, from_rest;
  };
  const Start cases[] = {{1.0, false, false}, {1.0, true, false}, {1.3, false, false}, {1.3, true, false},
                         {2.0, false, false}, {2.0, true, false}, {3.1, false, true},  {3.1, true, true}};
  for (const auto& [angle, tet, from_rest] : cases) {
    CAPTURE(angle, tet, from_rest);
    const Case c = bend_case(tet, angle);
    const Vertices reduced = from_rest ? c.model.V : reduced_pose(c);
    ReferenceOptions ro;
    ro.anderson_window = 6;
    LocalGlobalArap lg;
    lg.precompute(c.model, ro);
    REQUIRE(lg.set_handles(c.handles).ok());
    // The energy after k accelerated rounds, k = 1, 2, …, never goes up, and
    // no round's energy exceeds the reduced start's (which meets the handles;
    // the rest pose's energy, 0, is of a pose that does not).
    double previous = std::numeric_limits<double>::infinity();
    ReferenceSolution sol;
    int rejected = 0;
    for (int k = 1; k <= 40; ++k) {
      ro.max_iterations = k;
      lg.set_iteration_options(ro);
      const ReferenceSummary s = lg.solve(c.targets, &sol, reduced);
      CAPTURE(k, s.energy, previous, s.initial_energy);
      REQUIRE(s.ok());
      CHECK(s.energy <= previous * (1 + 1e-12));
      if (!from_rest) CHECK(s.energy <= s.initial_energy * (1 + 1e-12));
      CHECK(sol.V.allFinite());
      previous = s.energy;
      rejected = s.rejected_steps;
    }
    rejected_total += rejected;
    ro.max_iterations = 20000;
    lg.set_iteration_options(ro);
    check_accelerated_against_plain(c, reduced, ro, &lg);
  }
  CHECK(rejected_total > 0);
}

TEST_CASE("refine: the Newton finish reaches the plain rounds' minimiser, the energy never rises",
          "[reference][refine][newton]") {
  // Trust-region Newton steps after a few rounds (RefineOptions::
  // newton_after) end at the classic minimiser that plain local-global
  // reaches when run long, on a surface and on tets; the energy of the
  // accepted poses never rises; a start already at the minimiser stays there.
  const bool tet = GENERATE(false, true);
  CAPTURE(tet);
  const Case c = bend_case(tet, 1.0);
  const Vertices reduced = reduced_pose(c);
  const double diag = bounding_box_diagonal(c.model.V);
  RefineOptions options;
  options.distance_tolerance = 0.0;  // to the reference test
  options.newton_after = 4;
  Refiner refiner;
  refiner.precompute(c.model, options);
  Vertices newton, plain;
  const RefineSummary sn = refiner.refine(c.handles, c.targets, reduced, &newton);
  RefineOptions rounds_only = options;
  rounds_only.newton_after = 0;
  rounds_only.anderson_window = 0;
  refiner.set_options(rounds_only);
  const RefineSummary sp = refiner.refine(c.handles, c.targets, reduced, &plain);
  INFO(sn.message << " / " << sp.message);
  CAPTURE(sn.rounds, sn.newton_steps, sn.cg_iterations, sp.rounds);
  REQUIRE(sn.ok());
  REQUIRE(sp.ok());
  CHECK(sn.converged);
  CHECK(sp.converged);
  CHECK(sn.newton_steps > 0);
  CHECK(sn.cg_iterations >= sn.newton_steps);
  CHECK(sp.newton_steps == 0);
  CHECK(std::abs(sn.arap_energy - sp.arap_energy) <= 1e-8 * sp.arap_energy);
  CHECK(rms_distance(newton, plain) <= 1e-5 * diag);
  CHECK(sn.handle_residual < 1e-9 * diag);
  for (size_t k = 1; k < sn.round_energy.size(); ++k)
    CHECK(sn.round_energy[k] <= sn.round_energy[k - 1] * (1 + 1e-12));
  // From the minimiser: nothing left to correct, and nothing is harmed.
  options.newton_after = 1;
  refiner.set_options(options);
  Vertices again;
  const RefineSummary sa = refiner.refine(c.handles, c.targets, newton, &again);
  CAPTURE(sa.rounds, sa.newton_steps);
  REQUIRE(sa.ok());
  CHECK(sa.converged);
  CHECK(sa.arap_energy <= sn.arap_energy * (1 + 1e-12));
  CHECK(max_distance(again, newton) <= 1e-6 * diag);
  // The default stop with Newton steps: within its estimate of the minimiser.
  options.distance_tolerance = 1e-4;
  options.newton_after = 4;
  refiner.set_options(options);
  Vertices stopped;
  const RefineSummary sd = refiner.refine(c.handles, c.targets, reduced, &stopped);
  CAPTURE(sd.rounds, sd.newton_steps, sd.estimated_distance);
  REQUIRE(sd.converged);
  CHECK(sd.estimated_distance <= 1e-4);
  CHECK(rms_distance(stopped, plain) / diag <= 1e-4);
  options.newton_after = -1;
  CHECK_THROWS_WITH(refiner.set_options(options), Catch::Contains("newton_after must be ≥ 0"));
}

TEST_CASE("refine: Anderson on E' (z = [V'; Q]) reaches the plain E' minimiser, energy never raised",
          "[reference][refine][anderson]") {
  const bool tet = GENERATE(false, true);
  CAPTURE(tet);
  const Case c = bend_case(tet, 0.9);
  const Vertices reduced = reduced_pose(c);
  ReferenceOptions ro;
  ro.energy = ReferenceEnergy::ModifiedArap;
  ro.anderson_window = 5;
  LocalGlobalArap lg;
  lg.precompute(c.model, ro);
  REQUIRE(lg.set_handles(c.handles).ok());
  check_accelerated_against_plain(c, reduced, ro, &lg);
}

TEST_CASE("refine: cancelling mid-way leaves a valid pose", "[reference][refine]") {
  const bool tet = GENERATE(false, true);
  const int window = GENERATE(0, 5);
  CAPTURE(tet, window);
  const Case c = bend_case(tet, 0.9);
  const Vertices reduced = reduced_pose(c);
  Refiner refiner = make_refiner(c, 1e-12, window);
  int calls = 0;
  Vertices out;
  const RefineSummary s = refiner.refine(c.handles, c.targets, reduced, &out, [&calls] { return ++calls > 7; });
  INFO(s.message);
  CHECK(s.ok());
  CHECK(s.cancelled);
  CHECK_FALSE(s.converged);
  CHECK(s.rounds == 7);
  CHECK(calls == 8);
  REQUIRE(out.rows() == c.model.V.rows());
  CHECK(out.allFinite());
  CHECK(s.handle_residual < 1e-9 * bounding_box_diagonal(c.model.V));
  CHECK(s.arap_energy == Approx(arap_energy(c.model.V, refiner.elements(), out)).epsilon(1e-12));
  CHECK(s.arap_energy <= s.initial_energy);
  // Cancelled before the first round: the input pose comes back.
  const RefineSummary none = refiner.refine(c.handles, c.targets, reduced, &out, [] { return true; });
  CHECK(none.cancelled);
  CHECK(none.rounds == 0);
  CHECK(max_distance(out, reduced) == 0.0);
}

TEST_CASE("refine: a new handle set re-factors, new targets do not", "[reference][refine]") {
  Case c = bend_case(false, 0.6);
  Refiner refiner;
  refiner.precompute(c.model);
  Vertices out;
  CHECK(refiner.refine(c.handles, c.targets, {}, &out).refactored);
  HandleTargets moved = c.targets;
  moved.patch_transforms[0](0, 3) += 0.05;
  const RefineSummary same = refiner.refine(c.handles, moved, out, &out);
  CHECK_FALSE(same.refactored);
  CHECK(same.setup_seconds == 0.0);
  const Index n = c.model.V.rows();
  c.handles.points.push_back({{n / 2}, {}});
  moved.points.resize(1, 3);
  moved.points.row(0) = out.row(n / 2);
  const RefineSummary more = refiner.refine(c.handles, moved, out, &out);
  INFO(more.message);
  CHECK(more.refactored);
  CHECK(more.ok());
  CHECK((out.row(n / 2) - moved.points.row(0)).norm() < 1e-9);
}

TEST_CASE("refine: bad settings give clear errors", "[reference][refine]") {
  const Case c = bend_case(false, 0.5);
  Refiner refiner;
  RefineOptions options;
  options.tolerance = -1e-6;
  CHECK_THROWS_WITH(refiner.precompute(c.model, options),
                    Catch::Contains("RefineOptions: tolerance must be finite and ≥ 0, got -1e-06"));
  options.tolerance = std::numeric_limits<double>::quiet_NaN();
  CHECK_THROWS_WITH(refiner.precompute(c.model, options), Catch::Contains("tolerance must be finite"));
  options = RefineOptions{};
  options.anderson_window = 17;
  CHECK_THROWS_WITH(refiner.precompute(c.model, options), Catch::Contains("anderson_window must be in [0, 16]"));
  options.anderson_window = -1;
  CHECK_THROWS_WITH(refiner.precompute(c.model, options), Catch::Contains("got -1"));
  options = RefineOptions{};
  options.threads = -2;
  CHECK_THROWS_WITH(refiner.precompute(c.model, options), Catch::Contains("threads must be ≥ 0 (0: all), got -2"));
  Vertices out;
  CHECK_THROWS_WITH(refiner.refine(c.handles, c.targets, {}, &out), Catch::Contains("call precompute first"));
  refiner.precompute(c.model);
  options = RefineOptions{};
  options.tolerance = -1.0;
  CHECK_THROWS_WITH(refiner.set_options(options), Catch::Contains("tolerance must be finite and ≥ 0"));
  const Vertices wrong = c.model.V.topRows(3);
  CHECK_THROWS_WITH(refiner.refine(c.handles, c.targets, wrong, &out), Catch::Contains("pose rows"));
  // The reference options validate the same settings.
  ReferenceOptions ro;
  ro.tolerance = -1.0;
  CHECK_THROWS_WITH(LocalGlobalArap().precompute(c.model, ro), Catch::Contains("tolerance must be finite and ≥ 0"));
  ro = ReferenceOptions{};
  ro.anderson_window = 17;
  std::string why;
  CHECK_FALSE(ro.is_valid(&why));
  CHECK(why.find("anderson_window must be in [0, 16]") != std::string::npos);
  // Acceleration requested with an empty window: the Anderson class itself
  // refuses.
  AndersonOptions ao;
  ao.window = 0;
  CHECK_FALSE(ao.is_valid(&why));
  CHECK_THROWS_AS(AndersonAcceleration().reset(10, ao), std::invalid_argument);
}

namespace {

// A Botsch–Sorkine .sel/.def scenario of ../shared/data on `mesh` (surface
// or the TetGen solid whose first nodes are the surface: the rest are free).
Case shared_case(const std::string& data, const std::string& mesh, const std::string& scenario) {
  Case c;
  const std::string bs = data + "/meshes/botsch-sorkine/";
  if (mesh.find("tets/") == 0) {
    const TetMesh m = read_tet_mesh(data + "/" + mesh);
    c.model.V = m.V;
    c.model.T = m.T;
  } else {
    const TriangleMesh m = read_triangle_mesh(data + "/" + mesh);
    c.model.V = m.V;
    c.model.F = m.F;
  }
  const Selection sel = read_sel(bs + scenario + ".sel");
  std::vector<int> roles(static_cast<size_t>(c.model.V.rows()), static_cast<int>(SelRole::Free));
  for (Index v = 0; v < sel.size(); ++v) roles[v] = static_cast<int>(sel.roles[v]);
  const SelDefScenario sd = apply_sel_def(roles, read_def(bs + scenario + ".def"), &c.model);
  c.handles = sd.handles;
  c.targets = sd.targets;
  return c;
}

}  // namespace

TEST_CASE("refine: converged shapes agree with the shared CGAL and libigl references", "[reference][refine][data]") {
  REQUIRE_SHARED_DATA(data);
  struct Reference {
    const char* mesh;
    const char* scenario;
    const char* reference;
  };
  // The converged ones (references/README.md): the CGAL bar is still falling
  // at 10,000 iterations and Bumpy Plane (40k) is too slow for a unit test.
  const std::vector<Reference> refs = {
      {"meshes/botsch-sorkine/cylinder.off", "cylinder", "cgal_sr_cylinder_it10000.off"},
#ifndef QPREDUCE_SANITIZER_BUILD  // (the surface cylinder alone there: 100 s for the three)
      {"meshes/botsch-sorkine/cactus.off", "cactus", "cgal_sr_cactus_it10000.off"},
      {"tets/solid_cylinder.node", "cylinder", "libigl_tet_solid_cylinder_it2000.off"},
#endif
  };
  for (const Reference& r : refs) {
    CAPTURE(r.mesh);
    const Case c = shared_case(data, r.mesh, r.scenario);
    const TriangleMesh ref = read_triangle_mesh(data + "/references/" + r.reference);
    const Index ns = ref.V.rows();  // the tet reference holds the surface nodes only
    REQUIRE(ns <= c.model.V.rows());
    // The default stop (an estimated 1e-4 of the diagonal from converged),
    // from rest: within 0.1 % of the reference.
    Refiner refiner;
    refiner.precompute(c.model);
    Vertices out;
    const RefineSummary d = refiner.refine(c.handles, c.targets, {}, &out);
    CAPTURE(d.rounds, d.estimated_distance);
    REQUIRE(d.ok());
    CHECK(d.converged);
    CHECK(d.estimated_distance <= RefineOptions{}.distance_tolerance);
    CHECK(rms_distance(out.topRows(ns), ref.V) / bounding_box_diagonal(c.model.V) <= 1e-3);
    // Then tightly (no distance test, energy change 1e-9) for the energy.
    RefineOptions options;
    options.tolerance = 1e-9;
    options.distance_tolerance = 0.0;
    refiner.set_options(options);
    const RefineSummary s = refiner.refine(c.handles, c.targets, out, &out);
    CAPTURE(s.rounds, s.seconds, s.arap_energy, s.rejected_steps);
    REQUIRE(s.ok());
    CHECK(s.converged);
    const double diag = bounding_box_diagonal(c.model.V);
    const Vertices mine = out.topRows(ns);
    const double rms = rms_distance(mine, ref.V) / diag;
    CAPTURE(rms, max_distance(mine, ref.V) / diag);
    CHECK(rms <= 1e-3);
    // The converged pose's energy is at most the reference's (both minimise
    // the same energy; theirs stopped after a fixed iteration count).
    const double theirs = c.model.is_tet() ? arap_energy(c.model.V, refiner.elements(),
                                                         [&] {
                                                           Vertices v = out;
                                                           v.topRows(ns) = ref.V;
                                                           return v;
                                                         }())
                                           : arap_energy(c.model.V, refiner.elements(), ref.V);
    CAPTURE(theirs);
    if (!c.model.is_tet()) CHECK(s.arap_energy <= theirs * (1 + 1e-6));
  }
}
