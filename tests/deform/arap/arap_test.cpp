// ARAP in libigl's terms (arap.h): handles named at precompute are met
// exactly by the reduced solve, on surfaces and tets, for random targets and
// for the cylinder's .sel handle set held vertex by vertex; arap() and ArapSolver::refine reach the
// same converged shape; bad arguments throw errors that name them.
#include <catch2/catch.hpp>

#include "../../shared_data.h"

#include "qpreduce/deform/arap/arap.h"
#include "qpreduce/deform/io/handles_io.h"
#include "qpreduce/deform/io/mesh_io.h"
#include "qpreduce/deform/mesh/shapes.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>
#include <vector>

using namespace qpreduce;
using namespace qpreduce::deform;
using shapes::box_tets;
using shapes::capped_cylinder;

namespace {

double diagonal(const Vertices& V) { return (V.colwise().maxCoeff() - V.colwise().minCoeff()).norm(); }

// `count` distinct vertices, drawn with a fixed seed.
std::vector<Index> random_vertices(Index n, Index count, unsigned seed) {
  std::vector<Index> all(static_cast<size_t>(n));
  for (Index v = 0; v < n; ++v) all[static_cast<size_t>(v)] = v;
  std::mt19937 rng(seed);
  std::shuffle(all.begin(), all.end(), rng);
  all.resize(static_cast<size_t>(count));
  return all;
}

// Targets for b: a smooth bend of the rest shape (rotation about x growing
// along z) plus a random offset of `noise` diagonals per vertex.
Vertices bent_targets(const Vertices& V, const std::vector<Index>& b, double noise, unsigned seed) {
  const double lo = V.col(2).minCoeff(), hi = V.col(2).maxCoeff(), d = diagonal(V);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Vertices bc(static_cast<Index>(b.size()), 3);
  for (size_t i = 0; i < b.size(); ++i) {
    const Eigen::Vector3d p = V.row(b[i]).transpose();
    const double t = (p.z() - lo) / (hi - lo);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(0.8 * t, Eigen::Vector3d::UnitX()).toRotationMatrix();
    bc.row(static_cast<Index>(i)) = (R * p + noise * d * Eigen::Vector3d(u(rng), u(rng), u(rng))).transpose();
  }
  return bc;
}

double handle_error(const Vertices& U, const std::vector<Index>& b, const Vertices& bc) {
  double worst = 0.0;
  for (size_t i = 0; i < b.size(); ++i) worst = std::max(worst, (U.row(b[i]) - bc.row(static_cast<Index>(i))).norm());
  return worst;
}

Handles as_handles(const std::vector<Index>& b) {
  Handles h;
  for (Index v : b) h.points.push_back(PointHandle{{v}, {}});
  return h;
}

// The reduced deformer's own frame for (b, bc) on `model` (no rows written
// from bc): how far its float reconstruction puts the handles.
double deformer_handle_error(const DeformableMesh& model, const DeformerOptions& options, const std::vector<Index>& b,
                             const Vertices& bc, Status* handle_status) {
  Deformer deformer;
  REQUIRE(deformer.precompute(model, options).ok());
  const ConstraintSummary cs = deformer.set_handles(as_handles(b));
  REQUIRE(cs.usable());
  *handle_status = cs.status;
  HandleTargets targets;
  targets.points = bc;
  Vertices U;
  REQUIRE(deformer.frame(targets, &U).ok());
  return handle_error(U, b, bc);
}

// ArapSolver on (V, F, b): the subspace holds b exactly (the on-site step
// has full rank, and the float reconstruction is within its round-off of the
// targets before their rows are written), the solve writes them exactly, and
// the rest of the shape moves (it is not the rest pose).
// Returns the on-site step's message.
std::string check_exact(const Vertices& V, const ElementsRef& F, const std::vector<Index>& b, const Vertices& bc,
                        const ArapSolverOptions& options = {}) {
  ArapSolver solver;
  const PrecomputeSummary ps = solver.precompute(V, F, b, options);
  INFO(ps.message);
  REQUIRE(ps.ok());
  REQUIRE(solver.ready());
  CHECK(solver.handle_summary().status == Status::Success);
  CHECK(solver.handle_summary().rank == 3 * static_cast<Index>(b.size()));
  const double d = diagonal(V);
  Vertices U;
  const FrameSummary fs = solver.solve(bc, &U);
  REQUIRE(fs.ok());
  CAPTURE(b.size(), solver.reconstruction_handle_error() / d);
  CHECK(solver.reconstruction_handle_error() <= 1e-5 * d);  // float round-off of exactly held proxies
  CHECK(handle_error(U, b, bc) <= 1e-8 * d);
  CHECK((U - V).rowwise().norm().maxCoeff() > 1e-3 * d);
  return solver.handle_summary().message;
}

}  // namespace

