// Linear proxies: farthest-point samples, vertex groups, explicit groups and
// the covering check.
#include <catch2/catch.hpp>

#include "proxies_test_util.h"

#include "qpreduce/deform/deformer/handles.h"
#include "qpreduce/deform/mesh/shapes.h"

#include <set>
#include <stdexcept>

using namespace qpreduce;
using namespace qpreduce::deform;
using namespace proxies_test;

TEST_CASE("farthest-point samples cover every component and are deterministic", "[linear][fps]") {
  Surface s = join(icosphere(2), icosphere(1, Eigen::RowVector3d(3, 0, 0), 0.3));
  const Index n0 = s.V.rows();
  s.V.conservativeResize(n0 + 1, 3);
  s.V.row(n0) << 9, 9, 9;  // unreferenced: its own component
  const MeshComponents comps = connected_components(s.V.rows(), s.F);
  REQUIRE(comps.count == 3);
  CHECK_THROWS_WITH(linear_proxies_fps(s.V, s.F, 2),
                    Catch::Contains("2 samples cannot cover 3 connected components") &&
                        Catch::Contains("1 of them unreferenced"));
  CHECK_THROWS_AS(linear_proxies_fps(s.V, s.F, s.V.rows() + 1), std::invalid_argument);
  for (Index m : {Index(3), Index(20), s.V.rows()}) {
    CAPTURE(m);
    const LinearProxies p = linear_proxies_fps(s.V, s.F, m);
    const LinearProxies q = linear_proxies_fps(s.V, s.F, m);
    CHECK(p.groups == q.groups);
    REQUIRE(p.count() == m);
    check_rows_sum_to_one(p);
    std::set<Index> distinct;
    std::set<int> covered;
    for (const auto& g : p.groups) {
      REQUIRE(g.size() == 1u);
      distinct.insert(g[0]);
      covered.insert(comps.vertex_component[g[0]]);
    }
    CHECK(distinct.size() == static_cast<std::size_t>(m));
    CHECK(covered.size() == 3u);
    std::string why;
    CHECK(proxies_cover_components(p, comps, &why));
  }
  // Spread: 12 samples on the 162-vertex sphere (alone) are far apart.
  const Surface sphere = icosphere(2);
  const LinearProxies p = linear_proxies_fps(sphere.V, sphere.F, 12);
  double closest = 10.0;
  for (Index i = 0; i < 12; ++i) {
    for (Index j = 0; j < i; ++j) {
      closest = std::min(closest, (sphere.V.row(p.groups[i][0]) - sphere.V.row(p.groups[j][0])).norm());
    }
  }
  CHECK(closest > 0.7);  // the 12 icosahedron vertices are 1.05 apart
}

TEST_CASE("vertex groups: exact count, non-empty, within components, rows of W sum to one", "[linear][groups]") {
  Surface s = join(icosphere(3), icosphere(2, Eigen::RowVector3d(4, 0, 0), 0.5));
  const Index n0 = s.V.rows();
  s.V.conservativeResize(n0 + 1, 3);
  s.V.row(n0) << 9, 9, 9;
  const MeshComponents comps = connected_components(s.V.rows(), s.F);
  const GroupSpace space = GENERATE(GroupSpace::Spectral, GroupSpace::Positions);
  CAPTURE(static_cast<int>(space));
  ClusterOptions o;
  CHECK_THROWS_WITH(linear_proxies_groups(s.V, s.F, 2, space, o, nullptr), Catch::Contains("out is null"));
  LinearProxies a, b;
  CHECK_THROWS_WITH(linear_proxies_groups(s.V, s.F, 2, space, o, &a), Catch::Contains("cannot cover 3"));
  const ClusterSummary sa = linear_proxies_groups(s.V, s.F, 30, space, o, &a);
  INFO(sa.brief_report());
  REQUIRE(sa.ok());
  REQUIRE(linear_proxies_groups(s.V, s.F, 30, space, o, &b).ok());
  CHECK(a.groups == b.groups);
  REQUIRE(a.count() == 30);
  check_rows_sum_to_one(a);
  std::vector<Index> seen(static_cast<std::size_t>(s.V.rows()), 0);
  for (const auto& g : a.groups) {
    REQUIRE_FALSE(g.empty());
    for (Index v : g) {
      ++seen[v];
      CHECK(comps.vertex_component[v] == comps.vertex_component[g[0]]);
    }
  }
  for (Index v = 0; v < s.V.rows(); ++v) CHECK(seen[v] == 1);  // a partition of the vertices
  std::string why;
  CHECK(proxies_cover_components(a, comps, &why));
}

TEST_CASE("proxies_cover_components detects uncovered and jointly pinned components", "[linear][errors]") {
  const Surface s = join(icosphere(1), icosphere(1, Eigen::RowVector3d(3, 0, 0)));
  const MeshComponents comps = connected_components(s.V.rows(), s.F);
  std::string why;
  CHECK_FALSE(proxies_cover_components(linear_proxies_from_groups({{0}, {5}}, s.V.rows()), comps, &why));
  CHECK_THAT(why, Catch::Contains("component 1 has no linear proxy"));
  // One group averaging vertices of both spheres pins only their sum.
  CHECK_FALSE(proxies_cover_components(linear_proxies_from_groups({{0, 50}}, s.V.rows()), comps, &why));
  CHECK_THAT(why, Catch::Contains("1 of 2"));
  CHECK(proxies_cover_components(linear_proxies_from_groups({{0, 50}, {1}}, s.V.rows()), comps, &why));
  CHECK_THROWS_WITH(linear_proxies_from_groups({{0, 0}}, s.V.rows()), Catch::Contains("twice"));
  CHECK_THROWS_WITH(linear_proxies_from_groups({{}}, s.V.rows()), Catch::Contains("empty"));
}

TEST_CASE("farthest-point samples do not depend on the mesh's units or position", "[linear][fps]") {
  // A symmetric mesh has many vertices at equal distance from the samples:
  // which one is taken must not be decided by the last bits of the
  // coordinates (the deformer samples the units-free rest pose, whose bits
  // differ between a mesh and the same mesh scaled or moved).
  const TriangleMesh m = shapes::capped_cylinder(1.0, 4.0, 16, 12);
  const Normalization unit = normalization_of(m.V);
  const Vertices base = (m.V.rowwise() - unit.centre.transpose()) / unit.scale;
  const LinearProxies reference = linear_proxies_fps(base, m.F, 33);
  for (const double scale : {1e-20, 1e-3, 7.0, 1e6, 1e25}) {
    CAPTURE(scale);
    const Vertices V = (scale * m.V).rowwise() + Eigen::RowVector3d(0.3, -2.0, 5.0) * scale;
    const Normalization frame = normalization_of(V);
    const Vertices local = (V.rowwise() - frame.centre.transpose()) / frame.scale;
    CHECK(linear_proxies_fps(local, m.F, 33).groups == reference.groups);
  }
}
