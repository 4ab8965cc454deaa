// qpreduce::deform — the plugin contract: how a deformation model plugs into
// the reduced deformer without touching the engine (docs/plugins.md).
//
// A model supplies two things (the plugin owns the physics, the engine the
// linear algebra):
//
//  1. Energy blocks. A quadratic energy in u = [V′ (3n); Q (4r)] and the
//     cluster coordinates S (9d, cluster a at 9a..9a+8, column-major 3×3):
//         E(u, S) = ½ uᵀ L u − Sᵀ Dᵀ u + ½ Sᵀ N S,
//         L (3n + 4r)² symmetric PSD,  D (3n + 4r) × 9d,  N 9d × 9d,
//     with [[L, −D], [−Dᵀ, N]] PSD. The deformer eliminates Q when L_QQ is
//     4×4 block diagonal (q_separable), otherwise keeps Q as unknowns; either
//     way it factors ONE system (the engine's variational subspace, Eq. 14–15),
//     adds the affine-patch control layer (Eq. 47) and the linear proxies.
//     Phase 1 (Eq. 17) is then the engine's, with S held fixed.
//
//  2. A Phase 2 projection (ClusterProjection). Each round the engine hands
//     it g = D_Vᵀ·V′ (9d: per cluster a, G_a = Σ_{k∈a} Σ c_ijk e′_ij e_ijᵀ,
//     the ARAP coupling with Q = 0, paper Eq. 19 and 48) and the current S,
//     and it overwrites S with the cluster transforms that minimise its
//     Phase 2 energy (rotations for ARAP, scaled rotations for conformal).
//     Clusters listed in ClusterGeometry::rigid (rigid affine patches) must
//     stay rotations whatever the model.
//
// The built-in models: make_arap_model (E′ of Eq. 8–11, rotations) and
// make_conformal_model (the same energy, scaled rotations s = ψ·t with
// ψ ∈ [1/ψ_max, ψ_max], Eq. 48–49). A custom model is given to the deformer
// through DeformerOptions::custom_model.
#pragma once

#include "qpreduce/deform/energy/arap_energy.h"

#include <qpreduce/alternation.h>

#include <memory>
#include <string>
#include <vector>

namespace qpreduce::deform {

// What the deformer knows about the clusters when it builds the projection.
struct ClusterGeometry {
  Index d = 0;
  // Σ a_k over the cluster's elements (global rotation weights), d entries.
  Eigen::VectorXd measure;
  // C_a = Σ_{k∈a} Σ_{(i,j)∈G_k} c_ijk‖e_ij‖² (> 0; the "C" of Eq. 49: the
  // Phase 2 energy of s_a = ψ·t is −ψ·tr(tᵀG_a) + ½ψ²·C_a), d entries.
  Eigen::VectorXd stiffness;
  // W_ab = Σ a_kj over neighbouring element pairs (k ∈ a, j ∈ b), a ≠ b
  // (Eq. 11's cluster coupling), symmetric d × d, zero diagonal.
  SparseMatrix<double> coupling;
  // Clusters that are rigid patches' rotations: the projection must return
  // rotations there (d entries, 0/1).
  std::vector<char> rigid;
};

// Builds the ClusterGeometry of rotation elements grouped into d clusters.
//   V         n × 3 rest positions
//   elements  r rotation elements over V (arap_energy.h)
//   clusters  r labels in [0, d), one per element
//   d         number of clusters
//   rigid     d flags (1: a rigid patch's cluster), or empty: none rigid
// Returns measure, stiffness (d each), coupling (d × d) and rigid (d).
// Throws std::invalid_argument on a label outside [0, d), sizes that
// disagree, or a cluster with C_a ≤ 0 (its scale and rotation undetermined).
ClusterGeometry cluster_geometry(const Vertices& V, const RotationElements& elements,
                                 const std::vector<int>& clusters, Index d, std::vector<char> rigid = {});

// Σ_{a<b} W_ab‖s_a − s_b‖²_F: how much neighbouring cluster transforms differ,
// what γ (Eq. 11) penalises.
//   geometry  the clusters' ClusterGeometry (its coupling W, d × d)
//   S         9d cluster transforms (cluster a at 9a..9a+8, column-major 3 × 3)
double cluster_rotation_roughness(const ClusterGeometry& geometry, const Eigen::Ref<const Eigen::VectorXd>& S);

// Phase 2 of a model: an InputProjection (engine) that also knows its
// manifold, so the invariant kit (qpreduce/testing) can check it.
class ClusterProjection : public InputProjection<double> {
 public:
  // project(g, y): y (9d) ← the model's Phase 2 update from g (9d) and the
  // current y; returns ‖Δy‖. No heap allocation.