TEST_CASE("ArapSolver: handles named at precompute are met exactly, on a surface", "[arap]") {
  const TriangleMesh m = capped_cylinder(1.0, 6.0, 16, 24);
  for (const Index count : {Index(3), Index(10), Index(100)}) {
    CAPTURE(count);
    const std::vector<Index> b = random_vertices(m.V.rows(), count, 7u + static_cast<unsigned>(count));
    check_exact(m.V, m.F, b, bent_targets(m.V, b, 0.01, 3));
  }
}

TEST_CASE("ArapSolver: solve into the caller's buffer equals solve into a matrix", "[arap]") {
  const TriangleMesh m = capped_cylinder(1.0, 6.0, 12, 16);
  const std::vector<Index> b = random_vertices(m.V.rows(), 20, 31u);
  const Vertices bc = bent_targets(m.V, b, 0.01, 3);
  ArapSolver a, c;
  REQUIRE(a.precompute(m.V, m.F, b).ok());
  REQUIRE(c.precompute(m.V, m.F, b).ok());
  Vertices U;
  REQUIRE(a.solve(bc, &U).ok());
  std::vector<double> buffer(static_cast<size_t>(3 * m.V.rows()), -1.0);
  REQUIRE(c.solve(bc, Eigen::Map<Vertices>(buffer.data(), m.V.rows(), 3)).ok());
  CHECK(Eigen::Map<Vertices>(buffer.data(), m.V.rows(), 3) == U);  // the same frame, written in place
  CHECK(c.reconstruction_handle_error() == a.reconstruction_handle_error());
  CHECK_THROWS_WITH(c.solve(bc, Eigen::Map<Vertices>(buffer.data(), m.V.rows() - 1, 3)),
                    Catch::Matchers::Contains("rows"));
}

TEST_CASE("ArapSolver: handles named at precompute are met exactly, on tets", "[arap]") {
  const TetMesh m = box_tets(1.0, 1.0, 4.0, 3, 3, 12);
  for (const Index count : {Index(4), Index(40)}) {
    CAPTURE(count);
    const std::vector<Index> b = random_vertices(m.V.rows(), count, 11u + static_cast<unsigned>(count));
    check_exact(m.V, m.T, b, bent_targets(m.V, b, 0.01, 5));
  }
}

TEST_CASE("ArapSolver: a 1,000-vertex handle set is met exactly", "[arap]") {
  // (The precompute's dense d × d steps grow as the cube of the handle count,
  // about 15 s here at 1,000: docs/performance.md, "Exact handles". The
  // on-site step eliminates the held proxies: docs/engine.md.)
#ifdef QPREDUCE_SANITIZER_BUILD
  const Index count = 100;
#else
  const Index count = 1000;
#endif
  const TriangleMesh m = capped_cylinder(1.0, 6.0, 30, 60);
  const std::vector<Index> b = random_vertices(m.V.rows(), count, 19u);
  ArapSolverOptions options;
  options.deformer.linear_proxies = 10;
  const std::string message = check_exact(m.V, m.F, b, bent_targets(m.V, b, 0.0, 1), options);
  INFO(message);
  CHECK(message.find("eliminated") != std::string::npos);
}

TEST_CASE("ArapSolver: without the handles at precompute the same set is not met", "[arap]") {
  // The contrast that makes the exact set worth naming: the default proxies
  // (farthest-point samples that do not know b) cannot follow 100 point
  // handles, and the deformer's frame leaves them visibly off.
  const TriangleMesh m = capped_cylinder(1.0, 6.0, 16, 24);
  const std::vector<Index> b = random_vertices(m.V.rows(), 100, 107u);
  const Vertices bc = bent_targets(m.V, b, 0.01, 3);
  DeformableMesh model;
  model.V = m.V;
  model.F = m.F;
  Status status = Status::NotRun;
  const double error = deformer_handle_error(model, DeformerOptions{}, b, bc, &status);
  CHECK(status == Status::ConstraintsLeastSquares);
  CHECK(error > 1e-3 * diagonal(m.V));
}

