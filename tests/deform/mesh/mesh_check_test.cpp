// Pre-flight diagnostics (src/mesh/mesh_check.cpp): each defect class on a
// small mesh built here, the argument checks, the duplicate search against a
// brute-force one, and the shared meshes (no errors; the README's counts of
// unreferenced vertices). The shared cases skip when ../shared is absent.
#include <catch2/catch.hpp>

#include <variant>

#include "../io/io_test_util.h"  // shared_data(), REQUIRE_SHARED_DATA

#include "qpreduce/deform/io/handles_io.h"
#include "qpreduce/deform/io/mesh_io.h"
#include "qpreduce/deform/io/tet_io.h"
#include "qpreduce/deform/mesh/mesh_check.h"
#include "qpreduce/deform/mesh/shapes.h"

#include <cmath>
#include <random>
#include <utility>
#include <stdexcept>
#include <string>
#include <vector>

using namespace qpreduce;
using namespace qpreduce::deform;

namespace {

// The finding of `defect`, or nullptr.
const MeshFinding* find(const MeshCheckSummary& s, MeshDefect defect) {
  for (const MeshFinding& f : s.findings)
    if (f.defect == defect) return &f;
  return nullptr;
}

// The defects found, in report order.
std::vector<MeshDefect> defects(const MeshCheckSummary& s) {
  std::vector<MeshDefect> out;
  for (const MeshFinding& f : s.findings) out.push_back(f.defect);
  return out;
}

// The unit square [0, 1]² in z = 0 as two triangles (vertices 0..3), shifted by `dx` in x.
TriangleMesh square(double dx = 0.0) {
  TriangleMesh m;
  m.V.resize(4, 3);
  m.V << dx, 0, 0, dx + 1, 0, 0, dx + 1, 1, 0, dx, 1, 0;
  m.F.resize(2, 3);
  m.F << 0, 1, 2, 0, 2, 3;
  return m;
}

// A closed, outward tetrahedron surface.
TriangleMesh tetrahedron_surface() {
  TriangleMesh m;
  m.V.resize(4, 3);
  m.V << 1, 1, 1, 1, -1, -1, -1, 1, -1, -1, -1, 1;
  m.F.resize(4, 3);
  m.F << 0, 1, 2, 0, 3, 1, 0, 2, 3, 1, 3, 2;
  return m;
}

// Appends a vertex and returns its index.
Index add_vertex(Vertices* V, double x, double y, double z) {
  V->conservativeResize(V->rows() + 1, 3);
  V->row(V->rows() - 1) << x, y, z;
  return V->rows() - 1;
}

// Two tets on the face (0, 1, 2): V0..V3 the corner of the unit cube, V4 = −e_z.
Vertices two_tet_vertices() {
  Vertices V(5, 3);
  V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, -1;
  return V;
}

// `a` and a copy of `b` moved so that b's vertex `at_b` lies on a's vertex
// `at_a`, and merged into it: two solids sharing exactly that vertex.
TetMesh glued_at_vertex(const TetMesh& a, Index at_a, const TetMesh& b, Index at_b) {
  const Index na = a.V.rows();
  TetMesh m;
  m.V.resize(na + b.V.rows() - 1, 3);
  m.V.topRows(na) = a.V;
  const Eigen::RowVector3d shift = a.V.row(at_a) - b.V.row(at_b);
  std::vector<int> index(static_cast<size_t>(b.V.rows()));
  for (Index v = 0, next = na; v < b.V.rows(); ++v) {
    if (v == at_b) {
      index[v] = static_cast<int>(at_a);
      continue;
    }
    m.V.row(next) = b.V.row(v) + shift;
    index[v] = static_cast<int>(next++);
  }
  m.T.resize(a.T.rows() + b.T.rows(), 4);
  m.T.topRows(a.T.rows()) = a.T;
  for (Index t = 0; t < b.T.rows(); ++t)
    for (int k = 0; k < 4; ++k) m.T(a.T.rows() + t, k) = index[static_cast<size_t>(b.T(t, k))];
  return m;
}

}  // namespace

