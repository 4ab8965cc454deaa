// qpreduce::deform — proxies of the reduced deformable model (Ye & Yan,
// Section 3.1): rotational clusters and linear proxies.
//
// Rotational proxies (Eq. 8): the r local rotations r_k are grouped into d
// clusters, r_k ≈ s_{i_k} + q_k, one rotation s_i per cluster. A rotation
// element is a VERTEX for surfaces (spokes-and-rims ARAP, one rotation per
// vertex) and a TET for solids. Clusters come from k-means on a spectral
// embedding (DESIGN.md, numerical choice 8):
//   * solve  L φ = λ M φ  (L the n × n cotangent Laplacian, PSD; M the n × n
//     lumped mass, diagonal) for the smallest eigenpairs, with Spectra's
//     shift-invert Lanczos around σ < 0 (so L − σM is SPD and one sparse
//     Cholesky serves every iteration);
//   * skip the null eigenvectors (λ ≈ 0: the constants of the component), keep
//     the next K, M-orthonormal, and scale each by 1/√λ: vertex v is embedded
//     at (φ_1(v)/√λ_1, …, φ_K(v)/√λ_K) (the commute-time / Green's-function
//     embedding, so low frequencies dominate);
//   * an element that spans several vertices (a tet) is embedded at the mean
//     of its vertices' embeddings;
//   * k-means (k-means++ seeding, Lloyd iterations) in that space.
// Connected components: the eigenproblem is solved per component (a
// disconnected L has one zero eigenvalue per component, and Lanczos cannot
// resolve a repeated eigenvalue reliably). Every component gets at least one
// cluster, so no cluster spans two components; the remaining d − c clusters go
// one at a time to the component with the largest measure (area or volume)
// per cluster, never more clusters than the component has elements. Hence
// d ≥ c is required (std::invalid_argument otherwise), as is d ≤ #elements.
//
// Linear proxies (Eq. 12): W V′ = X with W = Ŵ ⊗ I₃, Ŵ (m × n) sparse with
// rows summing to 1: a row with a single 1 samples a vertex, a row with 1/N on
// the N vertices of a group averages them. Every connected component of the
// mesh (unreferenced vertices included: each is its own component with a zero
// row in L) needs at least one proxy, otherwise H is singular on ker(Wᵀ) and
// the KKT system of Eq. 14 is singular.
#pragma once

#include <qpreduce/common.h>
#include <qpreduce/deform/mesh/geometry.h>
#include <qpreduce/factorization.h>

#include <Eigen/Core>

#include <cstdint>
#include <string>
#include <vector>

namespace qpreduce::deform {

// ---- k-means ----

struct KMeansOptions {
  // Seed of the k-means++ draws. The same seed gives the same labels on every
  // platform (the generator and the draws are our own, not <random>'s
  // distributions).
  std::uint64_t seed = 1;
  // Lloyd iterations at most (each: assign to the nearest centre, recompute
  // centres). 100 is far above what a well-seeded k-means needs for d ≲ 100.
  int max_iterations = 100;
  // Converged when no label changes, or when the objective Σ‖x − c‖² drops by
  // less than tolerance·objective in an iteration. (Lloyd's tail moves a few
  // boundary points per iteration for tens of iterations; Hamerly's bounds
  // make those iterations O(n), so there is little to gain by stopping early.)
  double tolerance = 1e-6;

  bool is_valid(std::string* why) const;
};

struct KMeansResult {
  std::vector<int> labels;                                                  // per point, in [0, k)
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> centres;  // k × dim
  double objective = 0.0;  // Σ ‖x − c_label‖²
  int iterations = 0;
  bool converged = false;
};

// k-means of the rows of `points` (n × dim) into exactly k non-empty clusters
// (an empty cluster is refilled with the point farthest from its centre).
// Lloyd iterations accelerated with Hamerly's distance bounds (same result).
// Deterministic for a seed. Throws std::invalid_argument when k < 1, k > n,
// points are not finite, or the options are invalid.
KMeansResult kmeans(const Eigen::Ref<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>& points,
                    Index k, const KMeansOptions& options = {});

// ---- spectral embedding ----

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
  std::string brief_report() const;
};

// The `count` smallest eigenpairs (zeros included) of L φ = λ M φ, with L
// (n × n) symmetric PSD and mass (n) the positive diagonal of M, by
// shift-invert around sigma < 0 (options.shift_scale is not used here;
// spectral_embedding derives σ from it). Meant for a CONNECTED operator: on a
// disconnected one Lanczos may return fewer copies of a repeated eigenvalue
// than there are (use spectral_embedding). n ≤ options.dense_max_size: dense
// solver instead. Throws std::invalid_argument on sizes, non-positive mass,
// count ∉ [1, n], σ ≥ 0 or bad options. Spectra not converging or L − σM
// failing to factor come back as Status::NumericalFailure with the reason;
// `out` is then left untouched.
SpectralSummary laplacian_eigenpairs(const SparseMatrix<double>& L, const Eigen::VectorXd& mass, Index count,
                                     double sigma, const SpectralOptions& options, Eigenpairs* out);

