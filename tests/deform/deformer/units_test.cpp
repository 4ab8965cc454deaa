// Metamorphic tests of the deformer and the full-space refine (issue: units):
// a scene scaled by 10^k, moved rigidly, or with its vertices renumbered
// gives the same pose transformed the same way, and the same statuses and
// messages. The meshes are jittered: on an exactly symmetric mesh the
// automatic proxies (k-means, farthest points) choose between equal
// candidates by the last bits, which no normalisation can make equal.
#include <catch2/catch.hpp>

#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/energy/arap_energy.h"
#include "qpreduce/deform/mesh/shapes.h"
#include "qpreduce/deform/reference/reference.h"
#include "qpreduce/deform/refine/refine.h"

#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <string>
#include <vector>

using namespace qpreduce;
using namespace qpreduce::deform;

// Named, so that its helpers do not meet those of the other test files of
// this target in a unity build (CMAKE_UNITY_BUILD).
namespace units_test {
namespace {

struct Scene {
  DeformableMesh model;
  Handles handles;
  std::vector<HandleTargets> frames;
};

// A similarity x ↦ s·R·x + t.
struct Similarity {
  double s = 1.0;
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  Eigen::Vector3d apply(const Eigen::Vector3d& x) const { return s * (R * x) + t; }
  Eigen::Vector3d invert(const Eigen::Vector3d& y) const { return R.transpose() * (y - t) / s; }
};

void jitter(Vertices* V, double amount, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-amount, amount);
  for (Index i = 0; i < V->size(); ++i) V->data()[i] += u(rng);
}

// Bottom fixed, top an Affine handle patch moved by a bend; and point
// handles on a few free vertices (the rows the conditioning tests judge).
Scene make_scene(bool tet, bool points) {
  Scene scene;
  std::vector<int> sel;
  double height = 0.0;
  if (tet) {
    const TetMesh m = shapes::box_tets(0.3, 0.3, 1.0, 3, 3, 10);
    scene.model.V = m.V;
    scene.model.T = m.T;
    height = 1.0;
  } else {
    const TriangleMesh m = shapes::capped_cylinder(0.15, 1.0, 16, 14);
    scene.model.V = m.V;
    scene.model.F = m.F;
    height = 1.0;
  }
  jitter(&scene.model.V, 2e-3, 7);
  scene.model.V.rowwise() += Eigen::RowVector3d(0.3, -0.2, 0.1);  // off the origin
  const Index n = scene.model.V.rows();
  for (Index v = 0; v < n; ++v) {
    const double z = scene.model.V(v, 2) - 0.1;
    sel.push_back(z < 0.08 * height ? 0 : (z > 0.92 * height ? 2 : 1));
  }
  Eigen::Matrix4d def = Eigen::Matrix4d::Identity();
  def.topLeftCorner<3, 3>() = Eigen::AngleAxisd(0.8, Eigen::Vector3d(0.2, 1.0, 0.1).normalized()).toRotationMatrix();
  def.block<3, 1>(0, 3) = Eigen::Vector3d(0.35, -0.05, -0.15);
  const SelDefScenario sd = apply_sel_def(sel, def, &scene.model);
  scene.handles = sd.handles;
  HandleTargets targets = sd.targets;
  if (points) {  // three free vertices pulled sideways
    for (Index v = 0, found = 0; v < n && found < 3; ++v) {
      if (sel[v] != 1 || std::abs(scene.model.V(v, 2) - 0.1 - 0.5 * height) > 0.05 * height) continue;
      if (found > 0 && (scene.model.V.row(v) - scene.model.V.row(scene.handles.points.back().vertices[0])).norm() < 0.1)
        continue;
      scene.handles.points.push_back({{v}, {}});
      ++found;
    }
    targets.points.resize(static_cast<Index>(scene.handles.points.size()), 3);
    for (size_t i = 0; i < scene.handles.points.size(); ++i) {
      targets.points.row(static_cast<Index>(i)) =
          scene.model.V.row(scene.handles.points[i].vertices[0]) + Eigen::RowVector3d(0.12, 0.05, 0.0);
    }
  }
  // Two frames: halfway (translation and targets halved), then the full pose.
  HandleTargets half = targets;
  half.points = 0.5 * (targets.points + [&] {
                  Vertices rest(targets.points.rows(), 3);
                  for (Index i = 0; i < rest.rows(); ++i)
                    rest.row(i) = scene.model.V.row(scene.handles.points[i].vertices[0]);
                  return rest;
                }());
  for (auto& T : half.patch_transforms) {
    const Eigen::Matrix3d A = T.leftCols<3>();
    T.leftCols<3>() =
        Eigen::Matrix3d(Eigen::AngleAxisd(0.5 * Eigen::AngleAxisd(A).angle(), Eigen::AngleAxisd(A).axis()));
    T.col(3) *= 0.5;
  }
  scene.frames = {half, targets};
  return scene;
}

Scene transformed(const Scene& in, const Similarity& g) {
  Scene out = in;
  for (Index v = 0; v < out.model.V.rows(); ++v)
    out.model.V.row(v) = g.apply(in.model.V.row(v).transpose()).transpose();
  for (HandleTargets& f : out.frames) {
    for (Index i = 0; i < f.points.rows(); ++i) f.points.row(i) = g.apply(f.points.row(i).transpose()).transpose();
    for (auto& T : f.patch_transforms) {  // y ↦ g(A·g⁻¹(y) + b)
      const Eigen::Matrix3d A = g.R * T.leftCols<3>() * g.R.transpose();
      const Eigen::Vector3d b = g.s * (g.R * T.col(3)) + g.t - A * g.t;
      T.leftCols<3>() = A;
      T.col(3) = b;
    }
  }
  return out;
}

// Vertex v of `in` becomes vertex perm[v]; the proxies are given (the
// automatic ones start from the lowest index).
Scene renumbered(const Scene& in, const std::vector<Index>& perm) {
  Scene out = in;
  const Index n = in.model.V.rows();
  for (Index v = 0; v < n; ++v) out.model.V.row(perm[v]) = in.model.V.row(v);
  auto remap = [&](auto& E) {
    for (Index i = 0; i < E.size(); ++i) E.data()[i] = static_cast<int>(perm[E.data()[i]]);
  };
  remap(out.model.F);
  remap(out.model.T);
  if (!in.model.is_tet() && !in.model.clusters.empty()) {
    for (Index v = 0; v < n; ++v) out.model.clusters[perm[v]] = in.model.clusters[v];
  }
  std::vector<std::vector<Index>> groups = in.model.linear.groups;
  for (auto& g : groups) {
    for (Index& v : g) v = perm[v];
    std::sort(g.begin(), g.end());
  }
  out.model.linear = linear_proxies_from_groups(groups, n);
  for (Index v = 0; v < n; ++v) out.model.patch_of_vertex[perm[v]] = in.model.patch_of_vertex[v];
  for (PointHandle& h : out.handles.points)
    for (Index& v : h.vertices) v = perm[v];
  return out;
}

struct Result {
  std::string precompute, constraints, frame;  // status and message
  Vertices pose, refined;
  double energy = 0.0, refined_energy = 0.0, classic = 0.0;
};

std::string said(const qpreduce::Outcome& o) { return std::string(to_string(o.status)) + ": " + o.message; }

DeformerOptions options(bool double_basis = false) {
  DeformerOptions o;
  o.double_basis = double_basis;
  o.rotational_proxies = 10;
  o.linear_proxies = 12;
  // Rounds to a tolerance with no time budget: the same rounds whatever the
  // machine, and a converged pose. (A fixed count of float rounds with no
  // tolerance ends on an iterate that carries the float products' noise:
  // 40 rounds agree to 6.7·10⁻⁷ of the diagonal only.)
  o.time_budget = 0.0;
  o.tolerance = 1e-13;
  o.iterations = 1000;
  return o;
}

Result run(const Scene& scene, bool refine, const Vertices* refine_from = nullptr, bool double_basis = false) {
  Result out;
  Deformer deformer;
  out.precompute = said(deformer.precompute(scene.model, options(double_basis)));
  if (!deformer.ready()) return out;
  out.constraints = said(deformer.set_handles(scene.handles));
  for (const HandleTargets& f : scene.frames) {
    const FrameSummary fs = deformer.frame(f, &out.pose);
    out.frame = said(fs);
    out.energy = fs.model_energy;
  }
  if (refine) {
    Refiner refiner;
    refiner.precompute(scene.model);
    const RefineSummary rs =
        refiner.refine(scene.handles, scene.frames.back(), refine_from ? *refine_from : out.pose, &out.refined);
    out.frame += " / refine " + said(rs);
    out.refined_energy = rs.energy;
    // Classic ARAP of the refined pose, from elements built on the given mesh.
    const RotationElements given = scene.model.is_tet() ? tet_elements(scene.model.V, scene.model.T)
                                                        : spokes_and_rims_elements(scene.model.V, scene.model.F);
    out.classic = arap_energy(scene.model.V, given, out.refined);
  }
  return out;
}

double diagonal(const Vertices& V) { return (V.colwise().maxCoeff() - V.colwise().minCoeff()).norm(); }

Vertices moved(const Vertices& V, const Similarity& g, const std::vector<Index>* perm = nullptr) {
  Vertices out(V.rows(), 3);
  for (Index v = 0; v < V.rows(); ++v) out.row(perm ? (*perm)[v] : v) = g.apply(V.row(v).transpose()).transpose();
  return out;
}

// Largest |g⁻¹(moved_v) − base_v| over the vertices, over the base's diagonal.
double distance_back(const Vertices& base, const Vertices& moved, const Similarity& g,
                     const std::vector<Index>* perm = nullptr) {
  double worst = 0.0;
  for (Index v = 0; v < base.rows(); ++v) {
    const Index w = perm ? (*perm)[v] : v;
    worst = std::max(worst, (g.invert(moved.row(w).transpose()) - base.row(v).transpose()).norm());
  }
  return worst / diagonal(base);
}

// The reduced rounds converge to the fixed point of double rounds (float
// products relative to a double reference). Scaled or renumbered, the scene
// is the same in the frame to the last bits, and so is the reduced pose:
// the 10⁻⁹ of the diagonal (measured ≤ 4·10⁻¹⁶). Moved rigidly, the
// frame's coordinates differ in their last bits, and the float
// reconstruction basis (B in float, V′ = B·w) rounds each placement in its
// own way: a few float roundings of the diagonal (2⁻²⁴ ≈ 6·10⁻⁸; measured
// ≤ 1.9·10⁻⁷). The refine's safeguard treats energies within round-off as
// equal (kEnergyRoundOff), so its rounds take the same steps at every scale
// and place (measured ≤ 4·10⁻¹³); it stops at its reference test (steps of
// 10⁻¹⁰ of the diagonal), which the moved tets pass one round earlier than
// the base (measured 3.2·10⁻¹⁰). With the basis in double
// (DeformerOptions::double_basis) the moved reduced pose meets 10⁻⁹ too.
constexpr double kReducedTolerance = 1e-9;
constexpr double kFloatReconstructionTolerance = 1e-6;
constexpr double kRefinedTolerance = 1e-9;

// The sanitizer build tries every other power (-30, -18, …, 30) and the
// references at the two extremes: the same checks on fewer scales.
#ifdef QPREDUCE_SANITIZER_BUILD
constexpr int kPowerStep = 12;
const std::vector<int> kReferencePowers = {-30, 30};
#else
constexpr int kPowerStep = 6;
const std::vector<int> kReferencePowers = {-30, -12, 9, 30};
#endif

}  // namespace