TEST_CASE("clean small meshes have no findings", "[mesh_check]") {
  const TriangleMesh sq = square(), closed = tetrahedron_surface();
  for (const TriangleMesh* m : {&sq, &closed}) {
    const MeshCheckSummary s = diagnose_mesh(m->V, m->F);
    CHECK(s.verdict == MeshCheckStatus::Clean);
    CHECK(s.findings.empty());
    CHECK(s.components == 1);
    CHECK_FALSE(s.anchors_checked);
    CHECK(s.worst_quality > 0.5);
  }
  const MeshCheckSummary s = diagnose_mesh(sq.V, sq.F);
  CHECK(s.diagonal == Approx(std::sqrt(2.0)));
  CHECK(s.shortest_edge == Approx(1.0));
  CHECK(s.longest_edge == Approx(std::sqrt(2.0)));
  Tetrahedra T(2, 4);
  T << 0, 1, 2, 3, 0, 2, 1, 4;
  const MeshCheckSummary t = diagnose_mesh(two_tet_vertices(), T);
  CHECK(t.verdict == MeshCheckStatus::Clean);
  CHECK(t.corners == 4);
}

TEST_CASE("a sliver triangle is a warning naming it, a zero-area one an error", "[mesh_check]") {
  TriangleMesh m = square();
  const Index apex = add_vertex(&m.V, 0.5, -1e-5, 0);
  m.F.conservativeResize(3, 3);
  m.F.row(2) << 0, static_cast<int>(apex), 1;
  MeshCheckSummary s = diagnose_mesh(m.V, m.F);
  CHECK(s.verdict == MeshCheckStatus::Warnings);
  REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::NearDegenerateElement});
  const MeshFinding& thin = s.findings[0];
  // The check ran (the Outcome's status); the finding is its message.
  CHECK(s.ok());
  CHECK(s.message == thin.message);
  CHECK(std::get<std::string>(*s.report().find("verdict")) == "warnings");
  CHECK(thin.severity == CheckSeverity::Warning);
  CHECK(thin.count == 1);
  CHECK(thin.first == std::vector<std::vector<Index>>{{2}});
  CHECK_THAT(thin.message, Catch::Contains("triangle 2 (vertices 0, 4, 1) is nearly degenerate"));
  CHECK(s.worst_quality == Approx(2e-5 / std::sqrt(3.0)).epsilon(1e-6));

  SECTION("collinear corners") {
    m.V(apex, 1) = 0.0;
    s = diagnose_mesh(m.V, m.F);
    CHECK(s.verdict == MeshCheckStatus::Errors);
    REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::DegenerateElement});
    CHECK_THAT(s.findings[0].message, Catch::Contains("triangle 2 (vertices 0, 4, 1) is degenerate: area 0"));
  }
  SECTION("a repeated corner") {
    m.F.row(2) << 0, 1, 1;
    s = diagnose_mesh(m.V, m.F);
    REQUIRE(find(s, MeshDefect::DegenerateElement));
    CHECK_THAT(find(s, MeshDefect::DegenerateElement)->message, Catch::Contains("triangle 2 repeats a corner"));
  }
}

TEST_CASE("counts cover every offender, the list stops at max_listed", "[mesh_check]") {
  TriangleMesh m = square();
  const int slivers = 25;
  for (int i = 0; i < slivers; ++i) {
    const int a = static_cast<int>(add_vertex(&m.V, 2 + i, 0, 0)), b = static_cast<int>(add_vertex(&m.V, 3 + i, 0, 0));
    const int c = static_cast<int>(add_vertex(&m.V, 2.5 + i, 1e-7, 0));
    m.F.conservativeResize(m.F.rows() + 1, 3);
    m.F.row(m.F.rows() - 1) << a, b, c;
  }
  MeshCheckOptions o;
  o.max_listed = 4;
  const MeshCheckSummary s = diagnose_mesh(m.V, m.F, {}, o);
  const MeshFinding* thin = find(s, MeshDefect::NearDegenerateElement);
  REQUIRE(thin);
  CHECK(thin->count == slivers);
  CHECK(thin->first == std::vector<std::vector<Index>>{{2}, {3}, {4}, {5}});
  CHECK_THAT(thin->message, Catch::Contains("(25 triangles in all)"));
  CHECK(s.components == 1 + slivers);
}

