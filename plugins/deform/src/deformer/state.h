// Internal: the state of a Deformer session, shared by deformer.cpp
// (precompute, on-site step, frames) and deformer_cache.cpp (save/load).
//
// Shapes (n vertices, r rotation elements, d clusters, m linear proxies,
// s patches, n_u = 3·n_free + 12·s (+ 4r when Q is kept) control unknowns,
// nx = 3m + 12s):
//   subspace B = [N UD]            n_u × (nx + 9d), inside `solver`
//   P (control_row)                3n × n_u, sparse, V′ = P·u
//   basis = P·B (float, row-major) 3n × (nx + 9d)
//   MN, MU                         9d × nx, 9d × 9d (Phase 2 input G = MN·X + MU·S)
#pragma once

#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/mesh/geometry.h"

#include <qpreduce/alternating.h>
#include <qpreduce/subspace_solver.h>

#include <vector>

namespace qpreduce::deform::detail_deformer {

using Triplets = std::vector<Eigen::Triplet<double>>;
using RowMatrixF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// A mesh without its unreferenced vertices; old_of_new maps back.
struct CompactMesh {
  Vertices V;
  Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> E;
  std::vector<Index> old_of_new;
};
// `unreferenced`: ascending vertex indices used by no row of E.
CompactMesh compact_mesh(const Vertices& V, const ElementsRef& E, const std::vector<Index>& unreferenced);

}  // namespace qpreduce::deform::detail_deformer

namespace qpreduce::deform {

struct Deformer::State {
  using Triplets = detail_deformer::Triplets;
  using RowMatrixF = detail_deformer::RowMatrixF;

  // What precompute was given beyond rest and the patches (kept for save(),
  // so that load() can refuse a cache made from other inputs).
  struct Inputs {
    Triangles F;
    Tetrahedra T;
    std::vector<int> clusters;
    std::vector<std::vector<Index>> groups;
    DeformerOptions options;
  } inputs;
  // Model.
  Vertices rest;
  RotationElements elements;
  std::vector<int> clusters;
  // The model's patches, plus an internal Fixed patch (last) for vertices
  // used by no element, when there are any outside the model's patches.
  std::vector<int> patch_of_vertex;
  std::vector<PatchType> patch_types;
  MeshComponents components;        // of the elements (set_topology), reused by precompute
  std::vector<Index> unreferenced;  // vertices used by no element, ascending
  Index n = 0, d = 0, m = 0, s = 0;
  Index nu = 0;                        // control-layer size
  Index patch_base = 0;                // first patch unknown (3·n_free); Q (when kept) starts at patch_base + 12s
  bool keep_q = false;                 // Q not eliminated (the model's L_QQ is not block diagonal)
  std::vector<Index> control_of_free;  // vertex → first control row (free vertices), −1 in a patch
  std::vector<Index> fixed_patches;
  // Rigid patches (Eq. 47 with t_s ∈ SO(3)): each has its own rotational
  // cluster, the rotation of its elements; when a handle does not prescribe
  // the patch, Phase 1 ties t_s = s_c (9 constraint rows whose right-hand
  // side is that cluster's rotation, folded into the y-map below), so the
  // patch moves rigidly with the rotation Phase 2 fits.
  std::vector<Index> rigid_cluster_of_patch;  // s entries, −1 if not Rigid
  Eigen::VectorXd cluster_measure;     // Σ a_k per cluster (global rotation weights)
  // Subspace and reduced operators.
  SubspaceSolver<double> solver;
  std::shared_ptr<const DeformationModel> model;
  std::unique_ptr<ClusterProjection> projection;  // the model's Phase 2
  Matrix<double> MN, MU;  // 9d × nx, 9d × 9d: Phase 2 input G = M_N·X + M_U·S
  FusedAlternation<double> fused;
  bool fused_inputs_plain = false;  // fused was last set with G_z = MN, G_y = MU (MN, MU never change after precompute)
  // With float rounds, G_z·T (the largest product of a new handle set) in
  // float too (FusedPrecision); finish() sets alternating.float_products.
  FusedPrecision fused_precision() const {
    return alternating.float_products ? FusedPrecision::Float : FusedPrecision::Double;
  }
  RowMatrixF basis;       // 3n × (nx + 9d): rows of P·[N UD], float
  Index nx = 0;           // 3m + 12s
  // For the on-site step's A_r = AᵀB from contiguous rows: the control rows
  // of the patch unknowns, [N UD](patch_base + i, :) (12s × (nx + 9d),
  // double), and the vertex of each free control triple (control row 3i + a
  // is basis row 3·free_vertices[i] + a).
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> patch_rows;
  std::vector<Index> free_vertices;
  // On-site.
  FixedCoordinateSolver<double> phase1;
  Handles handles;
  Index rows = 0;
  // Ties of the current handle set: free Rigid patches, their rows start at
  // tie_row0 of b. With E (9·ties × 9d) selecting s_c(a, c) for row 3a + c of
  // tie i, X = M_b·b + M_Y·S + tie_map·S, tie_map = M_b[:, ties]·E (nx × 9d),
  // and Phase 2 sees G = M_N·X + (M_U + M_N·tie_map)·S.
  std::vector<Index> tied_patches;
  Index tie_row0 = 0;
  Matrix<double> tie_map, MU_tied;
  // Pose.
  Eigen::VectorXd S;  // 9d, world frame
  Eigen::VectorXd x;  // nx
  Eigen::Matrix3d r0 = Eigen::Matrix3d::Identity();
  // Frame workspaces (sized once).
  Eigen::VectorXd b, s_local, w;
  Eigen::VectorXf wf, vf;
  AlternatingOptions alternating;
  bool global_rotation = true;
  bool ready = false;

