// Rotational clusters (Section 3.1, Eq. 8): spectral k-means per connected
// component, and clusters from `.id` files; see clusters.h and
// docs/proxies.md.
#include "qpreduce/deform/proxies/clusters.h"

#include "proxies_internal.h"

#include <qpreduce/checks.h>
#include <qpreduce/util/timer.h>

#include <fmt/format.h>

#include <algorithm>
#include <limits>
#include <map>
#include <stdexcept>
#include <utility>

namespace qpreduce::deform {

namespace {

using detail::RowMatrix;

// What compute_rotation_clusters clusters in each element component: the
// referenced vertices (per-vertex clustering) or the elements, ascending, with
// the component's measure (summed masses or element measures).
struct ComponentItems {
  std::vector<std::vector<Index>> items;  // per component
  std::vector<double> weight;             // per component

  std::vector<Index> capacity() const {
    std::vector<Index> out(items.size());
    for (std::size_t i = 0; i < items.size(); ++i) out[i] = static_cast<Index>(items[i].size());
    return out;
  }
};

ComponentItems items_per_component(const MeshComponents& components, const Eigen::VectorXd& mass,
                                   const Eigen::VectorXd& measures, bool per_vertex) {
  const Index c = components.element_components;
  ComponentItems out;
  out.items.resize(static_cast<std::size_t>(c));
  out.weight.assign(static_cast<std::size_t>(c), 0.0);
  if (per_vertex) {
    for (Index v = 0; v < static_cast<Index>(components.vertex_component.size()); ++v) {
      if (components.is_unreferenced(v)) continue;
      out.items[components.vertex_component[v]].push_back(v);
      out.weight[components.vertex_component[v]] += mass[v];
    }
  } else {
    for (Index e = 0; e < static_cast<Index>(components.element_component.size()); ++e) {
      out.items[components.element_component[e]].push_back(e);
      out.weight[components.element_component[e]] += measures[e];
    }
  }
  return out;
}

// Embedding of each element of one component at the mean of its vertices'
// embeddings: coordinates has a row per vertex of `vertices` (ascending, the
// component's vertices of an n-vertex mesh), the result a row per element of
// `elements`.
RowMatrix element_points(const Matrix<double>& coordinates, const std::vector<Index>& vertices,
                         const std::vector<Index>& elements, const ElementsRef& E, Index n) {
  RowMatrix points(static_cast<Index>(elements.size()), coordinates.cols());
  std::vector<int> position(static_cast<std::size_t>(n), -1);
  for (std::size_t i = 0; i < vertices.size(); ++i) position[vertices[i]] = static_cast<int>(i);
  for (std::size_t i = 0; i < elements.size(); ++i) {
    const Index e = elements[i];
    Eigen::RowVectorXd mean = Eigen::RowVectorXd::Zero(coordinates.cols());
    for (Index a = 0; a < E.cols(); ++a) mean += coordinates.row(position[E(e, a)]);
    points.row(static_cast<Index>(i)) = mean / static_cast<double>(E.cols());
  }
  return points;
}

// The vertex of `targets` nearest to vertex `query` (Euclidean; lowest index on ties).
Index nearest(const VerticesRef& V, Index query, const std::vector<Index>& targets) {
  Index best = targets.front();
  double best_d2 = std::numeric_limits<double>::infinity();
  for (Index t : targets) {
    const double d2 = (V.row(query) - V.row(t)).squaredNorm();
    if (d2 < best_d2) {
      best_d2 = d2;
      best = t;
    }
  }
  return best;
}

// Unreferenced vertices carry no rotation: each takes the label of the
// nearest referenced vertex.
void label_unreferenced(const VerticesRef& V, const MeshComponents& components, std::vector<int>* labels) {
  if (components.unreferenced.empty()) return;
  const Index n = V.rows();
  std::vector<Index> referenced;
  referenced.reserve(static_cast<std::size_t>(n - static_cast<Index>(components.unreferenced.size())));
  for (Index v = 0; v < n; ++v) {
    if (!components.is_unreferenced(v)) referenced.push_back(v);
  }
  for (Index v : components.unreferenced) (*labels)[v] = (*labels)[nearest(V, v, referenced)];
}

}  // namespace

bool ClusterOptions::is_valid(std::string* why) const { return spectral.is_valid(why) && kmeans.is_valid(why); }

std::string ClusterSummary::brief_report() const {
  return fmt::format("clusters: {}{}{} | {} elements, {} clusters, {} components | k-means objective {:.3e}, "
                     "{} iterations{} | k-means {:.3f}s, total {:.3f}s | {}",
                     to_string(status), message.empty() ? "" : " — ", message, elements, clusters, components,
                     kmeans_objective, kmeans_iterations, kmeans_converged ? "" : " (not converged)", kmeans_seconds,
                     total_seconds, spectral.brief_report());
}

ClusterSummary compute_rotation_clusters(const VerticesRef& V, const ElementsRef& E, ClusterElement element, Index d,
                                         const ClusterOptions& options, Clustering* out) {
  qpreduce::Timer total;
  const char* what = "compute_rotation_clusters";
  detail::check_cluster_call(what, options, out);
  if (E.rows() == 0) throw std::invalid_argument("compute_rotation_clusters: the mesh has no elements");
  SparseMatrix<double> L;
  Eigen::VectorXd mass;
  laplacian_and_mass(V, E, &L, &mass);  // checks V and E
  const Eigen::VectorXd measures = element_measures(V, E);
  const MeshComponents components = connected_components(V.rows(), E);
  const Index n = V.rows();
  const bool per_vertex = element == ClusterElement::Vertex;
  const Index elements = per_vertex ? n - static_cast<Index>(components.unreferenced.size()) : E.rows();
  detail::check_count(what, "cluster", d, elements, per_vertex ? "referenced vertices" : "elements",
                      components.element_components, 0);

  ClusterSummary summary;
  summary.elements = per_vertex ? n : E.rows();
  summary.clusters = d;
  summary.components = components.element_components;
  const ComponentItems parts = items_per_component(components, mass, measures, per_vertex);
  const std::vector<Index> share = detail::apportion(d, parts.weight, parts.capacity());

  const std::vector<std::vector<Index>> vertex_lists = components.vertex_lists();
  Clustering result;
  result.count = d;
  result.labels.assign(static_cast<std::size_t>(summary.elements), -1);
  result.component_of_cluster.reserve(static_cast<std::size_t>(d));
  int base = 0;
  for (Index comp = 0; comp < components.element_components; ++comp) {
    const Index k = share[comp];
    const std::vector<Index>& items = parts.items[comp];
    std::vector<int> local(items.size(), 0);
    if (k > 1) {
      Matrix<double> coordinates;  // per vertex of the component
      if (!detail::embed_component(V, L, mass, vertex_lists[comp], comp, options.spectral, &coordinates, &summary)) {
        summary.total_seconds = total.seconds();
        return summary;
      }
      qpreduce::Timer timer;
      // Per vertex, vertex_lists[comp] and items are the same ascending list.
      const RowMatrix points =
          per_vertex ? RowMatrix(coordinates) : element_points(coordinates, vertex_lists[comp], items, E, n);
      local = detail::cluster_component(points, k, options.kmeans, comp, &summary);
      summary.kmeans_seconds += timer.seconds();
    }
    for (std::size_t i = 0; i < items.size(); ++i) result.labels[items[i]] = base + local[i];
    for (Index j = 0; j < k; ++j) result.component_of_cluster.push_back(static_cast<int>(comp));
    base += static_cast<int>(k);
  }
  if (per_vertex) label_unreferenced(V, components, &result.labels);
  summary.spectral.status = Status::Success;
  summary.status = Status::Success;
  *out = std::move(result);
  summary.total_seconds = total.seconds();
  return summary;
}

IdClustering clusters_from_ids(const std::vector<int>& ids, Index expected_size) {
  qpreduce::check_size("clusters_from_ids: id count", expected_size, static_cast<Index>(ids.size()));
  if (ids.empty()) throw std::invalid_argument("clusters_from_ids: no ids");
  // Non-negative ids ascending, then −1, −2, …: order by (id < 0, |id|).
  std::vector<int> distinct(ids);
  std::sort(distinct.begin(), distinct.end());
  distinct.erase(std::unique(distinct.begin(), distinct.end()), distinct.end());
  std::stable_partition(distinct.begin(), distinct.end(), [](int id) { return id >= 0; });
  const auto first_negative = std::find_if(distinct.begin(), distinct.end(), [](int id) { return id < 0; });
  std::reverse(first_negative, distinct.end());
  IdClustering out;
  out.count = static_cast<Index>(distinct.size());
  out.painted = static_cast<Index>(distinct.end() - first_negative);
  out.original_id = distinct;
  std::map<int, int> label_of;
  for (std::size_t c = 0; c < distinct.size(); ++c) label_of[distinct[c]] = static_cast<int>(c);
  out.labels.resize(ids.size());
  for (std::size_t i = 0; i < ids.size(); ++i) out.labels[i] = label_of[ids[i]];
  return out;
}

std::vector<std::vector<Index>> cluster_members(const std::vector<int>& labels, Index count) {
  std::vector<std::vector<Index>> members(static_cast<std::size_t>(count));
  for (std::size_t i = 0; i < labels.size(); ++i) {
    if (labels[i] < 0 || labels[i] >= count) {
      throw std::invalid_argument(
          fmt::format("cluster_members: label {} of element {} outside [0, {})", labels[i], i, count));
    }
    members[labels[i]].push_back(static_cast<Index>(i));
  }
  return members;
}

std::vector<int> element_clusters_from_vertex_labels(const std::vector<int>& per_vertex, const ElementsRef& E) {
  const Index n = static_cast<Index>(per_vertex.size());
  std::vector<int> out(static_cast<std::size_t>(E.rows()));
  for (Index e = 0; e < E.rows(); ++e) {
    const Index v = E.cols() > 0 ? E(e, 0) : -1;
    if (v < 0 || v >= n) {
      throw std::invalid_argument(fmt::format(
          "element_clusters_from_vertex_labels: element {} has first corner {} outside [0, {}) (one label per vertex)",
          e, v, n));
    }
    out[static_cast<std::size_t>(e)] = per_vertex[static_cast<std::size_t>(v)];
  }
  return out;
}

void ClusterSummary::add_details(Report* out) const {
  out->add("spectral", spectral.report())
      .add("elements", elements)
      .add("clusters", clusters)
      .add("components", components)
      .add("kmeans_objective", kmeans_objective)
      .add("kmeans_iterations", kmeans_iterations)
      .add("kmeans_converged", kmeans_converged)
      .add("kmeans_seconds", kmeans_seconds)
      .add("total_seconds", total_seconds);
}

}  // namespace qpreduce::deform