TEST_CASE("units: a scene scaled by 10^k, k in -30…30, deforms to the same pose scaled", "[deformer][units]") {
  for (const bool tet : {false, true}) {
    for (const bool points : {false, true}) {
      const Scene base_scene = make_scene(tet, points);
      const Result base = run(base_scene, true);
      INFO((tet ? "tets" : "triangles") << (points ? " with point handles" : ""));
      INFO(base.precompute << " | " << base.constraints << " | " << base.frame);
      REQUIRE(base.pose.rows() == base_scene.model.V.rows());
      for (int k = -30; k <= 30; k += kPowerStep) {
        Similarity g;
        g.s = std::pow(10.0, k);
        const Vertices start = moved(base.pose, g);  // the refine from the same pose, moved
        const Result o = run(transformed(base_scene, g), true, &start);
        INFO("scale 1e" << k << ": " << o.precompute << " | " << o.constraints << " | " << o.frame);
        CHECK(o.precompute == base.precompute);
        CHECK(o.constraints == base.constraints);
        REQUIRE(o.pose.rows() == base.pose.rows());
        CHECK(distance_back(base.pose, o.pose, g) <= kReducedTolerance);
        CHECK(distance_back(base.refined, o.refined, g) <= kRefinedTolerance);
        // Energies in the given units, homogeneous in the lengths: degree 2
        // on triangles, 3 on tets.
        const double unit = std::pow(g.s, tet ? 3 : 2);
        if (std::isfinite(base.energy)) CHECK(std::abs(o.energy / unit - base.energy) <= 1e-6 * base.energy);
        CHECK(std::abs(o.classic / unit - base.classic) <= 1e-8 * base.classic);
        CHECK(std::abs(o.refined_energy - o.classic) <= 1e-9 * o.classic);
      }
    }
  }
}

