// Rotational clusters: exact count, non-empty, within components,
// deterministic; clusters from .id files and per-element labels.
#include <catch2/catch.hpp>

#include "proxies_test_util.h"

#include <stdexcept>

using namespace qpreduce;
using namespace qpreduce::deform;
using namespace proxies_test;

TEST_CASE("spectral rotation clusters: exact count, non-empty, deterministic, never spanning components",
          "[clusters]") {
  // A big sphere (642 vertices, Spectra path) and a small one (162, dense path).
  const Surface s = join(icosphere(3), icosphere(2, Eigen::RowVector3d(4, 0, 0), 0.5));
  const Index d = GENERATE(2, 9, 27);
  CAPTURE(d);
  ClusterOptions o;
  Clustering a, b;
  const ClusterSummary sa = compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, d, o, &a);
  INFO(sa.brief_report());
  REQUIRE(sa.ok());
  REQUIRE(compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, d, o, &b).ok());
  CHECK(a.labels == b.labels);
  CHECK(a.count == d);
  REQUIRE(a.labels.size() == static_cast<std::size_t>(s.V.rows()));
  check_partition(a.labels, d);
  const MeshComponents comps = connected_components(s.V.rows(), s.F);
  REQUIRE(a.component_of_cluster.size() == static_cast<std::size_t>(d));
  for (Index v = 0; v < s.V.rows(); ++v) CHECK(a.component_of_cluster[a.labels[v]] == comps.vertex_component[v]);
  // The sphere with 4× the area gets most clusters.
  const Index on_big = std::count(a.component_of_cluster.begin(), a.component_of_cluster.end(), 0);
  CHECK(on_big >= d - on_big);
  CHECK(sa.spectral.max_relative_residual < 1e-8);
  // Clusters on a sphere are spatially coherent: each cluster's vertices lie
  // in a cap much smaller than the sphere (for d ≥ 9).
  if (d >= 9) {
    const auto members = cluster_members(a.labels, d);
    for (Index c = 0; c < d; ++c) {
      Eigen::RowVector3d mean = Eigen::RowVector3d::Zero();
      for (Index v : members[c]) mean += s.V.row(v);
      mean /= static_cast<double>(members[c].size());
      double spread = 0.0;
      for (Index v : members[c]) spread = std::max(spread, (s.V.row(v) - mean).norm());
      const double radius = a.component_of_cluster[c] == 0 ? 1.0 : 0.5;
      CHECK(spread < 1.5 * radius);
    }
  }
  // Another seed: still a valid partition of the same size.
  o.kmeans.seed = 7;
  Clustering c;
  REQUIRE(compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, d, o, &c).ok());
  check_partition(c.labels, d);
}

TEST_CASE("rotation clusters: count errors and unreferenced vertices", "[clusters][errors]") {
  Surface s = join(icosphere(1), icosphere(1, Eigen::RowVector3d(3, 0, 0)));
  const Index n0 = s.V.rows();
  s.V.conservativeResize(n0 + 1, 3);
  s.V.row(n0) << 3.5, 0, 0;  // nearest referenced vertex is on the second sphere
  ClusterOptions o;
  Clustering out;
  CHECK_THROWS_WITH(compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, 1, o, &out),
                    Catch::Contains("cannot cover 2 connected components"));
  CHECK_THROWS_WITH(compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, n0 + 1, o, &out),
                    Catch::Contains("[1, 84]"));
  CHECK_THROWS_AS(compute_rotation_clusters(s.V, s.F, ClusterElement::Element, 161, o, &out), std::invalid_argument);
  REQUIRE(compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, 6, o, &out).ok());
  check_partition(out.labels, 6);
  CHECK(out.component_of_cluster[out.labels[n0]] == 1);
  // d = number of elements: singletons.
  REQUIRE(compute_rotation_clusters(s.V, s.F, ClusterElement::Vertex, n0, o, &out).ok());
  check_partition(out.labels, n0);
}

