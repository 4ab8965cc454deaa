// Internal to qpreduce_deform: the per-component steps shared by the spectral
// embedding (spectral.cpp), the rotational clusters (clusters.cpp) and the
// linear proxy groups (linear_proxies.cpp).
#pragma once

#include "qpreduce/deform/proxies/clusters.h"
#include "qpreduce/deform/proxies/kmeans.h"
#include "qpreduce/deform/proxies/spectral.h"

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace qpreduce::deform::detail {

using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// The failing branch of an options struct's is_valid: stores `reason` in
// *why (when not null) and returns false.
inline bool reject(std::string* why, const char* reason) {
  if (why) *why = reason;
  return false;
}

// ---- spectral.cpp

// Eigenpairs of one connected operator with shift σ < 0 (no argument checks).
SpectralSummary eigenpairs_with_shift(const SparseMatrix<double>& L, const Eigen::VectorXd& mass, Index count,
                                      double sigma, const SpectralOptions& options, Eigenpairs* out);

// Non-null modes of the component `vertices` (a connected component of L with
// positive masses), scaled by 1/√λ: |vertices| × options.eigenvectors,
// zero-padded. σ = −shift_scale / (bounding-box diagonal of the component)².
SpectralSummary component_embedding(const VerticesRef& V, const SparseMatrix<double>& L, const Eigen::VectorXd& mass,
                                    const std::vector<Index>& vertices, const SpectralOptions& options,
                                    Matrix<double>* coordinates);

// Adds counts and times of `part` to `into` (max of the residuals).
void accumulate(SpectralSummary* into, const SpectralSummary& part);

// ---- per_component.cpp

// The argument checks every clustering entry point starts with: valid
// options and a non-null output (std::invalid_argument naming `what`).
void check_cluster_call(const char* what, const ClusterOptions& options, const void* out);

// d items (clusters, samples, groups) over `elements` things to cluster and
// `components` connected components: std::invalid_argument unless
// max(1, components) ≤ d ≤ elements.
void check_count(const char* what, const char* noun, Index d, Index elements, const char* elements_name,
                 Index components, Index unreferenced_components);

// Splits `total` items over components: one each, then one at a time to the
// component with the largest weight per item so far (ties: lowest index),
// never beyond its capacity. Components with zero weight get only their one.
// Preconditions (checked by the callers): count ≤ total ≤ Σ capacity,
// capacity ≥ 1.
std::vector<Index> apportion(Index total, const std::vector<double>& weight, const std::vector<Index>& capacity);

// Spectral embedding of one component into *coordinates, accumulated into
// summary->spectral; on failure sets the summary's status and message and
// returns false.
bool embed_component(const VerticesRef& V, const SparseMatrix<double>& L, const Eigen::VectorXd& mass,
                     const std::vector<Index>& vertices, Index component, const SpectralOptions& options,
                     Matrix<double>* coordinates, ClusterSummary* summary);

// Clusters `points` of one component into k (k-means with a seed of the
// component's own, or all 0 for k = 1); k-means figures go into *summary.
std::vector<int> cluster_component(const RowMatrix& points, Index k, const KMeansOptions& options, Index component,
                                   ClusterSummary* summary);

}  // namespace qpreduce::deform::detail