TEST_CASE("duplicate vertices: exact and within the tolerance, not beyond", "[mesh_check]") {
  TriangleMesh m = square();
  const Index twin = add_vertex(&m.V, 1, 1, 0);  // at vertex 2
  m.F.row(1) << 0, static_cast<int>(twin), 3;    // the second triangle uses the copy: a seam
  MeshCheckSummary s = diagnose_mesh(m.V, m.F);
  const MeshFinding* dup = find(s, MeshDefect::DuplicateVertex);
  REQUIRE(dup);
  CHECK(dup->count == 1);
  CHECK(dup->first == std::vector<std::vector<Index>>{{twin}});
  CHECK_THAT(dup->message, Catch::Contains("vertex 4 lies at the position of vertex 2"));
  CHECK(s.verdict == MeshCheckStatus::Warnings);

  m.V(twin, 0) += 0.5e-10 * std::sqrt(2.0);  // half the tolerance
  CHECK(find(diagnose_mesh(m.V, m.F), MeshDefect::DuplicateVertex));
  m.V(twin, 0) += 1e-10 * std::sqrt(2.0);  // 1.5 times the tolerance
  CHECK_FALSE(find(diagnose_mesh(m.V, m.F), MeshDefect::DuplicateVertex));
}

TEST_CASE("the grid search for duplicates agrees with comparing every pair", "[mesh_check]") {
  std::mt19937 rng(20);
  std::uniform_real_distribution<double> unit(0.0, 1.0), inside(0.01, 0.99);
  for (int trial = 0; trial < 5; ++trial) {
    const int n = 400;
    Vertices V(n, 3);
    for (int i = 0; i < n; ++i) V.row(i) << inside(rng), inside(rng), inside(rng);
    V.row(0) << 0, 0, 0;
    V.row(1) << 1, 1, 1;  // the box is the unit cube, whatever was drawn
    MeshCheckOptions o;
    o.duplicate_distance = 1e-3;
    const double r = o.duplicate_distance * std::sqrt(3.0);
    // Plant copies of earlier vertices at distances 0.1 r … 1.9 r in random directions.
    for (int i = 200; i < n; i += 3) {
      Eigen::RowVector3d d(unit(rng) - 0.5, unit(rng) - 0.5, unit(rng) - 0.5);
      V.row(i) = V.row(i - 150) + (0.1 + 1.8 * unit(rng)) * r * d.normalized();
    }
    Tetrahedra all(n / 4, 4);  // reference every vertex so that only duplicates are found
    for (int e = 0; e < n / 4; ++e) all.row(e) << 4 * e, 4 * e + 1, 4 * e + 2, 4 * e + 3;
    std::vector<Index> expected;
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < i; ++j)
        if ((V.row(i) - V.row(j)).norm() <= r) {
          expected.push_back(i);
          break;
        }
    o.max_listed = n;
    const MeshCheckSummary s = diagnose_mesh(V, all, {}, o);
    const MeshFinding* dup = find(s, MeshDefect::DuplicateVertex);
    std::vector<Index> found;
    if (dup)
      for (const auto& f : dup->first) found.push_back(f[0]);
    INFO("trial " << trial);
    CHECK(!expected.empty());
    CHECK(found == expected);
  }
}

TEST_CASE("unreferenced vertices: far away an error naming the distance, near a warning", "[mesh_check]") {
  TriangleMesh m = square();
  const Index far = add_vertex(&m.V, 1 + 1.7 * std::sqrt(2.0), 0.5, 0);  // 1.7 diagonals right of the box
  const Index near = add_vertex(&m.V, 0.5, 0.5, 0.3);
  const MeshCheckSummary s = diagnose_mesh(m.V, m.F);
  CHECK(s.verdict == MeshCheckStatus::Errors);
  REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::FarUnreferencedVertex, MeshDefect::UnreferencedVertex});
  CHECK(s.findings[0].first == std::vector<std::vector<Index>>{{far}});
  CHECK_THAT(s.findings[0].message,
             Catch::Contains("vertex 4 is referenced by no element and lies 1.7 bounding-box diagonals away"));
  CHECK(s.findings[1].first == std::vector<std::vector<Index>>{{near}});
  CHECK(s.findings[1].severity == CheckSeverity::Warning);
  // The scale is the referenced vertices': the far vertex does not stretch it.
  CHECK(s.diagonal == Approx(std::sqrt(2.0)));
  CHECK(s.components == 1);
}

