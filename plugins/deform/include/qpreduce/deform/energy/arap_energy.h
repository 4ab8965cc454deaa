// qpreduce::deform — ARAP energies (paper Section 3.1, Eq. 6–11): the
// rotation elements (spokes-and-rims on surfaces, one per tet on solids), the
// modified energy E′ as sparse matrices, and the elimination of Q.
//
// Layout. Unknowns u = [V′; Q]: V′ is 3n with vertex i at rows 3i..3i+2 (x,
// y, z interleaved), Q is 4r with element k at rows 3n + 4k..3n + 4k + 3.
// Rotational proxies S are 9d: cluster i at 9i + 3c + r holds s_i(r, c)
// (column-major). Then
//     E′(u, S) = ½ uᵀ L u − Sᵀ Dᵀ u + ½ Sᵀ N S
//     L: (3n + 4r)² symmetric PSD,  D: (3n + 4r) × 9d,  N: 9d × 9d.
// The definitions (Eq. 6–11: weights, measures, the split r_k ≈ s_{i_k} + q_k,
// the penalties, the moving-frame term) and the Q elimination are derived
// in docs/deform.md ("The ARAP energy as matrices").
#pragma once

#include "qpreduce/deform/mesh/mesh.h"

#include <qpreduce/common.h>

#include <string>
#include <utility>
#include <vector>

namespace qpreduce::deform {

struct RotationElements {
  // Edges of element k are [offsets[k], offsets[k+1]).
  std::vector<Index> offsets{0};
  std::vector<int> edge_i, edge_j;
  std::vector<double> weight;      // c_ijk
  Eigen::VectorXd measure;         // a_k, r entries
  Vertices normal;                 // r × 3 unit normals (surfaces), empty for tets
  bool is_surface = true;
  // The index of each element in the set it was selected from
  // (select_elements), r entries; empty: element k is itself. On surfaces
  // element k is the spokes and rims of vertex original[k].
  std::vector<Index> original;

  Index size() const { return static_cast<Index>(offsets.size()) - 1; }
};

// Spokes-and-rims elements of a triangle mesh: V n × 3, F m × 3; r = n
// elements (one per vertex), weights ½ cot of the opposite angle, measures
// the barycentric vertex areas, normals the area-weighted vertex normals.
// Unreferenced vertices get an element with no edges and zero measure.
RotationElements spokes_and_rims_elements(const Vertices& V, const Triangles& F);
// One element per tetrahedron: V n × 3, T m × 4; r = m elements of six
// edges, weights (1/6)·ℓ_opp·cot θ_opp, measures the volumes, no normals.
RotationElements tet_elements(const Vertices& V, const Tetrahedra& T);
// The elements `keep` (ascending indices into `elements`), renumbered 0, 1,
// … in that order, with their edges, weights, measures and normals. E′
// without the moving-frame term (γ = 0) is a sum over elements, so L and D
// assembled on disjoint subsets add up to those of the whole (up to the
// element rows of Q, renumbered). Throws std::invalid_argument on an index
// out of range or not ascending. The moving-frame pairs (element_neighbours)
// of the subset are the pairs of the whole with both elements kept, so an
// element's rows of Q are complete when its neighbours are kept with it.
RotationElements select_elements(const RotationElements& elements, const std::vector<Index>& keep);

struct EnergyParameters {
  // α: overall penalty on the linearised rotation correction q_k (Eq. 10).
  // Larger α keeps each element's rotation closer to its cluster's s_i
  // (stiffer, more rigid clusters); smaller α lets q_k absorb more of the
  // deformation (smoother, closer to full ARAP, but q_k is only a linear
  // approximation of a rotation). See docs/deform.md for the study.
  double alpha = 0.1;
  // β: extra penalty on q_k's action on the normal (surfaces only), which
  // discourages out-of-surface distortion such as bulging.
  double beta = 0.1;
  // γ: moving-frame differential penalty (Eq. 11) between neighbouring
  // rotation elements; 0 (the default) switches it off. It counters folds
  // in sharp bends (paper Fig. 8) at the cost of keeping Q (4 per element)
  // in the factored system. See docs/plugins.md for its effect.
  double gamma = 0.0;

