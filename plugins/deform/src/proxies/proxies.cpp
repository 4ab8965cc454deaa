// Rotational clusters and linear proxies (Section 3.1); see proxies.h.
#include "spectral_internal.h"

#include <qpreduce/support.h>

#include <Eigen/Dense>

#include <fmt/format.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <functional>
#include <limits>
#include <map>
#include <queue>
#include <stdexcept>
#include <utility>

namespace qpreduce::deform {

namespace {

using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Splits `total` items over components: one each, then one at a time to the
// component with the largest weight per item so far (ties: lowest index),
// never beyond its capacity. Components with zero weight get only their one.
// Preconditions (checked by the callers): count ≤ total ≤ Σ capacity,
// capacity ≥ 1.
std::vector<Index> apportion(Index total, const std::vector<double>& weight, const std::vector<Index>& capacity) {
  const std::size_t c = weight.size();
  std::vector<Index> share(c, 1);
  Index left = total - static_cast<Index>(c);
  while (left > 0) {
    std::size_t best = c;
    double best_ratio = -1.0;
    for (std::size_t i = 0; i < c; ++i) {
      if (share[i] >= capacity[i]) continue;
      const double ratio = weight[i] / static_cast<double>(share[i]);
      if (ratio > best_ratio) {
        best_ratio = ratio;
        best = i;
      }
    }
    assert(best < c);
    ++share[best];
    --left;
  }
  return share;
}

// Different, reproducible k-means seeds per component.
std::uint64_t component_seed(std::uint64_t seed, Index component) {
  return seed + 0x9E3779B97F4A7C15ull * static_cast<std::uint64_t>(component);
}

// Undirected edge graph of E in compressed form, edge weights = lengths.
struct EdgeGraph {
  std::vector<Index> start;  // n + 1
  std::vector<int> neighbour;
  std::vector<double> length;
};

EdgeGraph edge_graph(const VerticesRef& V, const ElementsRef& E) {
  const Index n = V.rows();
  std::vector<std::pair<int, int>> edges;
  edges.reserve(static_cast<std::size_t>(E.rows() * E.cols() * (E.cols() - 1)));
  for (Index e = 0; e < E.rows(); ++e) {
    for (Index a = 0; a < E.cols(); ++a) {
      for (Index b = 0; b < E.cols(); ++b) {
        if (a != b) edges.emplace_back(E(e, a), E(e, b));
      }
    }
  }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  EdgeGraph g;
  g.start.assign(static_cast<std::size_t>(n + 1), 0);
  for (const auto& [i, j] : edges) ++g.start[i + 1];
  for (Index v = 0; v < n; ++v) g.start[v + 1] += g.start[v];
  g.neighbour.reserve(edges.size());
  g.length.reserve(edges.size());
  for (const auto& [i, j] : edges) {
    g.neighbour.push_back(j);
    g.length.push_back((V.row(i) - V.row(j)).norm());
  }
  return g;
}

// Dijkstra from `source` that only lowers `dist` (the incremental step of
// farthest-point sampling: dist holds the distance to the nearest sample).
void relax_from(const EdgeGraph& g, Index source, std::vector<double>& dist) {
  using Item = std::pair<double, Index>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  dist[source] = 0.0;
  queue.emplace(0.0, source);
  while (!queue.empty()) {
    const auto [d, u] = queue.top();
    queue.pop();
    if (d > dist[u]) continue;
    for (Index k = g.start[u]; k < g.start[u + 1]; ++k) {
      const int v = g.neighbour[k];
      const double nd = d + g.length[k];
      if (nd < dist[v]) {
        dist[v] = nd;
        queue.emplace(nd, v);
      }
    }
  }
}

Index argmax(const std::vector<double>& values) {
  return static_cast<Index>(std::max_element(values.begin(), values.end()) - values.begin());
}

// d items (clusters, samples, groups) over `elements` things to cluster and
// `components` connected components.
void check_count(const char* what, const char* noun, Index d, Index elements, const char* elements_name,
                 Index components, Index unreferenced_components) {
  if (d < 1 || d > elements) {
    throw std::invalid_argument(fmt::format("{}: {} count must lie in [1, {}] (the number of {}), got {}", what, noun,
                                            elements, elements_name, d));
  }
  if (d < components) {
    throw std::invalid_argument(fmt::format(
        "{}: {} {}s cannot cover {} connected components{}: expected at least {}, got {}", what, d, noun, components,
        unreferenced_components > 0 ? fmt::format(" ({} of them unreferenced vertices)", unreferenced_components)
                                    : std::string(),
        components, d));
  }
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

// Clusters `points` of one component into k (k-means, or all 0 for k = 1).
std::vector<int> cluster_component(const RowMatrix& points, Index k, const KMeansOptions& options, Index component,
                                   ClusterSummary* summary) {
  if (k == 1) return std::vector<int>(static_cast<std::size_t>(points.rows()), 0);
  KMeansOptions local = options;
  local.seed = component_seed(options.seed, component);
  KMeansResult result = kmeans(points, k, local);
  summary->kmeans_objective += result.objective;
  summary->kmeans_iterations = std::max(summary->kmeans_iterations, result.iterations);
  summary->kmeans_converged = summary->kmeans_converged && result.converged;
  return std::move(result.labels);
}

// Spectral embedding of one component into *coordinates, accumulated into
// summary->spectral; on failure sets the summary's status and message and
// returns false.
bool embed_component(const VerticesRef& V, const SparseMatrix<double>& L, const Eigen::VectorXd& mass,
                     const std::vector<Index>& vertices, Index component, const SpectralOptions& options,
                     Matrix<double>* coordinates, ClusterSummary* summary) {
  const SpectralSummary part = detail::component_embedding(V, L, mass, vertices, options, coordinates);
  detail::accumulate(&summary->spectral, part);
  if (part.ok()) return true;
  summary->status = part.status;
  summary->spectral.status = part.status;
  summary->message = fmt::format("component {} ({} vertices): {}", component, vertices.size(), part.message);
  summary->spectral.message = part.message;
  return false;
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
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument(std::string(what) + ": " + why);
  if (!out) throw std::invalid_argument("compute_rotation_clusters: out is null");
  if (E.rows() == 0) throw std::invalid_argument("compute_rotation_clusters: the mesh has no elements");
  SparseMatrix<double> L;
  Eigen::VectorXd mass;
  laplacian_and_mass(V, E, &L, &mass);  // checks V and E
  const Eigen::VectorXd measures = element_measures(V, E);
  const MeshComponents components = connected_components(V.rows(), E);
  const Index n = V.rows();
  const bool per_vertex = element == ClusterElement::Vertex;
  const Index elements = per_vertex ? n - static_cast<Index>(components.unreferenced.size()) : E.rows();
  check_count(what, "cluster", d, elements, per_vertex ? "referenced vertices" : "elements",
              components.element_components, 0);

  ClusterSummary summary;
  summary.elements = per_vertex ? n : E.rows();
  summary.clusters = d;
  summary.components = components.element_components;

  // Clustered items of each component: vertices (referenced) or elements.
  const Index c = components.element_components;
  std::vector<std::vector<Index>> items(static_cast<std::size_t>(c));
  std::vector<double> weight(static_cast<std::size_t>(c), 0.0);
  if (per_vertex) {
    for (Index v = 0; v < n; ++v) {
      if (components.is_unreferenced(v)) continue;
      items[components.vertex_component[v]].push_back(v);
      weight[components.vertex_component[v]] += mass[v];
    }
  } else {
    for (Index e = 0; e < E.rows(); ++e) {
      items[components.element_component[e]].push_back(e);
      weight[components.element_component[e]] += measures[e];
    }
  }
  std::vector<Index> capacity(static_cast<std::size_t>(c));
  for (Index i = 0; i < c; ++i) capacity[i] = static_cast<Index>(items[i].size());
  const std::vector<Index> share = apportion(d, weight, capacity);

  const std::vector<std::vector<Index>> vertex_lists = components.vertex_lists();
  Clustering result;
  result.count = d;
  result.labels.assign(static_cast<std::size_t>(summary.elements), -1);
  result.component_of_cluster.reserve(static_cast<std::size_t>(d));
  int base = 0;
  for (Index comp = 0; comp < c; ++comp) {
    const Index k = share[comp];
    std::vector<int> local(items[comp].size(), 0);
    if (k > 1) {
      Matrix<double> coordinates;  // per vertex of the component
      if (!embed_component(V, L, mass, vertex_lists[comp], comp, options.spectral, &coordinates, &summary)) {
        summary.total_seconds = total.seconds();
        return summary;
      }
      qpreduce::Timer timer;
      RowMatrix points(static_cast<Index>(items[comp].size()), coordinates.cols());
      if (per_vertex) {
        // vertex_lists[comp] and items[comp] are the same ascending list.
        points = coordinates;
      } else {
        std::vector<int> position(static_cast<std::size_t>(n), -1);
        for (std::size_t i = 0; i < vertex_lists[comp].size(); ++i) position[vertex_lists[comp][i]] = static_cast<int>(i);
        for (std::size_t i = 0; i < items[comp].size(); ++i) {
          const Index e = items[comp][i];
          Eigen::RowVectorXd mean = Eigen::RowVectorXd::Zero(coordinates.cols());
          for (Index a = 0; a < E.cols(); ++a) mean += coordinates.row(position[E(e, a)]);
          points.row(static_cast<Index>(i)) = mean / static_cast<double>(E.cols());
        }
      }
      local = cluster_component(points, k, options.kmeans, comp, &summary);
      summary.kmeans_seconds += timer.seconds();
    }
    for (std::size_t i = 0; i < items[comp].size(); ++i) result.labels[items[comp][i]] = base + local[i];
    for (Index j = 0; j < k; ++j) result.component_of_cluster.push_back(static_cast<int>(comp));
    base += static_cast<int>(k);
  }
  if (per_vertex && !components.unreferenced.empty()) {
    std::vector<Index> referenced;
    referenced.reserve(static_cast<std::size_t>(elements));
    for (Index v = 0; v < n; ++v) {
      if (!components.is_unreferenced(v)) referenced.push_back(v);
    }
    for (Index v : components.unreferenced) result.labels[v] = result.labels[nearest(V, v, referenced)];
  }
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

LinearProxies linear_proxies_from_groups(std::vector<std::vector<Index>> groups, Index n) {
  std::vector<Eigen::Triplet<double, int>> entries;
  for (std::size_t j = 0; j < groups.size(); ++j) {
    std::vector<Index>& group = groups[j];
    if (group.empty()) throw std::invalid_argument(fmt::format("linear_proxies_from_groups: group {} is empty", j));
    std::sort(group.begin(), group.end());
    for (std::size_t i = 0; i < group.size(); ++i) {
      if (group[i] < 0 || group[i] >= n) {
        throw std::invalid_argument(fmt::format("linear_proxies_from_groups: group {} has vertex {} outside [0, {})",
                                                j, group[i], n));
      }
      if (i > 0 && group[i] == group[i - 1]) {
        throw std::invalid_argument(
            fmt::format("linear_proxies_from_groups: group {} lists vertex {} twice", j, group[i]));
      }
      entries.emplace_back(static_cast<int>(j), static_cast<int>(group[i]), 1.0 / static_cast<double>(group.size()));
    }
  }
  LinearProxies out;
  out.W.resize(static_cast<Index>(groups.size()), n);
  out.W.setFromTriplets(entries.begin(), entries.end());
  out.W.makeCompressed();
  out.groups = std::move(groups);
  return out;
}

LinearProxies linear_proxies_from_ids(const std::vector<int>& ids, Index n) {
  const IdClustering relabelled = clusters_from_ids(ids, n);
  return linear_proxies_from_groups(cluster_members(relabelled.labels, relabelled.count), n);
}

LinearProxies linear_proxies_fps(const VerticesRef& V, const ElementsRef& E, Index m) {
  const char* what = "linear_proxies_fps";
  if (V.cols() != 3) throw std::invalid_argument(fmt::format("{}: V must have 3 columns: expected 3, got {}", what, V.cols()));
  if (!V.allFinite()) throw std::invalid_argument(fmt::format("{}: V contains NaN or infinite entries", what));
  const Index n = V.rows();
  const MeshComponents components = connected_components(n, E);  // checks indices
  check_count(what, "sample", m, n, "vertices", components.count, static_cast<Index>(components.unreferenced.size()));

  const EdgeGraph graph = edge_graph(V, E);
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> dist(static_cast<std::size_t>(n), inf);
  std::vector<char> sampled(static_cast<std::size_t>(n), 0);
  std::vector<std::vector<Index>> groups;
  groups.reserve(static_cast<std::size_t>(m));
  while (static_cast<Index>(groups.size()) < m) {
    Index s = argmax(dist);
    if (dist[s] == inf) {
      // A component without a sample: start at the vertex farthest (along the
      // edges) from its lowest-index vertex s, a peripheral vertex.
      std::vector<double> from_s(static_cast<std::size_t>(n), inf);
      relax_from(graph, s, from_s);
      for (std::size_t v = 0; v < from_s.size(); ++v) from_s[v] = std::isinf(from_s[v]) ? -1.0 : from_s[v];
      s = argmax(from_s);
    } else if (dist[s] == 0.0) {
      // Every remaining vertex coincides with a sample: take the first unsampled.
      s = static_cast<Index>(std::find(sampled.begin(), sampled.end(), 0) - sampled.begin());
    }
    sampled[s] = 1;
    groups.push_back({s});
    relax_from(graph, s, dist);
  }
  return linear_proxies_from_groups(std::move(groups), n);
}

ClusterSummary linear_proxies_groups(const VerticesRef& V, const ElementsRef& E, Index m, GroupSpace space,
                                     const ClusterOptions& options, LinearProxies* out) {
  qpreduce::Timer total;
  const char* what = "linear_proxies_groups";
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument(std::string(what) + ": " + why);
  if (!out) throw std::invalid_argument("linear_proxies_groups: out is null");
  if (V.cols() != 3) throw std::invalid_argument(fmt::format("{}: V must have 3 columns: expected 3, got {}", what, V.cols()));
  const Index n = V.rows();
  const MeshComponents components = connected_components(n, E);
  check_count(what, "group", m, n, "vertices", components.count, static_cast<Index>(components.unreferenced.size()));
  SparseMatrix<double> L;
  Eigen::VectorXd mass = Eigen::VectorXd::Zero(n);
  if (E.rows() > 0) laplacian_and_mass(V, E, space == GroupSpace::Spectral ? &L : nullptr, &mass);
  else if (!V.allFinite()) throw std::invalid_argument(fmt::format("{}: V contains NaN or infinite entries", what));

  ClusterSummary summary;
  summary.elements = n;
  summary.clusters = m;
  summary.components = components.count;
  const std::vector<std::vector<Index>> lists = components.vertex_lists();
  std::vector<double> weight(lists.size(), 0.0);
  std::vector<Index> capacity(lists.size());
  for (std::size_t c = 0; c < lists.size(); ++c) {
    capacity[c] = static_cast<Index>(lists[c].size());
    for (Index v : lists[c]) weight[c] += mass[v];
  }
  const std::vector<Index> share = apportion(m, weight, capacity);

  std::vector<std::vector<Index>> groups;
  groups.reserve(static_cast<std::size_t>(m));
  for (std::size_t comp = 0; comp < lists.size(); ++comp) {
    const Index k = share[comp];
    if (k == 1) {
      groups.push_back(lists[comp]);
      continue;
    }
    RowMatrix points;
    if (space == GroupSpace::Spectral) {
      Matrix<double> coordinates;
      if (!embed_component(V, L, mass, lists[comp], static_cast<Index>(comp), options.spectral, &coordinates,
                           &summary)) {
        summary.total_seconds = total.seconds();
        return summary;
      }
      points = coordinates;
    } else {
      points.resize(static_cast<Index>(lists[comp].size()), 3);
      for (std::size_t i = 0; i < lists[comp].size(); ++i) points.row(static_cast<Index>(i)) = V.row(lists[comp][i]);
    }
    qpreduce::Timer timer;
    const std::vector<int> local = cluster_component(points, k, options.kmeans, static_cast<Index>(comp), &summary);
    summary.kmeans_seconds += timer.seconds();
    std::vector<std::vector<Index>> part(static_cast<std::size_t>(k));
    for (std::size_t i = 0; i < local.size(); ++i) part[local[i]].push_back(lists[comp][i]);
    for (auto& group : part) groups.push_back(std::move(group));
  }
  *out = linear_proxies_from_groups(std::move(groups), n);
  summary.spectral.status = Status::Success;
  summary.status = Status::Success;
  summary.total_seconds = total.seconds();
  return summary;
}

bool proxies_cover_components(const LinearProxies& proxies, const MeshComponents& components, std::string* why) {
  const Index n = static_cast<Index>(components.vertex_component.size());
  qpreduce::check_size("proxies_cover_components: Ŵ columns", n, proxies.W.cols());
  const Index c = components.count;
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(proxies.W.rows(), c);
  for (Index v = 0; v < proxies.W.outerSize(); ++v) {
    for (SparseMatrix<double>::InnerIterator it(proxies.W, v); it; ++it) {
      B(it.row(), components.vertex_component[v]) += it.value();
    }
  }
  for (Index comp = 0; comp < c; ++comp) {
    if (B.rows() == 0 || B.col(comp).cwiseAbs().maxCoeff() == 0.0) {
      if (why) *why = fmt::format("connected component {} has no linear proxy", comp);
      return false;
    }
  }
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(B);
  // Entries of B are fractions in [0, 1]; 1e-10 separates rank loss from rounding.
  qr.setThreshold(1e-10);
  if (qr.rank() < c) {
    if (why) {
      *why = fmt::format("the proxies pin only {} of {} connected components independently (groups span components)",
                         qr.rank(), c);
    }
    return false;
  }
  return true;
}

}  // namespace qpreduce::deform