TEST_CASE("an edge in three triangles is non-manifold, a bow-tie vertex too", "[mesh_check]") {
  SECTION("three triangles on edge (0, 1)") {
    TriangleMesh m;
    m.V.resize(5, 3);
    m.V << 0, 0, 0, 1, 0, 0, 0.5, 1, 0, 0.5, -1, 0, 0.5, 0, 1;
    m.F.resize(3, 3);
    m.F << 0, 1, 2, 1, 0, 3, 0, 1, 4;
    const MeshCheckSummary s = diagnose_mesh(m.V, m.F);
    REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::NonManifoldEdge});
    CHECK(s.findings[0].first == std::vector<std::vector<Index>>{{0, 1}});
    CHECK_THAT(s.findings[0].message, Catch::Contains("edge (0, 1) is shared by 3 triangles"));
    CHECK(s.verdict == MeshCheckStatus::Warnings);
  }
  SECTION("two triangles meeting at one vertex") {
    TriangleMesh m;
    m.V.resize(5, 3);
    m.V << 0, 0, 0, 1, 0, 0, 1, 1, 0, -1, 0, 0, -1, -1, 0;
    m.F.resize(2, 3);
    m.F << 0, 1, 2, 0, 3, 4;
    const MeshCheckSummary s = diagnose_mesh(m.V, m.F);
    REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::NonManifoldVertex});
    CHECK(s.findings[0].first == std::vector<std::vector<Index>>{{0}});
    CHECK_THAT(s.findings[0].message, Catch::Contains("vertex 0 joins 2 separate fans"));
    CHECK(s.components == 1);  // sharing a vertex couples the Laplacian
  }
  SECTION("a closed fan around a vertex is manifold") {
    const TriangleMesh m = tetrahedron_surface();
    CHECK(diagnose_mesh(m.V, m.F).findings.empty());
  }
}