TEST_CASE("arap: one call reaches the shape ArapSolver::refine reaches", "[arap][refine]") {
  const TriangleMesh m = capped_cylinder(1.0, 6.0, 16, 24);
  std::vector<Index> b;
  for (Index v = 0; v < m.V.rows(); ++v)
    if (m.V(v, 2) < 0.3 || m.V(v, 2) > 5.7) b.push_back(v);  // both ends, as a libigl user would hold them
  const Vertices bc = bent_targets(m.V, b, 0.0, 1);
  RefineOptions tight;
  tight.distance_tolerance = 1e-7;
  Vertices U;
  const RefineSummary full = arap(m.V, m.F, b, bc, &U, tight);
  INFO(full.message);
  REQUIRE(full.ok());
  CHECK(full.converged);
  const double d = diagonal(m.V);
  CHECK(handle_error(U, b, bc) <= 1e-8 * d);

  ArapSolverOptions options;
  options.refine = tight;
  ArapSolver solver;
  REQUIRE(solver.precompute(m.V, m.F, b, options).ok());
  Vertices R;
  const RefineSummary finished = solver.refine(bc, &R);
  REQUIRE(finished.ok());
  const double rms = std::sqrt((R - U).rowwise().squaredNorm().mean()) / d;
  CAPTURE(rms, full.rounds, finished.rounds);
  CHECK(rms <= 1e-5);
  CHECK(finished.arap_energy == Approx(full.arap_energy).epsilon(1e-6));
  // From the reduced shape the finish needs fewer rounds than from rest.
  CHECK(finished.rounds < full.rounds);

  // U as libigl's initial guess: from the converged shape nothing moves far.
  Vertices again = U;
  const RefineSummary warm = arap(m.V, m.F, b, bc, &again, tight);
  REQUIRE(warm.ok());
  CHECK(warm.rounds <= full.rounds);
  CHECK(std::sqrt((again - U).rowwise().squaredNorm().mean()) / d <= 1e-5);
}

TEST_CASE("ArapSolver: a shared .sel handle set, held vertex by vertex, is met exactly", "[arap][data]") {
  REQUIRE_SHARED_DATA(data);
  // The cylinder's 482, the cactus's 864 and the bar's 962 held vertices
  // (the Bumpy Plane's 3,417 would need a 10 GB basis: docs/performance.md,
  // "Exact handles").
#ifdef QPREDUCE_SANITIZER_BUILD
  // The same check, smaller: every fourth held vertex of the cylinder.
  const std::vector<std::string> names = {"cylinder"};
  const Index every = 4;
#else
  const std::vector<std::string> names = {"cylinder", "cactus", "bar"};
  const Index every = 1;
#endif
  for (const std::string& name : names) {
    CAPTURE(name);
    const std::string bs = data + "/meshes/botsch-sorkine/";
    const TriangleMesh m = read_triangle_mesh(bs + name + ".off");
    const Selection sel = read_sel(bs + name + ".sel");
    const Eigen::Matrix4d def = read_def(bs + name + ".def");
    // libigl's habit: every fixed and handle vertex a point handle; the
    // fixed ones at rest, the handle ones where the .def puts them.
    std::vector<Index> b;
    Vertices bc(0, 3);
    for (Index v = 0, held = 0; v < sel.size(); ++v) {
      if (sel.roles[v] == SelRole::Free || held++ % every != 0) continue;
      Eigen::Vector3d p = m.V.row(v).transpose();
      if (sel.roles[v] == SelRole::Handle) p = def.topLeftCorner<3, 3>() * p + def.topRightCorner<3, 1>();
      b.push_back(v);
      bc.conservativeResize(bc.rows() + 1, 3);
      bc.row(bc.rows() - 1) = p.transpose();
    }
    CAPTURE(b.size());
    check_exact(m.V, m.F, b, bc);
  }
  // The Bumpy Plane's 3,417 held vertices are refused before anything is
  // allocated (ArapSolverOptions::max_basis_gb), with the size and arap().
  const std::string bs = data + "/meshes/botsch-sorkine/";
  const TriangleMesh plane = read_triangle_mesh(bs + "bumpy_plane.off");
  const Selection sel = read_sel(bs + "bumpy_plane.sel");
  std::vector<Index> held;
  for (Index v = 0; v < sel.size(); ++v)
    if (sel.roles[v] != SelRole::Free) held.push_back(v);
  ArapSolver solver;
  const PrecomputeSummary refused = solver.precompute(plane.V, plane.F, held);
  CHECK(refused.status == Status::NotRun);
  CHECK_THAT(refused.message, Catch::Matchers::Contains("3417 held vertices") &&
                                  Catch::Matchers::Contains("10.0 GB") && Catch::Matchers::Contains("arap()"));
  CHECK_FALSE(solver.ready());
  // ... and arap() (full space, one call) meets them exactly: its global
  // steps hold them, so a few rounds show it (converged: docs/performance.md).
  Vertices bc(static_cast<Index>(held.size()), 3);
  const Eigen::Matrix4d def = read_def(bs + "bumpy_plane.def");
  for (size_t i = 0; i < held.size(); ++i) {
    Eigen::Vector3d p = plane.V.row(held[i]).transpose();
    if (sel.roles[held[i]] == SelRole::Handle) p = def.topLeftCorner<3, 3>() * p + def.topRightCorner<3, 1>();
    bc.row(static_cast<Index>(i)) = p.transpose();
  }
  RefineOptions few;
  few.max_iterations = 3;
  Vertices U;
  const RefineSummary rs = arap(plane.V, plane.F, held, bc, &U, few);
  INFO(rs.message);
  REQUIRE(usable(rs.status));
  CHECK(handle_error(U, held, bc) <= 1e-8 * diagonal(plane.V));
  CHECK((U - plane.V).rowwise().norm().maxCoeff() > 1e-3 * diagonal(plane.V));
}