// Per-component spectral embedding of the vertices, n × K. Row v holds the
// coordinates of v in ITS component's eigenvectors (columns are per-component
// modes, so rows of different components are not comparable; zero-padded
// when a component has fewer than K non-null modes). Rows of unreferenced
// vertices are zero. V gives each component's size for the shift.
SpectralSummary spectral_embedding(const VerticesRef& V, const SparseMatrix<double>& L, const Eigen::VectorXd& mass,
                                   const MeshComponents& components, const SpectralOptions& options,
                                   Matrix<double>* embedding);

// ---- rotational clusters ----

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
  std::string brief_report() const;
};

// d rotational clusters of a triangle (E m × 3) or tet (E m × 4) mesh.
//   element = Vertex:  labels has n entries. Unreferenced vertices carry no
//                      rotation; they get the label of the nearest referenced
//                      vertex (Euclidean) and do not count towards d.
//   element = Element: labels has m entries; element embedding = mean of its
//                      vertices' embeddings.
// Throws std::invalid_argument on bad input (see geometry.h), d < 1, d larger
// than the number of clustered elements, d smaller than the number of
// components (of the elements: unreferenced vertices do not count), or invalid
// options. Spectral failures: Status::NumericalFailure, `out` left untouched.
ClusterSummary compute_rotation_clusters(const VerticesRef& V, const ElementsRef& E, ClusterElement element, Index d,
                                 const ClusterOptions& options, Clustering* out);

// Clusters from an `.id` vector (one integer per element, README of
// data/paper-examples): every distinct id is one cluster — the ids ≥ 0 and,
// as extra clusters, each distinct negative id (a region painted by a user).
// Relabelled to 0..count−1: non-negative ids ascending first, then negative
// ids in the order −1, −2, …; original_id[c] is the file's id of cluster c.
struct IdClustering {
  std::vector<int> labels;       // per element, in [0, count)
  Index count = 0;
  std::vector<int> original_id;  // count entries
  Index painted = 0;             // clusters that came from negative ids
};
// Throws std::invalid_argument when ids.size() ≠ expected_size or ids is empty.
IdClustering clusters_from_ids(const std::vector<int>& ids, Index expected_size);

// Members of each cluster, ascending: count lists.
std::vector<std::vector<Index>> cluster_members(const std::vector<int>& labels, Index count);

// ---- linear proxies ----

struct LinearProxies {
  // Ŵ, m × n: row j samples or averages the vertices of groups[j]; Σ_v Ŵ_jv = 1.
  SparseMatrix<double> W;
  // groups[j]: vertices of proxy j, ascending (a single vertex for samples).
  std::vector<std::vector<Index>> groups;

  Index count() const { return static_cast<Index>(groups.size()); }
};

// Ŵ from explicit groups of an n-vertex mesh (each group non-empty, indices in
// [0, n), no vertex twice in a group; groups may overlap). Throws otherwise.
LinearProxies linear_proxies_from_groups(std::vector<std::vector<Index>> groups, Index n);

// (a) m vertex samples by farthest-point sampling with Dijkstra distances
// along the mesh edges (E: triangles or tets, edge length = Euclidean): an
// approximation of geodesic FPS, so samples spread along thin parts instead
// of jumping across gaps. Deterministic: each component's first sample is the
// vertex farthest (along edges) from its lowest-index vertex; then every next
// sample is the vertex farthest from all samples so far. A component with no
// sample yet is at infinite distance, so the first c samples cover the c
// components (unreferenced vertices included) and the rest go where the mesh
// is least covered. Throws std::invalid_argument when m < c (naming both) or
// m > n.
LinearProxies linear_proxies_fps(const VerticesRef& V, const ElementsRef& E, Index m);

// (b) m vertex groups by k-means per component (counts apportioned like the
// rotational clusters, at least one per component, unreferenced vertices
// each their own group), on the spectral embedding or on positions.
enum class GroupSpace { Spectral, Positions };
ClusterSummary linear_proxies_groups(const VerticesRef& V, const ElementsRef& E, Index m, GroupSpace space,
                                     const ClusterOptions& options, LinearProxies* out);

// (c) groups from an `.id` vector (one id per vertex; each distinct id is a
// group, relabelled as in clusters_from_ids).
LinearProxies linear_proxies_from_ids(const std::vector<int>& ids, Index n);

// True when the KKT system of Eq. 14 can be nonsingular with these proxies:
// the m × c matrix B_jc = Σ_{v ∈ component c} Ŵ_jv has rank c (every component
// pinned independently). Otherwise false, with the reason in `why`.
bool proxies_cover_components(const LinearProxies& proxies, const MeshComponents& components, std::string* why);

}  // namespace qpreduce::deform