TEST_CASE("triangles oriented against their neighbours are counted and named, a Möbius strip is not orientable",
          "[mesh_check]") {
  const TriangleMesh tube = shapes::capped_cylinder(1.0, 2.0, 16, 6);
  const Index m = tube.F.rows();
  const auto flipped_copy = [&](auto flip) {
    TriangleMesh t = tube;
    for (Index f = 0; f < m; ++f)
      if (flip(f)) std::swap(t.F(f, 1), t.F(f, 2));
    return t;
  };
  CHECK_FALSE(find(diagnose_mesh(tube.V, tube.F), MeshDefect::InconsistentOrientation));
  // All flipped (inward normals) is consistent too.
  const TriangleMesh inward = flipped_copy([](Index) { return true; });
  CHECK_FALSE(find(diagnose_mesh(inward.V, inward.F), MeshDefect::InconsistentOrientation));

  const TriangleMesh one = flipped_copy([](Index f) { return f == 7; });
  const MeshCheckSummary s1 = diagnose_mesh(one.V, one.F);
  const MeshFinding* f1 = find(s1, MeshDefect::InconsistentOrientation);
  REQUIRE(f1);
  CHECK(f1->severity == CheckSeverity::Warning);
  CHECK(s1.verdict == MeshCheckStatus::Warnings);
  CHECK(f1->count == 1);
  CHECK(f1->first == std::vector<std::vector<Index>>{{7}});
  CHECK_THAT(f1->message, Catch::Contains("triangle 7 (vertices") && Catch::Contains("oriented against") &&
                              Catch::Contains("3 of the"));
  CHECK(std::string(to_string(f1->defect)) == "inconsistent_orientation");

  // Every other triangle flipped: the smaller class (here the odd ones, a
  // tie broken against triangle 0's class) is the count.
  const TriangleMesh half = flipped_copy([](Index f) { return f % 2 == 1; });
  const MeshCheckSummary sh = diagnose_mesh(half.V, half.F);
  const MeshFinding* fh = find(sh, MeshDefect::InconsistentOrientation);
  REQUIRE(fh);
  CHECK(fh->count == m / 2);
  CHECK(fh->first.front() == std::vector<Index>{1});
  CHECK(static_cast<Index>(fh->first.size()) == MeshCheckOptions{}.max_listed);
  CHECK_THAT(fh->message, !Catch::Contains("not orientable"));

  // A Möbius strip: locally consistent everywhere but along one rung, and no
  // flip fixes it.
  const int N = 12;
  TriangleMesh strip;
  strip.V.resize(2 * N, 3);
  for (int i = 0; i < N; ++i) {
    const double t = 2 * M_PI * i / N;
    for (int side = 0; side < 2; ++side) {
      const double w = side == 0 ? 0.3 : -0.3;
      strip.V.row(2 * i + side) << (1 + w * std::cos(t / 2)) * std::cos(t), (1 + w * std::cos(t / 2)) * std::sin(t),
          w * std::sin(t / 2);
    }
  }
  strip.F.resize(2 * N, 3);
  for (int i = 0; i < N; ++i) {
    const Index top = 2 * i, bottom = 2 * i + 1;
    // After the half twist the strip meets its start upside down.
    const Index next_top = i + 1 < N ? 2 * (i + 1) : 1, next_bottom = i + 1 < N ? 2 * (i + 1) + 1 : 0;
    strip.F.row(2 * i) << top, bottom, next_bottom;
    strip.F.row(2 * i + 1) << top, next_bottom, next_top;
  }
  const MeshCheckSummary ms = diagnose_mesh(strip.V, strip.F);
  const MeshFinding* fm = find(ms, MeshDefect::InconsistentOrientation);
  REQUIRE(fm);
  CHECK(fm->count >= 1);
  CHECK_THAT(fm->message, Catch::Contains("not orientable"));
  CHECK_FALSE(ms.has_errors());
}

TEST_CASE("tets: inverted, all inverted, degenerate, a face in three tets", "[mesh_check]") {
  Vertices V = two_tet_vertices();
  Tetrahedra T(2, 4);
  SECTION("one of two inverted") {
    T << 0, 1, 2, 3, 0, 1, 2, 4;
    const MeshCheckSummary s = diagnose_mesh(V, T);
    REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::InvertedTet});
    CHECK(s.findings[0].first == std::vector<std::vector<Index>>{{1}});
    CHECK_THAT(s.findings[0].message, Catch::Contains("tet 1 is inverted"));
    CHECK_THAT(s.findings[0].message, Catch::Contains("1 of the 2 tets are positive"));
  }
  SECTION("all inverted: the opposite convention") {
    T << 0, 2, 1, 3, 0, 1, 2, 4;
    const MeshCheckSummary s = diagnose_mesh(V, T);
    REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::InvertedTet});
    CHECK(s.findings[0].count == 2);
    CHECK_THAT(s.findings[0].message, Catch::Contains("every tet is negatively oriented"));
  }
  SECTION("a flat tet") {
    const Index flat = add_vertex(&V, 0.3, 0.3, 0);
    T << 0, 1, 2, 3, 0, 1, 2, static_cast<int>(flat);
    const MeshCheckSummary s = diagnose_mesh(V, T);
    REQUIRE(s.has_errors());
    CHECK(s.findings[0].defect == MeshDefect::DegenerateElement);
    CHECK_THAT(s.findings[0].message, Catch::Contains("tet 1 (vertices 0, 1, 2, 5) is degenerate: volume 0"));
  }
  SECTION("a face in three tets") {
    const Index apex = add_vertex(&V, 0.2, 0.2, 0.5);
    T.resize(3, 4);
    T << 0, 1, 2, 3, 0, 2, 1, 4, 0, 1, 2, static_cast<int>(apex);
    const MeshCheckSummary s = diagnose_mesh(V, T);
    const MeshFinding* f = find(s, MeshDefect::NonManifoldFace);
    REQUIRE(f);
    CHECK(f->first == std::vector<std::vector<Index>>{{0, 1, 2}});
    CHECK_THAT(f->message, Catch::Contains("face (0, 1, 2) is shared by 3 tets"));
  }
}

