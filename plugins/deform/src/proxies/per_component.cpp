// The per-component steps shared by the rotational clusters and the linear
// proxy groups (docs/proxies.md, "Connected components").
#include "proxies_internal.h"

#include <fmt/format.h>

#include <algorithm>
#include <cassert>
#include <stdexcept>
#include <utility>

namespace qpreduce::deform::detail {

namespace {

// Different, reproducible k-means seeds per component.
std::uint64_t component_seed(std::uint64_t seed, Index component) {
  return seed + 0x9E3779B97F4A7C15ull * static_cast<std::uint64_t>(component);
}

}  // namespace

void check_cluster_call(const char* what, const ClusterOptions& options, const void* out) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument(std::string(what) + ": " + why);
  if (!out) throw std::invalid_argument(std::string(what) + ": out is null");
}

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

bool embed_component(const VerticesRef& V, const SparseMatrix<double>& L, const Eigen::VectorXd& mass,
                     const std::vector<Index>& vertices, Index component, const SpectralOptions& options,
                     Matrix<double>* coordinates, ClusterSummary* summary) {
  const SpectralSummary part = component_embedding(V, L, mass, vertices, options, coordinates);
  accumulate(&summary->spectral, part);
  if (part.ok()) return true;
  summary->status = part.status;
  summary->spectral.status = part.status;
  summary->message = fmt::format("component {} ({} vertices): {}", component, vertices.size(), part.message);
  summary->spectral.message = part.message;
  return false;
}

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

}  // namespace qpreduce::deform::detail