  // y ← the nearest valid element, cluster by cluster (idempotent).
  virtual void retract(Eigen::Ref<Eigen::VectorXd> y) const = 0;
  // Whether every cluster block of y is a valid element within `tolerance`;
  // otherwise *why names the first offending cluster.
  virtual bool valid(const Eigen::Ref<const Eigen::VectorXd>& y, double tolerance, std::string* why) const = 0;
  // The Phase 2 energy the update decreases, up to a constant:
  //     Σ_a (−tr(s_aᵀG_a) + ½‖s_a‖²_F·C_a/3) + γ·Σ_{a<b} W_ab‖s_a − s_b‖²_F
  // (‖s_a‖²_F·C_a/3 = ψ_a²·C_a for s_a = ψ_a·t_a: constant on rotations).
  virtual double energy(const Eigen::Ref<const Eigen::VectorXd>& g, const Eigen::Ref<const Eigen::VectorXd>& y) const = 0;
};

// A deformation model (the plugin contract above): its energy blocks and its
// Phase 2 projection. Implementations are immutable and shared between
// deformers (std::shared_ptr<const DeformationModel>).
class DeformationModel {
 public:
  virtual ~DeformationModel() = default;
  // Short name, stored in caches and reports ("arap", "conformal", ...).
  virtual std::string name() const = 0;
  // Parameters that change what precompute makes, as (name, value) pairs in
  // a fixed order (stored in caches and compared on load).
  virtual std::vector<std::pair<std::string, double>> parameters() const = 0;
  // The energy blocks for rest positions V (n × 3), rotation elements and
  // their cluster labels (r entries in [0, d)). Throws std::invalid_argument
  // on bad input. The rows of V′ must be sums of per-element terms, and so
  // must the rows of Q when the result is q_separable (each element's own 4
  // rows); otherwise an element's rows of Q must be complete whenever it is
  // assembled with its neighbours (element_neighbours, which on a subset
  // keeps the pairs of kept elements). Deformer::precompute_part assembles
  // subsets of the elements (select_elements) on different processes and
  // adds or keeps their rows accordingly.
  virtual ModifiedArapSystem assemble(const Vertices& V, const RotationElements& elements,
                                      const std::vector<int>& clusters, Index d) const = 0;
  // The Phase 2 projection for these clusters.
  virtual std::unique_ptr<ClusterProjection> projection(const ClusterGeometry& geometry) const = 0;
};

// E′ of Eq. 8–11 with rotations (paper Phase 2, Eq. 19; with γ > 0 the
// cluster rotations are updated block by block, Gauss–Seidel over clusters,
// from G_a + 2γ·Σ_b W_ab s_b).
//   energy  α, β, γ of E′ (β acts on surfaces only; ignored for tets)
// Throws std::invalid_argument when `energy` is not valid.
std::shared_ptr<const DeformationModel> make_arap_model(const EnergyParameters& energy);

// Conformal-like deformation (appendix, Eq. 48–49): the same energy, with
// s_a = ψ_a·t_a, t_a ∈ SO(3), ψ_a ∈ [1/psi_max, psi_max]. Phase 2 in two
// steps per cluster: t_a = nearest rotation of G̃_a (Ψ fixed), then
// ψ_a = clamp(tr(t_aᵀG̃_a) / (C_a + 6γ·Σ_b W_ab)) in closed form (T fixed).
// Rigid clusters keep ψ = 1.
//   energy   α, β, γ of E′, as for make_arap_model
//   psi_max  the largest scale, finite and > 1
// Throws std::invalid_argument when `energy` is not valid or psi_max ≤ 1.
std::shared_ptr<const DeformationModel> make_conformal_model(const EnergyParameters& energy, double psi_max);

}  // namespace qpreduce::deform