TEST_CASE("units: coordinates far beyond 1e30 are the same problem (targets judged in the rest pose's frame)",
          "[deformer][units]") {
  // kMaxCoordinate bounds what can be normalised (1e100), and targets are
  // judged by their reach in the rest pose's frame (kMaxReach diagonals), so
  // a scene whose coordinates pass 1e30 (which was refused) deforms as at
  // unit size; a target beyond kMaxReach diagonals is refused at any scale.
  const Scene base_scene = make_scene(false, true);
  const Result base = run(base_scene, false);
  REQUIRE(base.pose.rows() == base_scene.model.V.rows());
  for (const double s : {1e31, 1e60, 1e90}) {
    Similarity g;
    g.s = s;
    const Scene scaled = transformed(base_scene, g);
    REQUIRE(scaled.model.V.cwiseAbs().maxCoeff() > 1e30);
    const Result o = run(scaled, false);
    INFO("scale " << s << ": " << o.precompute << " | " << o.constraints << " | " << o.frame);
    CHECK(o.precompute == base.precompute);
    CHECK(o.constraints == base.constraints);
    REQUIRE(o.pose.rows() == base.pose.rows());
    CHECK(distance_back(base.pose, o.pose, g) <= kReducedTolerance);
    // The same far target, relative to the mesh, is refused at either scale.
    for (const double scale : {1.0, s}) {
      Similarity h;
      h.s = scale;
      Scene far = transformed(base_scene, h);
      Deformer deformer;
      REQUIRE(deformer.precompute(far.model, options()).ok());
      REQUIRE(deformer.set_handles(far.handles).ok());
      HandleTargets t = far.frames.back();
      t.points(0, 0) = 1e31 * scale;  // about 10^31 diagonals away
      Vertices out;
      CHECK_THROWS_WITH(deformer.frame(t, &out), Catch::Contains("a point handle's target reaches") &&
                                                     Catch::Contains("beyond 1e+30 diagonals"));
    }
  }
}