TEST_CASE("arap and ArapSolver: bad arguments are refused with their names", "[arap][bad-input]") {
  const TriangleMesh m = capped_cylinder(1.0, 6.0, 8, 6);
  const std::vector<Index> b = {0, 5};
  const Vertices bc = m.V(b, Eigen::all);
  Vertices U;
  using Catch::Matchers::Contains;
  const Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> two_columns = m.F.leftCols(2);
  CHECK_THROWS_WITH(arap(m.V, two_columns, b, bc, &U), Contains("F must have 3 columns"));
  CHECK_THROWS_WITH(arap(m.V, m.F, {0, m.V.rows()}, bc, &U), Contains("b[1]") && Contains("outside"));
  CHECK_THROWS_WITH(arap(m.V, m.F, {3, 3}, bc, &U), Contains("b lists vertex 3 twice"));
  CHECK_THROWS_WITH(arap(m.V, m.F, {}, Vertices(0, 3), &U), Contains("b is empty"));
  CHECK_THROWS_WITH(arap(m.V, m.F, b, bc.topRows(1), &U), Contains("bc has 1 rows: expected 2"));
  Vertices nan = bc;
  nan(1, 2) = std::nan("");
  CHECK_THROWS_WITH(arap(m.V, m.F, b, nan, &U), Contains("bc contains NaN"));
  Vertices short_guess = m.V.topRows(3);
  CHECK_THROWS_WITH(arap(m.V, m.F, b, bc, &short_guess), Contains("U has 3 rows"));
  CHECK_THROWS_WITH(arap(m.V, m.F, b, bc, nullptr), Contains("U is null"));

  ArapSolver solver;
  CHECK_FALSE(solver.ready());
  CHECK_THROWS_WITH(solver.solve(bc, &U), Contains("call precompute first"));
  ArapSolverOptions bad;
  bad.max_rounds = 0;
  CHECK_THROWS_WITH(solver.precompute(m.V, m.F, b, bad), Contains("max_rounds"));
  CHECK_THROWS_WITH(solver.precompute(m.V, m.F, {1, 1}, {}), Contains("twice"));
  REQUIRE(solver.precompute(m.V, m.F, b).ok());
  CHECK_THROWS_WITH(solver.solve(nan, &U), Contains("bc contains NaN"));
  CHECK_THROWS_WITH(solver.solve(bc.topRows(1), &U), Contains("bc has 1 rows"));
  // A refused call loses nothing: the next good one works.
  REQUIRE(solver.solve(bc, &U).ok());
  CHECK(handle_error(U, b, bc) == 0.0);
}