TEST_CASE("rotation clusters of tets: one label per tet (barycentre embeddings) or per vertex", "[clusters][tets]") {
  Solid a = cube_tets(5, 0.2, 1);                                    // 750 tets, 216 vertices
  const Solid b = cube_tets(2, 0.0, 2, Eigen::RowVector3d(3, 0, 0));  // a second component
  Solid s;
  s.V.resize(a.V.rows() + b.V.rows(), 3);
  s.V << a.V, b.V;
  s.T.resize(a.T.rows() + b.T.rows(), 4);
  s.T << a.T, (b.T.array() + static_cast<int>(a.V.rows())).matrix();
  const MeshComponents comps = connected_components(s.V.rows(), s.T);
  REQUIRE(comps.count == 2);
  ClusterOptions o;
  Clustering per_tet, per_vertex;
  const ClusterSummary st = compute_rotation_clusters(s.V, s.T, ClusterElement::Element, 12, o, &per_tet);
  INFO(st.brief_report());
  REQUIRE(st.ok());
  REQUIRE(per_tet.labels.size() == static_cast<std::size_t>(s.T.rows()));
  check_partition(per_tet.labels, 12);
  for (Index t = 0; t < s.T.rows(); ++t) {
    CHECK(per_tet.component_of_cluster[per_tet.labels[t]] == comps.element_component[t]);
  }
  REQUIRE(compute_rotation_clusters(s.V, s.T, ClusterElement::Vertex, 12, o, &per_vertex).ok());
  REQUIRE(per_vertex.labels.size() == static_cast<std::size_t>(s.V.rows()));
  check_partition(per_vertex.labels, 12);
}

TEST_CASE(".id clusters: every negative id is one painted cluster, relabelled after the others", "[clusters][ids]") {
  const std::vector<int> ids = {3, -1, 0, -2, 3, -1, 5, 0};
  const IdClustering c = clusters_from_ids(ids, 8);
  CHECK(c.count == 5);
  CHECK(c.painted == 2);
  CHECK(c.original_id == std::vector<int>({0, 3, 5, -1, -2}));
  CHECK(c.labels == std::vector<int>({1, 3, 0, 4, 1, 3, 2, 0}));
  check_partition(c.labels, c.count);
  CHECK_THROWS_WITH(clusters_from_ids(ids, 9), Catch::Contains("expected 9, got 8"));
  CHECK_THROWS_AS(clusters_from_ids({}, 0), std::invalid_argument);

  const LinearProxies p = linear_proxies_from_ids(ids, 8);
  CHECK(p.count() == 5);
  check_rows_sum_to_one(p);
  CHECK(p.groups[1] == std::vector<Index>({0, 4}));
  CHECK(Eigen::MatrixXd(p.W)(1, 0) == 0.5);
}

TEST_CASE("element clusters from vertex labels: each tet takes its first corner's cluster", "[clusters][tets]") {
  const Solid s = cube_tets(2, 0.0, 1);
  std::vector<int> per_vertex(static_cast<std::size_t>(s.V.rows()));
  for (std::size_t v = 0; v < per_vertex.size(); ++v) per_vertex[v] = static_cast<int>(v % 5);
  const std::vector<int> labels = element_clusters_from_vertex_labels(per_vertex, s.T);
  REQUIRE(labels.size() == static_cast<std::size_t>(s.T.rows()));
  for (Index t = 0; t < s.T.rows(); ++t) CHECK(labels[t] == per_vertex[s.T(t, 0)]);
  CHECK(element_clusters_from_vertex_labels(per_vertex, RowT(0, 4)).empty());

  std::vector<int> short_labels(per_vertex.begin(), per_vertex.begin() + 3);
  CHECK_THROWS_AS(element_clusters_from_vertex_labels(short_labels, s.T), std::invalid_argument);
  CHECK_THROWS_WITH(element_clusters_from_vertex_labels({}, s.T),
                    Catch::Contains("element 0 has first corner") && Catch::Contains("outside [0, 0)"));
}