TEST_CASE("units: a rigidly moved scene deforms to the same pose moved", "[deformer][units]") {
  std::mt19937 rng(11);
  std::normal_distribution<double> normal;
  for (const bool tet : {false, true}) {
    Scene base_scene = make_scene(tet, true);
    // The proxies given, so that the same ones serve every placement.
    Deformer probe;
    REQUIRE(probe.precompute(base_scene.model, options()).ok());
    base_scene.model.clusters = probe.clusters();
    base_scene.model.linear = linear_proxies_fps(
        base_scene.model.V, tet ? ElementsRef(base_scene.model.T) : ElementsRef(base_scene.model.F), 12);
    const Result base = run(base_scene, true);
    INFO((tet ? "tets: " : "triangles: ") << base.precompute << " | " << base.constraints << " | " << base.frame);
    for (int trial = 0; trial < 3; ++trial) {
      Similarity g;
      g.R = Eigen::Quaterniond(normal(rng), normal(rng), normal(rng), normal(rng)).normalized().toRotationMatrix();
      g.t = 5.0 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng));
      const Vertices start = moved(base.pose, g);
      const Scene placed = transformed(base_scene, g);
      const Result o = run(placed, true, &start);
      INFO("trial " << trial << ": " << o.constraints << " | " << o.frame);
      CHECK(o.constraints == base.constraints);
      CHECK(distance_back(base.pose, o.pose, g) <= kFloatReconstructionTolerance);
      // The refine from the reduced pose of this placement, not the base's
      // moved: the whole product, end to end.
      {
        Vertices refined_own;
        Refiner refiner;
        refiner.precompute(placed.model);
        REQUIRE(refiner.refine(placed.handles, placed.frames.back(), o.pose, &refined_own).ok());
        CHECK(distance_back(base.refined, refined_own, g) <= kRefinedTolerance);
      }
      CHECK(distance_back(base.refined, o.refined, g) <= kRefinedTolerance);
    }
  }
}