  // Validates the mesh and the patches of `model`, and sets rest, n, the
  // patches, control_of_free, nu (without Q) and the rotation elements.
  // Throws std::invalid_argument naming the problem.
  void set_topology(const DeformableMesh& model);
  // Appends the 4r Q unknowns to the control layer (keep_q = true).
  void keep_rotation_corrections();
  // Gives every Rigid patch its own cluster (its elements: the patch's
  // vertices on surfaces; tets with all corners in the patch, else any
  // corner), appended after the others; empty clusters are dropped. Sets
  // rigid_cluster_of_patch. `T` are the tets (empty for surfaces).
  void separate_rigid_clusters(const Tetrahedra& T);
  // Finds rigid_cluster_of_patch in labels made by separate_rigid_clusters
  // (after a load); throws std::invalid_argument if they do not fit.
  void find_rigid_clusters(const Tetrahedra& T);
  // The elements of patch p (see separate_rigid_clusters).
  std::vector<Index> patch_elements(Index p, const Tetrahedra& T) const;
  // Sets the cluster labels (r entries in [0, d), none empty) and their
  // measures. Throws std::invalid_argument.
  void set_clusters(std::vector<int> labels, Index count);
  // Row of V′ coordinate (vertex v, axis a) in the control layer, as a sparse
  // combination: free vertices map to one control entry; patch vertices to
  // t_s(a, ·)·v + d_s(a).
  void control_row(Index v, int a, double scale, Index col, Triplets* t) const;
  // P (3n × n_u): V′ = P·u.
  SparseMatrix<double> control_matrix() const;
  // basis = P·[N UD] in float (3n × (nx + 9d)), once the solver holds the
  // subspace; through 3n × 32 double blocks, never the whole double product.
  void make_basis(const SparseMatrix<double>& P);
  // After the solver, basis, MN and MU are set: the model's projection,
  // patch_rows and free_vertices, the frame workspaces and the runtime
  // options; ready = true.
  void finish(const DeformerOptions& options);
};

}  // namespace qpreduce::deform
