// Internal to qpreduce_deform: the per-component spectral pieces shared by
// spectral.cpp and proxies.cpp.
#pragma once

#include "qpreduce/deform/proxies/proxies.h"

#include <vector>

namespace qpreduce::deform::detail {

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

}  // namespace qpreduce::deform::detail