TEST_CASE("units: with the basis in double a rigidly moved scene deforms to its pose moved to 1e-9",
          "[deformer][units]") {
  std::mt19937 rng(11);
  std::normal_distribution<double> normal;
  for (const bool tet : {false, true}) {
    Scene base_scene = make_scene(tet, true);
    Deformer probe;
    REQUIRE(probe.precompute(base_scene.model, options(true)).ok());
    REQUIRE(probe.double_basis());
    CHECK(probe.reconstruction_basis().size() == 0);
    base_scene.model.clusters = probe.clusters();
    base_scene.model.linear = linear_proxies_fps(
        base_scene.model.V, tet ? ElementsRef(base_scene.model.T) : ElementsRef(base_scene.model.F), 12);
    const Result base = run(base_scene, false, nullptr, true);
    const Result in_float = run(base_scene, false);
    INFO((tet ? "tets: " : "triangles: ") << base.precompute << " | " << base.constraints << " | " << base.frame);
    // The same fixed point as the float basis's, up to its round-off.
    CHECK(distance_back(in_float.pose, base.pose, Similarity{}) <= kFloatReconstructionTolerance);
    double worst = 0.0;
    for (int trial = 0; trial < 3; ++trial) {
      Similarity g;
      g.R = Eigen::Quaterniond(normal(rng), normal(rng), normal(rng), normal(rng)).normalized().toRotationMatrix();
      g.t = 5.0 * Eigen::Vector3d(normal(rng), normal(rng), normal(rng));
      const Result o = run(transformed(base_scene, g), false, nullptr, true);
      INFO("trial " << trial << ": " << o.constraints << " | " << o.frame);
      CHECK(o.constraints == base.constraints);
      CHECK(o.frame == base.frame);
      worst = std::max(worst, distance_back(base.pose, o.pose, g));
    }
    INFO("largest distance over the diagonal " << worst);
    CHECK(worst <= kReducedTolerance);
  }
}