  bool is_valid(std::string* why) const;
};

struct ModifiedArapSystem {
  Index n = 0, r = 0, d = 0;
  SparseMatrix<double> L;  // (3n + 4r) × (3n + 4r)
  SparseMatrix<double> D;  // (3n + 4r) × 9d
  SparseMatrix<double> N;  // 9d × 9d
  bool q_separable = true;  // L_QQ block diagonal (γ = 0): Q can be eliminated
};

// Pairs (k, j), k < j, of neighbouring rotation elements (the set H of
// Eq. 11): surface elements k, j whose vertices share an edge; tets sharing a
// face. Sorted. On a subset (select_elements) the pairs of kept elements,
// in the subset's numbering.
std::vector<std::pair<Index, Index>> element_neighbours(const RotationElements& elements);

// Assembles E′ (Eq. 8–11) as L, D and N (shapes above) for the rest pose V
// (n × 3) and its `elements` (r); cluster_of_element: r entries in [0, d),
// d ≥ 1. q_separable is γ = 0. Throws std::invalid_argument on invalid
// parameters or labels.
ModifiedArapSystem assemble_modified_arap(const Vertices& V, const RotationElements& elements,
                                          const std::vector<int>& cluster_of_element, Index d,
                                          const EnergyParameters& params);

struct EliminatedArapSystem {
  SparseMatrix<double> H;   // 3n × 3n = L_VV − L_VQ L_QQ⁻¹ L_QV
  SparseMatrix<double> Ds;  // 3n × 9d = D_V − L_VQ L_QQ⁻¹ D_Q
  SparseMatrix<double> DV;  // 3n × 9d = D_V, the pure ARAP coupling: DVᵀ·V′
                            // stacks the per-cluster Σ c e′ eᵀ of Phase 2 (Eq. 19)
  SparseMatrix<double> K;   // 9d × 9d = D_Qᵀ L_QQ⁻¹ D_Q, block diagonal (9 × 9 per
                            // cluster): with Q* = L_QQ⁻¹(D_Q S − L_QV V′) the
                            // S-coefficient of E′ is D_Vᵀ V′ + D_Qᵀ Q* = D_sᵀ V′ + K S
};

// The rotation step (Phase 2) for E′, in the reduced deformer and in the
// full-space local-global reference. With Q* = L_QQ⁻¹(D_Q S − L_QV V′) the
// minimiser over Q for the current (V′, S), E′ restricted to S is
// −Sᵀ(D_Vᵀ V′ + D_Qᵀ Q*) + ½SᵀNS, and ½SᵀNS is constant on rotations (γ = 0).
enum class ClusterRotationFit {
  // s_i = nearest rotation of (D_Vᵀ V′ + D_Qᵀ Q*)_i = (D_sᵀ V′ + K S)_i:
  // exact block-coordinate descent on E′ between (V′, Q) and S, whose fixed
  // points are the stationary points of E′ (the minimiser Ceres finds).
  // Linear in the reduced coordinates like the paper's form, so a reduced
  // round costs the same.
  Exact,
  // The paper's Phase 2 (Eq. 19): Q dropped, s_i = nearest rotation of
  // (D_Vᵀ V′)_i. Its fixed point is not the E′ minimiser: the two differ by
  // the Q term, O(‖Q‖) (docs/deform.md, "The rotation step").
  PaperPhase2,
};
const char* to_string(ClusterRotationFit fit);

// Eliminates Q element by element (4 × 4 Schur complements):
// H = L_VV − L_VQ L_QQ⁻¹ L_QV, D_s = D_V − L_VQ L_QQ⁻¹ D_Q. Throws
// std::invalid_argument when an L_QQ block is singular
// (α = 0 with an element whose edges do not determine q_k), or when L_QQ is
// not block diagonal (γ > 0; !system.q_separable).
EliminatedArapSystem eliminate_rotation_corrections(const ModifiedArapSystem& system);

// E′(V′, Q, S) evaluated term by term from Eq. 10–11 (for tests and reports).
// Vp: n × 3, Q: 4r, S: 9d.
double modified_arap_energy(const Vertices& V, const RotationElements& elements,
                            const std::vector<int>& cluster_of_element, const EnergyParameters& params,
                            const Vertices& Vp, const Eigen::VectorXd& Q, const Eigen::VectorXd& S);

// Classic ARAP energy of a deformed pose (Eq. 6 with the best rotation per
// element): ½ Σ_k min_{r_k ∈ SO(3)} Σ_{(i,j)∈G_k} c_ijk ‖e′_ij − r_k e_ij‖².
double arap_energy(const Vertices& V, const RotationElements& elements, const Vertices& Vp);

// Nearest rotation to a 3×3 matrix G in the sense max tr(RᵀG) over SO(3):
// R = U·diag(1, 1, det(UVᵀ))·Vᵀ from G = UΣVᵀ, so det R = +1 even when G is
// reflected (paper Phase 2, Eq. 19).
Eigen::Matrix3d fit_rotation(const Eigen::Matrix3d& G);

// fit_rotation of d 3×3 blocks in place: s holds 9·d entries, block a
// column-major in s[9a, 9a + 9), and each becomes its nearest rotation (the
// same as fit_rotation's to round-off). For the retraction of extrapolated
// rotations: nearly conformal blocks (det > 0 and ‖GᵀG·3/‖G‖² − I‖_F < 0.1,
// fit_rotation's Newton path) take Newton's X ← ½(X + X⁻ᵀ) four at a time in
// SIMD lanes, as many steps as the worst block of the four needs (a step
// more leaves a rotation unchanged to round-off); every other block goes to
// fit_rotation. trace (optional, d entries): tr(RᵀG) of each block, its sum
// of singular values, for the nearest scaled rotation ψR (ψ = trace / 3).
// No heap allocation.
void fit_rotations(double* s, Index d, double* trace = nullptr);

// Nearest rotations of d 3×3 blocks from starts near them, as Phase 2's
// rounds have them: t_a = argmax tr(tᵀG_a) over SO(3) (fit_rotation's, to
// round-off), by Newton's method on SO(3) from start_a's direction
// (start_a·√3/‖start_a‖_F, a rotation or a scaled rotation), four blocks
// at a time in SIMD lanes. A block whose start is not a rotation to
// 10⁻¹³, whose G is beyond 10^±50 in norm, or whose steps do not converge
// (a start far from the answer, a nearest rotation that is not unique)
// goes to fit_rotation; either way a block's result does not depend on
// the other blocks. G, start, t: 9·d entries, block a column-major at
// 9a; t may not alias G or start. Returns how many blocks went to
// fit_rotation. No heap allocation.
Index fit_rotations_near(const double* G, const double* start, double* t, Index d);

// The same rotation when G·n = 0 for a unit vector n, as for the covariance
// G = Σ c e′eᵀ of an element whose rest edges e all lie in the plane n⊥
// (flat parts of a surface), where fit_rotation has to take the SVD path.
// With T = [t₁ t₂] an orthonormal basis of n⊥, G = A·Tᵀ for A = G·T (3 × 2),
// and tr(RᵀG) = Σ (R t_i)·a_i is largest for [R t₁, R t₂] = W = A·(AᵀA)^(−1/2)
// (2 × 2 square root in closed form), so R = [W₁ W₂ W₁×W₂]·[t₁ t₂ n]ᵀ.
// Precondition: ‖G n‖ ≤ 1e-12·‖G‖ (not checked; the result is then exact to
// that order). A (nearly) rank-one A, σ₁σ₂ ≤ 1e-3·(σ₁² + σ₂²), goes to
// fit_rotation.
Eigen::Matrix3d fit_rotation_planar(const Eigen::Matrix3d& G, const Eigen::Vector3d& n);

}  // namespace qpreduce::deform
