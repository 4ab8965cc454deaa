// qpreduce::deform — linear proxies (Ye & Yan, Section 3.1, Eq. 12):
// W V′ = X with W = Ŵ ⊗ I₃, Ŵ (m by n) sparse with rows summing to 1. A row
// with a single 1 samples a vertex; a row with 1/N on the N vertices of a
// group averages them. Every connected component of the mesh (unreferenced
// vertices included: each is its own component with a zero row in L) needs at
// least one proxy, otherwise H is singular on ker(Wᵀ) and the KKT system of
// Eq. 14 is singular (docs/proxies.md).
#pragma once

#include <qpreduce/common.h>
#include <qpreduce/deform/mesh/geometry.h>
#include <qpreduce/deform/proxies/clusters.h>

#include <string>
#include <vector>

namespace qpreduce::deform {

struct LinearProxies {
  // Ŵ, m × n: row j samples or averages the vertices of groups[j]; Σ_v Ŵ_jv = 1.
  SparseMatrix<double> W;
  // groups[j]: vertices of proxy j, ascending (a single vertex for samples).
  std::vector<std::vector<Index>> groups;

  Index count() const { return static_cast<Index>(groups.size()); }
};

// Ŵ (m by n) from m explicit groups of an n-vertex mesh: each group non-empty,
// indices in [0, n), no vertex twice in a group; groups may overlap. Throws
// std::invalid_argument otherwise.
LinearProxies linear_proxies_from_groups(std::vector<std::vector<Index>> groups, Index n);

// (a) m vertex samples by farthest-point sampling with Dijkstra distances
// along the mesh edges (V n by 3; E triangles or tets, edge length =
// Euclidean): an approximation of geodesic FPS, so samples spread along thin
// parts instead of jumping across gaps. Deterministic: each component's first
// sample is the vertex farthest (along edges) from its lowest-index vertex;
// then every next sample is the vertex farthest from all samples so far. A
// component with no sample yet is at infinite distance, so the first c samples
// cover the c components (unreferenced vertices included) and the rest go
// where the mesh is least covered. Throws std::invalid_argument when m < c
// (naming both) or m > n.
LinearProxies linear_proxies_fps(const VerticesRef& V, const ElementsRef& E, Index m);
// The same with `seeds` (distinct vertices in [0, n)) sampled first, each its
// own proxy and in that order, then m more samples farthest from them (the
// components without a seed first): the proxies of a handle set known at
// precompute, which the subspace then meets exactly (docs/deform.md, "Exact
// handles"). seeds.size() + m proxies. Throws std::invalid_argument on a seed
// out of range or listed twice, or when m is below the number of components
// without a seed or above n − seeds.size().
LinearProxies linear_proxies_fps(const VerticesRef& V, const ElementsRef& E, Index m, const std::vector<Index>& seeds);

// (b) m vertex groups by k-means per component (counts apportioned like the
// rotational clusters, at least one per component, unreferenced vertices
// each their own group), on the spectral embedding or on positions.
// Same errors as linear_proxies_fps, plus invalid options; spectral failures
// come back as Status::NumericalFailure with `out` left untouched.
enum class GroupSpace { Spectral, Positions };
ClusterSummary linear_proxies_groups(const VerticesRef& V, const ElementsRef& E, Index m, GroupSpace space,
                                     const ClusterOptions& options, LinearProxies* out);

// (c) groups from an `.id` vector (one id per vertex, n entries; each distinct
// id is a group, relabelled as in clusters_from_ids).
LinearProxies linear_proxies_from_ids(const std::vector<int>& ids, Index n);

// True when the KKT system of Eq. 14 can be nonsingular with these proxies:
// the m × c matrix B_jc = Σ_{v ∈ component c} Ŵ_jv has rank c (every component
// pinned independently). Otherwise false, with the reason in `why`.
bool proxies_cover_components(const LinearProxies& proxies, const MeshComponents& components, std::string* why);

}  // namespace qpreduce::deform