TEST_CASE("units: renumbering the vertices renumbers the pose", "[deformer][units]") {
  for (const bool tet : {false, true}) {
    Scene base_scene = make_scene(tet, true);
    Deformer probe;
    REQUIRE(probe.precompute(base_scene.model, options()).ok());
    base_scene.model.clusters = probe.clusters();
    const Index n = base_scene.model.V.rows();
    base_scene.model.linear = linear_proxies_fps(
        base_scene.model.V, tet ? ElementsRef(base_scene.model.T) : ElementsRef(base_scene.model.F), 12);
    std::vector<Index> perm(static_cast<size_t>(n));
    std::iota(perm.begin(), perm.end(), Index(0));
    std::shuffle(perm.begin(), perm.end(), std::mt19937(5));
    const Result base = run(base_scene, true);
    const Vertices start = moved(base.pose, Similarity{}, &perm);
    const Result o = run(renumbered(base_scene, perm), true, &start);
    INFO((tet ? "tets: " : "triangles: ") << base.constraints << " | " << o.constraints);
    CHECK(o.constraints == base.constraints);
    CHECK(distance_back(base.pose, o.pose, Similarity{}, &perm) <= kReducedTolerance);
    CHECK(distance_back(base.refined, o.refined, Similarity{}, &perm) <= kRefinedTolerance);
  }
}

TEST_CASE("units: the full-space references (qpr compare's) answer the same at any scale", "[deformer][units]") {
  for (const bool tet : {false, true}) {
    const Scene scene = make_scene(tet, true);
    ReferenceOptions ro;
    ro.max_iterations = 60;  // a fixed amount of work: the same rounds at every scale
    ro.step_tolerance = 0.0;
    ro.energy_tolerance = 0.0;
    ReferenceSolution base_lg, base_ceres;
    const ReferenceSummary lg = solve_local_global(scene.model, scene.handles, scene.frames.back(), ro, &base_lg);
    INFO((tet ? "tets: " : "triangles: ") << lg.message);
    REQUIRE(lg.ok());
    ReferenceSummary ceres;
    if (has_ceres_reference()) {
      ceres = solve_ceres_reference(scene.model, scene.handles, scene.frames.back(), ReferenceOptions{}, &base_ceres);
      REQUIRE(ceres.ok());
    }
    for (const int k : kReferencePowers) {
      Similarity g;
      g.s = std::pow(10.0, k);
      const Scene scaled = transformed(scene, g);
      const double unit = std::pow(g.s, tet ? 3 : 2);
      INFO("scale 1e" << k);
      ReferenceSolution o;
      const ReferenceSummary s = solve_local_global(scaled.model, scaled.handles, scaled.frames.back(), ro, &o);
      CHECK(s.iterations == lg.iterations);
      CHECK(distance_back(base_lg.V, o.V, g) <= 1e-9);
      CHECK(std::abs(s.energy / unit - lg.energy) <= 1e-9 * lg.energy);
      CHECK(s.handle_residual / g.s <= 1e-9 * diagonal(scene.model.V));
      {
        // The class itself (the Refiner's engine), from a given pose: its
        // energies, elements and pose in the given units.
        LocalGlobalArap direct;
        direct.precompute(scaled.model, ro);
        REQUIRE(direct.set_handles(scaled.handles).ok());
        ReferenceSolution od;
        const ReferenceSummary d = direct.solve(scaled.frames.back(), &od, scaled.model.V);
        CHECK(d.iterations == lg.iterations);
        CHECK(distance_back(base_lg.V, od.V, g) <= 1e-9);
        CHECK(std::abs(d.energy / unit - lg.energy) <= 1e-9 * lg.energy);
        CHECK(std::abs(arap_energy(scaled.model.V, direct.elements(), od.V) - d.energy) <= 1e-9 * d.energy);
      }
      if (!has_ceres_reference()) continue;
      const ReferenceSummary c =
          solve_ceres_reference(scaled.model, scaled.handles, scaled.frames.back(), ReferenceOptions{}, &o);
      CHECK(c.ok());
      // Ceres stops at its relative function tolerance (1e-15), where the
      // energy is flat: the pose is fixed only to about √1e-15 ≈ 3·10⁻⁸ of
      // the diagonal (measured up to 6·10⁻⁸), its energy to 1e-9.
      CHECK(distance_back(base_ceres.V, o.V, g) <= 1e-7);
      CHECK(std::abs(c.energy / unit - ceres.energy) <= 1e-9 * ceres.energy);
    }
  }
}

}  // namespace units_test