TEST_CASE("tets: a vertex where pieces of solid share no face is non-manifold", "[mesh_check]") {
  SECTION("two tets touching at one vertex") {
    Vertices V(7, 3);
    V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, -1, 0, 0, 0, -1, 0, 0, 0, -1;
    Tetrahedra T(2, 4);
    T << 0, 1, 2, 3, 0, 5, 4, 6;
    const MeshCheckSummary s = diagnose_mesh(V, T);
    REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::NonManifoldVertex});
    CHECK(s.findings[0].count == 1);
    CHECK(s.findings[0].first == std::vector<std::vector<Index>>{{0}});
    CHECK(s.findings[0].item == "vertex");
    CHECK_THAT(s.findings[0].message, Catch::Contains("vertex 0 joins 2 separate groups of tets"));
    CHECK_THAT(s.findings[0].message, Catch::Contains("the solid is not a manifold there"));
    CHECK(s.verdict == MeshCheckStatus::Warnings);
    CHECK(s.components == 1);  // sharing a vertex couples the Laplacian
  }
  SECTION("two tets sharing only an edge: both its ends") {
    Vertices V = two_tet_vertices();
    const Index p = add_vertex(&V, 0.5, -1, -1);
    Tetrahedra T(2, 4);
    T << 0, 1, 2, 3, 0, 1, static_cast<int>(p), 4;
    const MeshCheckSummary s = diagnose_mesh(V, T);
    REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::NonManifoldVertex});
    CHECK(s.findings[0].count == 2);
    CHECK(s.findings[0].first == std::vector<std::vector<Index>>{{0}, {1}});
    CHECK_THAT(s.findings[0].message, Catch::Contains("(2 vertices in all)"));
  }
  SECTION("two boxes of tets glued at a corner") {
    const TetMesh box = shapes::box_tets(1, 1, 1, 2, 2, 2);
    const Index corner = box.V.rows() - 1;  // (1, 1, 1)
    const TetMesh m = glued_at_vertex(box, corner, box, 0);
    const MeshCheckSummary s = diagnose_mesh(m.V, m.T);
    REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::NonManifoldVertex});
    CHECK(s.findings[0].count == 1);
    CHECK(s.findings[0].first == std::vector<std::vector<Index>>{{corner}});
  }
  SECTION("a cube in six tets and a box of 3 × 3 × 3 cubes (interior vertices) are clean") {
    for (const TetMesh& m : {shapes::box_tets(1, 1, 1, 1, 1, 1), shapes::box_tets(1, 2, 3, 3, 3, 3)}) {
      const MeshCheckSummary s = diagnose_mesh(m.V, m.T);
      CHECK(s.verdict == MeshCheckStatus::Clean);
      CHECK(s.findings.empty());
    }
  }
}

TEST_CASE("components: the unanchored one is named with its size and first vertex", "[mesh_check]") {
  TriangleMesh m = square();
  const TriangleMesh other = square(10.0);
  m.V.conservativeResize(8, 3);
  m.V.bottomRows(4) = other.V;
  m.F.conservativeResize(4, 3);
  m.F.bottomRows(2) = other.F.array() + 4;
  std::vector<char> anchored(8, 0);
  anchored[1] = 1;
  MeshCheckSummary s = diagnose_mesh(m.V, m.F, anchored);
  CHECK(s.components == 2);
  CHECK(s.anchors_checked);
  REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::UnanchoredComponent});
  CHECK(s.findings[0].first == std::vector<std::vector<Index>>{{1}});
  CHECK_THAT(s.findings[0].message,
             Catch::Contains("connected component 1 (4 vertices, first vertex 4) has no handle or fixed region"));
  anchored[6] = 1;
  CHECK(diagnose_mesh(m.V, m.F, anchored).findings.empty());
  CHECK(diagnose_mesh(m.V, m.F).findings.empty());  // no anchors given: not checked
  // The shared helper alone: sizes grouped by thousands.
  MeshComponents big;
  big.count = big.element_components = 2;
  big.vertex_component.assign(1300, 0);
  std::fill(big.vertex_component.begin() + 96, big.vertex_component.end(), 1);
  std::vector<char> held(1300, 0);
  held[0] = 1;
  CHECK_THAT(unanchored_components(big, held).message, Catch::Contains("component 1 (1,204 vertices, first vertex 96)"));
}

