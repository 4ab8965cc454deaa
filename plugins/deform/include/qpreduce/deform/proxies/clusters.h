// qpreduce::deform — rotational clusters (Ye & Yan, Section 3.1, Eq. 8): the r
// local rotations r_k are grouped into d clusters, r_k ≈ s_{i_k} + q_k, one
// rotation s_i per cluster. A rotation element is a VERTEX for surfaces
// (spokes-and-rims ARAP) and a TET for solids. Clusters come from k-means on a
// per-component spectral embedding; how the d clusters are shared among
// connected components, and why, is in docs/proxies.md.
#pragma once

#include <qpreduce/common.h>
#include <qpreduce/deform/mesh/geometry.h>
#include <qpreduce/deform/proxies/kmeans.h>
#include <qpreduce/deform/proxies/spectral.h>

#include <string>
#include <vector>

namespace qpreduce::deform {

struct ClusterOptions {
  SpectralOptions spectral;
  KMeansOptions kmeans;
  bool is_valid(std::string* why) const;
};

// What is clustered: one label per vertex (surfaces: spokes-and-rims) or one
// per row of E (tets; also faces of a surface).
enum class ClusterElement { Vertex, Element };

struct Clustering {
  std::vector<int> labels;  // one per clustered element, in [0, count), every cluster non-empty
  Index count = 0;          // d
  std::vector<int> component_of_cluster;  // count entries (mesh component of each cluster)
};

struct ClusterSummary : Outcome {
  SpectralSummary spectral;
  Index elements = 0, clusters = 0, components = 0;
  double kmeans_objective = 0.0;   // Σ over components
  int kmeans_iterations = 0;       // max over components
  bool kmeans_converged = true;    // all components
  double kmeans_seconds = 0.0, total_seconds = 0.0;
  std::string brief_report() const override;

 protected:
  void add_details(Report* out) const override;
};

// d rotational clusters of a triangle or tet mesh (Eq. 8).
//
// Inputs:
//   V        n by 3 positions
//   E        m by 3 triangles or m by 4 tets
//   element  Vertex:  labels has n entries. Unreferenced vertices carry no
//                     rotation; they get the label of the nearest referenced
//                     vertex (Euclidean) and do not count towards d.
//            Element: labels has m entries; an element is embedded at the
//                     mean of its vertices' embeddings.
//   d        cluster count
// Outputs:
//   out      labels in [0, d), every cluster non-empty, none spanning two
//            connected components
// Throws std::invalid_argument on bad input (see geometry.h), d < 1, d larger
// than the number of clustered elements, d smaller than the number of
// components (of the elements: unreferenced vertices do not count), or invalid
// options. Spectral failures: Status::NumericalFailure, `out` left untouched.
ClusterSummary compute_rotation_clusters(const VerticesRef& V, const ElementsRef& E, ClusterElement element, Index d,
                                         const ClusterOptions& options, Clustering* out);

// Clusters from an `.id` vector (one integer per element; docs/formats.md,
// "Handle and proxy files"): every distinct id is one cluster — the ids ≥ 0
// and, as extra clusters, each distinct negative id (a region painted by a
// user). Relabelled to 0..count−1: non-negative ids ascending first, then
// negative ids in the order −1, −2, …; original_id[c] is the file's id of
// cluster c.
struct IdClustering {
  std::vector<int> labels;       // per element, in [0, count)
  Index count = 0;
  std::vector<int> original_id;  // count entries
  Index painted = 0;             // clusters that came from negative ids
};
// Throws std::invalid_argument when ids.size() ≠ expected_size or ids is empty.
IdClustering clusters_from_ids(const std::vector<int>& ids, Index expected_size);

// Members of each cluster, ascending: count lists. Throws
// std::invalid_argument for a label outside [0, count).
std::vector<std::vector<Index>> cluster_members(const std::vector<int>& labels, Index count);

// Per-element clusters from per-vertex ones: an element (a tet, or a face)
// takes the cluster of its first corner.
//
// Inputs:
//   per_vertex  one cluster label per vertex (n entries)
//   E           m by k elements (k = 3 or 4), corners in [0, n)
// Returns m labels, element e's being per_vertex[E(e, 0)].
// Throws std::invalid_argument when a first corner lies outside [0, n).
std::vector<int> element_clusters_from_vertex_labels(const std::vector<int>& per_vertex, const ElementsRef& E);

}  // namespace qpreduce::deform
