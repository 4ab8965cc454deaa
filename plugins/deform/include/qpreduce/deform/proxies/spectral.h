// qpreduce::deform — generalized Laplace–Beltrami eigenpairs L φ = λ M φ and
// the per-component spectral embedding that the rotational clusters are drawn
// in (docs/proxies.md, "Spectral embedding").
#pragma once

#include <qpreduce/common.h>
#include <qpreduce/deform/mesh/geometry.h>
#include <qpreduce/factorization.h>

#include <Eigen/Core>

#include <string>

namespace qpreduce::deform {

struct SpectralOptions {
  // K: eigenvectors kept per component after the null ones (fewer when the
  // component is too small to have K). The shape's coarse parts are in the
  // first ~10 modes; more mostly adds noise to k-means.
  Index eigenvectors = 12;
  // Shift σ = −shift_scale / (bounding-box diagonal of the component)². The
  // first non-zero eigenvalue of a shape of diameter D is ≈ (π/D)² ≈ 10/D²,
  // so σ sits two to three orders below it: fast Lanczos convergence, and
  // L − σM stays far from singular relative to rounding.
  double shift_scale = 1e-2;
  // Factorization of L − σM (SPD for σ < 0).
  Backend backend = Backend::Cholmod;
  // Lanczos basis size: ncv = min(n, max(2·nev + 1, min_lanczos_vectors)).
  Index min_lanczos_vectors = 20;
  // Spectra restarts at most, and its relative eigenvalue tolerance.
  Index max_restarts = 1000;
  double tolerance = 1e-10;
  // An eigenvalue counts as null when λ ≤ zero_tolerance · (tr L / tr M). tr L /
  // tr M is the mean eigenvalue (≈ 1/h² for edge length h); λ_1 of a
  // component is ≈ 1/D², so this is safe for meshes up to D/h ≈ 10⁴.
  double zero_tolerance = 1e-10;
  // Components with at most this many vertices use a dense eigensolver
  // (exact, and Lanczos needs n ≫ nev anyway).
  Index dense_max_size = 400;
  // Lanczos finds one vector per eigenspace from one start vector, so on a
  // symmetric shape it can miss copies of a repeated eigenvalue. With this on,
  // the count of eigenvalues below τ = λ_max·(1 + inertia_margin) (relative to
  // λ_max − σ) is read from the inertia of LDLᵀ(L − τM) (one extra
  // factorization), and missed ones are recovered by Lanczos on the deflated
  // operator, at most max_deflation_rounds more runs (a multiplicity-k
  // eigenvalue needs up to k − 1).
  bool verify_with_inertia = true;
  double inertia_margin = 1e-6;
  Index max_deflation_rounds = 8;

  bool is_valid(std::string* why) const;
};

// Eigenpairs of L φ = λ M φ: values ascending, vectors n × count M-orthonormal.
struct Eigenpairs {
  Eigen::VectorXd values;
  Matrix<double> vectors;
};

// Summary of an eigen-solve or a clustering. Starts at NotRun.
struct SpectralSummary : Outcome {
  Index components = 0;     // components solved
  Index eigenpairs = 0;     // eigenpairs computed, summed over components
  Index lanczos_operations = 0;  // applications of (L − σM)⁻¹M (Spectra), summed
  Index deflation_rounds = 0;    // extra Lanczos runs for missed repeated eigenvalues (max)
  // max over components and pairs of ‖Lφ − λMφ‖ / (‖L‖_∞‖φ‖ + |λ|‖M‖_∞‖φ‖)
  double max_relative_residual = 0.0;
  double factorize_seconds = 0.0, eigen_seconds = 0.0, total_seconds = 0.0;
  std::string brief_report() const override;

 protected:
  void add_details(Report* out) const override;
};

// The `count` smallest eigenpairs (zeros included) of L φ = λ M φ by
// shift-invert Lanczos around sigma (Spectra), or a dense solver when
// n ≤ options.dense_max_size. options.shift_scale is not used here
// (spectral_embedding derives σ from it).
//
// Inputs:
//   L      n by n symmetric PSD (a cotangent Laplacian)
//   mass   n, the positive diagonal of M
//   count  eigenpairs wanted, in [1, n]
//   sigma  shift, < 0 (so L − σM is SPD)
// Outputs:
//   out    values (count, ascending) and vectors (n by count, M-orthonormal)
// Meant for a CONNECTED operator: on a disconnected one Lanczos may return
// fewer copies of a repeated eigenvalue than there are (use
// spectral_embedding). Throws std::invalid_argument on sizes, non-positive
// mass, count ∉ [1, n], σ ≥ 0 or bad options. Spectra not converging or
// L − σM failing to factor come back as Status::NumericalFailure with the
// reason; `out` is then left untouched.
SpectralSummary laplacian_eigenpairs(const SparseMatrix<double>& L, const Eigen::VectorXd& mass, Index count,
                                     double sigma, const SpectralOptions& options, Eigenpairs* out);

// Per-component spectral embedding of the vertices: each component's non-null
// modes scaled by 1/√λ (the commute-time embedding, docs/proxies.md).
//
// Inputs:
//   V           n by 3 positions (each component's size sets its shift)
//   L, mass     n by n cotangent Laplacian and the n lumped masses of V
//   components  connected_components of the mesh
// Outputs:
//   embedding   n by K (K = options.eigenvectors). Row v holds the
//               coordinates of v in ITS component's eigenvectors (columns are
//               per-component modes, so rows of different components are not
//               comparable; zero-padded when a component has fewer than K
//               non-null modes). Rows of unreferenced vertices are zero.
SpectralSummary spectral_embedding(const VerticesRef& V, const SparseMatrix<double>& L, const Eigen::VectorXd& mass,
                                   const MeshComponents& components, const SpectralOptions& options,
                                   Matrix<double>* embedding);

}  // namespace qpreduce::deform
