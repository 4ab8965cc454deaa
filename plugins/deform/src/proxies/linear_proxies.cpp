// Linear proxies (Section 3.1, Eq. 12): farthest-point samples, k-means
// vertex groups, groups from `.id` files, and the covering check; see
// linear_proxies.h and docs/proxies.md.
#include "qpreduce/deform/proxies/linear_proxies.h"

#include "proxies_internal.h"

#include <qpreduce/checks.h>
#include <qpreduce/util/timer.h>

#include <Eigen/Dense>

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <queue>
#include <stdexcept>
#include <utility>

namespace qpreduce::deform {

namespace {

using detail::apportion;
using detail::check_count;
using detail::cluster_component;
using detail::embed_component;
using detail::RowMatrix;

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

// Distances within this relative amount of the largest are a tie: the
// round-off of sums along different paths (about 1e-15 relative), not a
// difference of the mesh.
constexpr double kTieTolerance = 1e-10;

// The lowest index whose value ties with the largest (kTieTolerance): on a
// mesh with symmetries many vertices are equally far, and the last bits of
// the coordinates (which scaling or moving the mesh changes) must not choose
// among them.
Index argmax(const std::vector<double>& values) {
  const double top = *std::max_element(values.begin(), values.end());
  const double bar = std::isfinite(top) ? top - kTieTolerance * std::abs(top) : top;
  return static_cast<Index>(
      std::find_if(values.begin(), values.end(), [bar](double v) { return v >= bar; }) - values.begin());
}

}  // namespace

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
  return linear_proxies_fps(V, E, m, {});
}

LinearProxies linear_proxies_fps(const VerticesRef& V, const ElementsRef& E, Index m, const std::vector<Index>& seeds) {
  const char* what = "linear_proxies_fps";
  if (V.cols() != 3) throw std::invalid_argument(fmt::format("{}: V must have 3 columns: expected 3, got {}", what, V.cols()));
  if (!V.allFinite()) throw std::invalid_argument(fmt::format("{}: V contains NaN or infinite entries", what));
  const Index n = V.rows();
  const MeshComponents components = connected_components(n, E);  // checks indices
  std::vector<char> sampled(static_cast<std::size_t>(n), 0);
  std::vector<char> covered(static_cast<std::size_t>(components.count), 0);
  for (std::size_t i = 0; i < seeds.size(); ++i) {
    const Index v = seeds[i];
    if (v < 0 || v >= n) throw std::invalid_argument(fmt::format("{}: seeds[{}] = {} is outside [0, {})", what, i, v, n));
    if (sampled[static_cast<std::size_t>(v)]++) {
      throw std::invalid_argument(fmt::format("{}: seeds[{}] = {} is listed twice", what, i, v));
    }
    covered[static_cast<std::size_t>(components.vertex_component[v])] = 1;
  }
  const Index seeded = static_cast<Index>(seeds.size());
  if (seeded == 0) {
    check_count(what, "sample", m, n, "vertices", components.count, static_cast<Index>(components.unreferenced.size()));
  } else {
    const Index uncovered = components.count - static_cast<Index>(std::count(covered.begin(), covered.end(), 1));
    if (m < uncovered || m > n - seeded) {
      throw std::invalid_argument(
          fmt::format("{}: {} samples beyond the {} seeds: expected at least {} (the connected components without a "
                      "seed) and at most {} (the vertices that are not seeds)",
                      what, m, seeded, uncovered, n - seeded));
    }
  }

  const EdgeGraph graph = edge_graph(V, E);
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> dist(static_cast<std::size_t>(n), inf);
  std::vector<std::vector<Index>> groups;
  groups.reserve(static_cast<std::size_t>(seeded + m));
  for (Index v : seeds) {
    groups.push_back({v});
    relax_from(graph, v, dist);
  }
  while (static_cast<Index>(groups.size()) < seeded + m) {
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
  detail::check_cluster_call(what, options, out);
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