TEST_CASE("exact_handle_proxies: held vertices become proxies once, patches and groups as documented", "[arap]") {
  const TriangleMesh m = capped_cylinder(1.0, 6.0, 16, 24);
  DeformableMesh model;
  model.V = m.V;
  model.F = m.F;
  std::vector<Index> bottom;  // a fixed patch at the base
  for (Index v = 0; v < m.V.rows(); ++v)
    if (m.V(v, 2) < 0.3) bottom.push_back(v);
  model.patch_of_vertex.assign(static_cast<size_t>(m.V.rows()), -1);
  for (Index v : bottom) model.patch_of_vertex[static_cast<size_t>(v)] = 0;
  model.patch_types = {PatchType::Fixed};
  const std::vector<Index> b = random_vertices(m.V.rows(), 60, 23u);
  Handles handles = as_handles(b);
  handles.points.push_back(PointHandle{{b[0]}, {}});       // held twice: one proxy
  handles.points.push_back(PointHandle{{bottom[0]}, {}});  // inside the fixed patch: no proxy
  const LinearProxies proxies = exact_handle_proxies(model, handles, 12);
  std::vector<Index> first;
  for (Index j = 0; j < proxies.count(); ++j) first.push_back(proxies.groups[static_cast<size_t>(j)][0]);
  Index seeds = 0;
  for (Index v : b) seeds += model.patch_of_vertex[static_cast<size_t>(v)] < 0;
  CHECK(proxies.count() == seeds + 12);
  for (Index v : b) {
    if (model.patch_of_vertex[static_cast<size_t>(v)] >= 0) continue;
    CHECK(std::count(first.begin(), first.end(), v) == 1);
  }
  CHECK(std::count(first.begin(), first.end(), bottom[0]) == 0);

  // With them as the model's proxies the set is exact (its free vertices: a
  // point handle inside the fixed patch would contradict the patch).
  model.linear = proxies;
  Deformer deformer;
  REQUIRE(deformer.precompute(model).ok());
  std::vector<Index> free_b;
  for (Index v : b)
    if (model.patch_of_vertex[static_cast<size_t>(v)] < 0) free_b.push_back(v);
  REQUIRE(free_b.size() > 40);
  CHECK(deformer.set_handles(as_handles(free_b)).status == Status::Success);

  Handles group;
  group.points.push_back(PointHandle{{b[0], b[1]}, {0.5, 0.5}});
  CHECK_THROWS_WITH(exact_handle_proxies(model, group, 12), Catch::Matchers::Contains("is a group of 2 vertices"));
  Handles outside;
  outside.points.push_back(PointHandle{{m.V.rows()}, {}});
  CHECK_THROWS_WITH(exact_handle_proxies(model, outside, 12), Catch::Matchers::Contains("outside"));
}

TEST_CASE("ArapSolver: a subspace above max_basis_gb is refused with the size, and the last precompute stays",
          "[arap][bad-input]") {
  const TriangleMesh m = capped_cylinder(1.0, 6.0, 12, 16);
  const std::vector<Index> b = random_vertices(m.V.rows(), 20, 41u);
  const Vertices bc = bent_targets(m.V, b, 0.01, 3);
  ArapSolver solver;
  REQUIRE(solver.precompute(m.V, m.F, b).ok());
  Vertices before;
  REQUIRE(solver.solve(bc, &before).ok());
  // 8 bytes × 3n × 3(h + samples): a few MB here; a limit of 1 kB refuses it.
  ArapSolverOptions small;
  small.max_basis_gb = 1e-6;
  const std::vector<Index> more = random_vertices(m.V.rows(), 40, 43u);
  const PrecomputeSummary refused = solver.precompute(m.V, m.F, more, small);
  CHECK(refused.status == Status::NotRun);
  CHECK_THAT(refused.message, Catch::Matchers::Contains("40 held vertices") &&
                                  Catch::Matchers::Contains("GB") && Catch::Matchers::Contains("arap()"));
  REQUIRE(solver.ready());
  Vertices after;
  REQUIRE(solver.solve(bc, &after).ok());  // still the 20-vertex solver (40 targets would be needed otherwise)
  CHECK(handle_error(after, b, bc) <= 1e-8 * diagonal(m.V));
  CHECK_THROWS_WITH(solver.solve(bent_targets(m.V, more, 0.01, 3), &after), Catch::Matchers::Contains("bc"));
  ArapSolverOptions bad;
  bad.max_basis_gb = -1.0;
  CHECK_THROWS_WITH(solver.precompute(m.V, m.F, b, bad), Catch::Matchers::Contains("max_basis_gb"));
  small.max_basis_gb = 0.0;  // no limit
  CHECK(solver.precompute(m.V, m.F, more, small).ok());
}