TEST_CASE("empty meshes, no elements, NaN and huge coordinates, bad indices get findings, not crashes", "[mesh_check]") {
  SECTION("no vertices") {
    const MeshCheckSummary s = diagnose_mesh(Vertices(0, 3), Triangles(0, 3));
    CHECK(defects(s) == std::vector<MeshDefect>{MeshDefect::NoVertices, MeshDefect::NoElements});
    CHECK(s.verdict == MeshCheckStatus::Errors);
  }
  SECTION("no elements") {
    const MeshCheckSummary s = diagnose_mesh(square().V, Triangles(0, 3));
    REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::NoElements});
    CHECK_THAT(s.findings[0].message, Catch::Contains("no triangles, only 4 vertices"));
  }
  SECTION("NaN and 1e200") {
    TriangleMesh m = square();
    m.V(2, 1) = std::nan("");
    m.V(3, 0) = 1e200;
    const MeshCheckSummary s = diagnose_mesh(m.V, m.F);
    CHECK(defects(s) == std::vector<MeshDefect>{MeshDefect::NonFiniteCoordinate, MeshDefect::CoordinateOverflow});
    CHECK_THAT(s.findings[0].message, Catch::Contains("vertex 2 at (1, nan, 0) has a non-finite coordinate"));
    CHECK_THAT(s.findings[1].message, Catch::Contains("vertex 3 at (1e+200, 1, 0): coordinates beyond 1e+100"));
  }
  SECTION("an index out of range") {
    TriangleMesh m = square();
    m.F(1, 2) = 7;
    const MeshCheckSummary s = diagnose_mesh(m.V, m.F);
    REQUIRE(defects(s) == std::vector<MeshDefect>{MeshDefect::IndexOutOfRange});
    CHECK_THAT(s.findings[0].message, Catch::Contains("triangle 1 has corner 2 = 7, outside the 4 vertices"));
  }
  SECTION("argument errors throw") {
    const TriangleMesh m = square();
    CHECK_THROWS_WITH(diagnose_mesh(m.V, Eigen::MatrixXi::Zero(1, 2)), Catch::Contains("expected 3 or 4 columns, got 2"));
    CHECK_THROWS_WITH(diagnose_mesh(m.V, m.F, std::vector<char>(3, 1)), Catch::Contains("expected 4 flags"));
    MeshCheckOptions o;
    o.near_degenerate_quality = std::nan("");
    CHECK_THROWS_WITH(diagnose_mesh(m.V, m.F, {}, o), Catch::Contains("near_degenerate_quality"));
  }
}

TEST_CASE("errors are listed before warnings", "[mesh_check]") {
  TriangleMesh m = square();
  add_vertex(&m.V, 0.5, 0.5, 0.1);  // unreferenced, near: a warning
  add_vertex(&m.V, 50, 0, 0);       // unreferenced, far: an error
  const MeshCheckSummary s = diagnose_mesh(m.V, m.F);
  REQUIRE(s.findings.size() == 2);
  CHECK(s.findings[0].severity == CheckSeverity::Error);
  CHECK(s.findings[1].severity == CheckSeverity::Warning);
  CHECK(s.first(CheckSeverity::Error) == &s.findings[0]);
}

TEST_CASE("shared meshes: no errors and the README counts of unreferenced vertices", "[mesh_check][data]") {
  REQUIRE_SHARED_DATA(data);
  const std::pair<const char*, Index> surfaces[] = {
      {"meshes/botsch-sorkine/cactus.off", 0},       {"meshes/botsch-sorkine/bumpy_plane.off", 0},
      {"meshes/botsch-sorkine/bar.off", 0},          {"meshes/botsch-sorkine/cylinder.off", 0},
      {"meshes/bunny.off", 0},                       {"meshes/stanford-bunny.obj", 1113},
      {"meshes/armadillo.obj", 0},                   {"paper-examples/dinosaur/dinosaur.off", 0}};
  for (const auto& [path, unreferenced] : surfaces) {
    INFO(path);
    const TriangleMesh m = read_triangle_mesh(data + "/" + path);
    const MeshCheckSummary s = diagnose_mesh(m.V, m.F);
    std::string found;
    for (const MeshFinding& f : s.findings) found += std::string(to_string(f.defect)) + ": " + f.message + "\n";
    INFO(found);
    CHECK_FALSE(s.has_errors());
    const MeshFinding* loose = find(s, MeshDefect::UnreferencedVertex);
    CHECK((loose ? loose->count : 0) == unreferenced);
    CHECK(s.diagonal > 0.0);
  }
  // The one shared mesh with an error: the ogre's zero-area triangles, the
  // first being the one the geometry refuses.
  const TriangleMesh ogre = read_triangle_mesh(data + "/meshes/ogre.obj");
  const MeshCheckSummary os = diagnose_mesh(ogre.V, ogre.F);
  const MeshFinding* flat = find(os, MeshDefect::DegenerateElement);
  REQUIRE(flat);
  REQUIRE(!flat->first.empty());
  const Index first_flat = flat->first[0][0];
  CHECK_THROWS_WITH(face_areas(ogre.V, ogre.F), Catch::Contains("face " + std::to_string(first_flat) + " is degenerate"));
  Triangles rest(ogre.F.rows() - flat->count, 3);  // without them, the geometry accepts the mesh
  std::vector<char> dropped(static_cast<size_t>(ogre.F.rows()), 0);
  for (const auto& f : flat->first) dropped[static_cast<size_t>(f[0])] = 1;
  REQUIRE(flat->count <= static_cast<Index>(flat->first.size()));  // all of them listed
  for (Index f = 0, r = 0; f < ogre.F.rows(); ++f)
    if (!dropped[static_cast<size_t>(f)]) rest.row(r++) = ogre.F.row(f);
  CHECK_NOTHROW(face_areas(ogre.V, rest));
  // The cactus with its selection's anchors (fixed and handle vertices): one component, held.
  const TriangleMesh cactus = read_triangle_mesh(data + "/meshes/botsch-sorkine/cactus.off");
  const Selection sel = read_sel(data + "/meshes/botsch-sorkine/cactus.sel");
  std::vector<char> anchored(sel.roles.size());
  for (size_t v = 0; v < anchored.size(); ++v) anchored[v] = sel.roles[v] != SelRole::Free;
  const MeshCheckSummary s = diagnose_mesh(cactus.V, cactus.F, anchored);
  CHECK(s.verdict == MeshCheckStatus::Clean);
  CHECK(s.components == 1);
  for (const char* path : {"tets/solid_cactus.ele", "tets/hand.mesh", "tets/octopus-low.mesh"}) {
    INFO(path);
    const TetMesh t = read_tet_mesh(data + "/" + path);
    const MeshCheckSummary ts = diagnose_mesh(t.V, t.T);
    CHECK_FALSE(ts.has_errors());
    CHECK_FALSE(find(ts, MeshDefect::InvertedTet));  // the README: all tets positive
    CHECK_FALSE(find(ts, MeshDefect::NonManifoldVertex));
  }
  // The octopus and a copy of it touching at one vertex (the copy's leftmost
  // on the original's rightmost, both on the boundary): that vertex alone.
  const TetMesh octopus = read_tet_mesh(data + "/tets/octopus-low.mesh");
  Index right = 0, left = 0;
  octopus.V.col(0).maxCoeff(&right);
  octopus.V.col(0).minCoeff(&left);
  const TetMesh two = glued_at_vertex(octopus, right, octopus, left);
  const MeshCheckSummary gs = diagnose_mesh(two.V, two.T);
  const MeshFinding* pinched = find(gs, MeshDefect::NonManifoldVertex);
  REQUIRE(pinched);
  CHECK(pinched->count == 1);
  CHECK(pinched->first == std::vector<std::vector<Index>>{{right}});
  CHECK(gs.components == 1);
}
