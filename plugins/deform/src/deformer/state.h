// Internal: the state of a Deformer session, split the ProxSuite way:
//   Model      what precompute (or load) builds from the mesh and the options
//              (topology, clusters, subspace, reduced operators);
//   OnSite     what set_handles builds for one handle set (Phase 1 operators,
//              the fused rounds, the ties of free Rigid patches);
//   Pose       the results of the last frame (S, X, r₀, w);
//   Workspace  per-frame scratch, sized once;
//   Settings   the runtime options (rounds, global rotation), apart.
// Used by precompute.cpp, state.cpp, onsite.cpp, frame.cpp and cache.cpp.
//
// Shapes (n vertices, r rotation elements, d clusters, m linear proxies,
// s patches, n_u = 3·n_free + 12·s (+ 4r when Q is kept) control unknowns,
// nx = 3m + 12s):
//   subspace B = [N UD]            n_u × (nx + 9d), inside `solver`
//   P (control_matrix)             3n × n_u, sparse, V′ = P·u
//   basis = P·B (float, row-major) 3n × (nx + 9d)
//   MN, MU                         9d × nx, 9d × 9d (Phase 2 input G = MN·X + MU·S)
#pragma once

#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/mesh/geometry.h"

#include <qpreduce/alternation.h>
#include <qpreduce/subspace_solver.h>

#include <string>
#include <utility>
#include <vector>

namespace qpreduce::deform::detail {

using Triplets = std::vector<Eigen::Triplet<double>>;
using RowMatrixF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using RowMatrixD = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// A mesh without its unreferenced vertices; old_of_new maps back.
struct CompactMesh {
  Vertices V;
  Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> E;
  std::vector<Index> old_of_new;
};
// `unreferenced`: ascending vertex indices used by no row of E.
CompactMesh compact_mesh(const Vertices& V, const ElementsRef& E, const std::vector<Index>& unreferenced);

// What precompute was given beyond rest and the patches (kept for save(), so
// that load() can refuse a cache made from other inputs).
struct Inputs {
  Triangles F;
  Tetrahedra T;
  std::vector<int> clusters;
  std::vector<std::vector<Index>> groups;
  DeformerOptions options;
};

// What precompute (or load) builds; constant afterwards.
struct Model {
  Normalization frame;              // rest = (V − c)/σ (normalization_of the given V)
  RotationElements given_elements;  // `elements` in the given units (Deformer::elements)
  double energy_unit = 1.0;         // an energy of the frame times this is in the given units
  // Topology (set_topology).
  Vertices rest;
  RotationElements elements;
  // The mesh's patches, plus an internal Fixed patch (last) for vertices
  // used by no element, when there are any outside the mesh's patches.
  std::vector<int> patch_of_vertex;
  std::vector<PatchType> patch_types;
  MeshComponents components;        // of the elements, reused by precompute
  std::vector<Index> unreferenced;  // vertices used by no element, ascending
  Index n = 0, s = 0;
  Index nu = 0;                        // control-layer size
  Index patch_base = 0;                // first patch unknown (3·n_free); Q (when kept) starts at patch_base + 12s
  bool keep_q = false;                 // Q not eliminated (the model's L_QQ is not block diagonal)
  std::vector<Index> control_of_free;  // vertex → first control row (free vertices), −1 in a patch
  std::vector<Index> fixed_patches;

  // Proxies.
  std::vector<int> clusters;  // per rotation element, in [0, d)
  Index d = 0, m = 0;
  Index nx = 0;                    // 3m + 12s
  Eigen::VectorXd cluster_measure;  // Σ a_k per cluster (global rotation weights)
  // Rigid patches (Eq. 47 with t_s ∈ SO(3)): each has its own rotational
  // cluster, the rotation of its elements; when a handle does not prescribe
  // the patch, Phase 1 ties t_s = s_c (OnSite::tied_patches), so the patch moves
  // rigidly with the rotation Phase 2 fits.
  std::vector<Index> rigid_cluster_of_patch;  // s entries, −1 if not Rigid

  // Subspace and reduced operators.
  SubspaceSolver<double> solver;
  std::shared_ptr<const DeformationModel> energy_model;
  std::unique_ptr<ClusterProjection> projection;  // the energy model's Phase 2
  Matrix<double> MN, MU;  // 9d × nx, 9d × 9d: Phase 2 input G = M_N·X + M_U·S
  RowMatrixF basis;       // 3n × (nx + 9d): rows of P·[N UD], float
  // DeformerOptions::double_basis: the same rows in double here, `basis`
  // empty.
  bool double_basis = false;
  RowMatrixD basis_double;
  Index basis_first = 0;  // this process's rows [basis_first, + basis_count()): all 3n, except after precompute_part
  // After precompute_part with more than one process: its control rows
  // [part_first_row, + part_N.rows()) of N and UD in double, from which
  // basis_rows_from makes float rows when asked (basis_block); basis stays
  // empty. Such a part can only be saved, and the float rows made beside
  // the double ones were the distributed precompute's last peak.
  bool part_held = false;
  Matrix<double> part_N, part_UD;  // rows × nx, rows × 9d
  Index part_first_row = 0, part_vertex_rows = 0;
  Index held_rows() const { return double_basis ? basis_double.rows() : basis.rows(); }
  Index basis_count() const { return part_held ? part_vertex_rows : held_rows(); }
  // For the on-site step's A_r = AᵀB from contiguous rows: the control rows
  // of the patch unknowns, [N UD](patch_base + i, :) (12s × (nx + 9d)), and
  // the vertex of each free control triple (control row 3i + a is basis row
  // 3·free_vertices[i] + a).
  RowMatrixD patch_rows;
  std::vector<Index> free_vertices;

  // Validates the mesh and its patches, and sets rest, n, the patches,
  // control_of_free, nu (without Q) and the rotation elements. Throws
  // std::invalid_argument naming the problem.
  void set_topology(const DeformableMesh& mesh);
  // Appends the 4r Q unknowns to the control layer (keep_q = true).
  void keep_rotation_corrections();
  // Sets the cluster labels (r entries in [0, count), none empty) and their
  // measures. Throws std::invalid_argument.
  void set_clusters(std::vector<int> labels, Index count);
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
  // Row of V′ coordinate (vertex v, axis a) in the control layer, as a sparse
  // combination appended to *t in column `col`: free vertices map to one
  // control entry; patch vertices to t_s(a, ·)·v + d_s(a).
  void control_row(Index v, int a, double scale, Index col, Triplets* t) const;
  // P (3n × n_u): V′ = P·u.
  SparseMatrix<double> control_matrix() const;
  // basis = P·[N UD] in float, the vertex rows that control rows
  // [first_row, first_row + N_rows.rows()) give (all 3n for the whole N, UD;
  // make_basis sets basis_first), once patch_rows is set; through
  // rows × 32 double blocks, never the whole double product.
  void make_basis(Index first_row, const Matrix<double>& N_rows, const Matrix<double>& UD_rows);
  // The vertex rows [first, first + count) that control rows
  // [first_row, first_row + rows) give (see make_basis).
  std::pair<Index, Index> vertex_rows_of(Index first_row, Index rows) const;
  // Rows [first, first + count) of P·[N UD] into *out (count × p, its scalar),
  // from control rows [first_row, first_row + N_rows.rows()) of N, UD (which
  // must hold every control row these vertex rows use) and patch_rows.
  template <typename Rows>  // RowMatrixF, or RowMatrixD for double_basis
  void basis_rows_from(Index first_row, const Matrix<double>& N_rows, const Matrix<double>& UD_rows, Index first,
                       Index count, Rows* out) const;
  // *out += scale · row i of the whole reconstruction basis (whole_basis()),
  // in double, with no temporary (the on-site step's A_r rows).
  template <typename Row>
  void add_basis_row(Index i, double scale, Row&& out) const {
    if (double_basis) {
      out += scale * basis_double.row(i);
    } else {
      out += scale * basis.row(i).cast<double>();
    }
  }
  // patch_rows from the solver's double basis (which it then still holds).
  void take_patch_rows();
  bool whole_basis() const { return basis_first == 0 && held_rows() == 3 * n; }
  // The energy model's projection and free_vertices, once the solver, MN,
  // MU and patch_rows are set.
  void finish_reduction();
};

// What set_handles builds for one handle set.
struct OnSite {
  // Phase 1 and the fused rounds for this handle set (the engine's
  // Alternation: G_z = M_N, G_y = M_U from precompute).
  Alternation<double> alternation;
  bool warm = false;                // a frame ran since set_handles (DeformerOptions::cold_start_rounds)
  Handles handles;
  Index rows = 0;  // constraint rows
  // Ties of the current handle set: free Rigid patches, their rows start at
  // tie_row0 of b. Row 3a + c of tie i follows s_c(a, c) of its cluster
  // (AlternationSetup::follow_y), so the patch moves with the cluster.
  std::vector<Index> tied_patches;
  Index tie_row0 = 0;
  // Why this handle set's rounds run plain whatever anderson_window says
  // (empty: they may be accelerated): a tied free Rigid patch, constraints
  // not solved exactly, or a projection without quadratic_term.
  std::string plain_reason;
  // A dependent set solved on its independent rows (onsite.cpp,
  // reduce_dependent_rows), or a softened set with more rows than the
  // subspace has coordinates, on the rows of its R factor: b = P·(the set's
  // targets), P (fewer rows) × rows; empty otherwise (b is the targets).
  Matrix<double> target_projection;
};

// Why a handle set's rounds cannot be accelerated nor corrected for point
// handles before its constraints are solved (the paper's Eq. 19 step, a tie
// to a free Rigid patch, a projection without quadratic_term), or "": then
// set_handles asks the alternation for Phase 1's energy terms.
std::string plain_reason(const Model& model, bool exact_rotation_fit, bool tied);

// The results of the last frame (warm start of the next one).
struct Pose {
  Eigen::VectorXd S;  // 9d, world frame
  Eigen::VectorXd x;  // nx
  Eigen::Matrix3d r0 = Eigen::Matrix3d::Identity();
  Eigen::VectorXf wf;  // [X; S_local] in float (reduced_coordinates)
  Eigen::VectorXd wd;  // the same in double, with Model::double_basis
};

// Per-frame scratch (sized once by finish).
struct Workspace {
  Eigen::VectorXd b;          // Phase 1's right-hand side: b_targets, or P·b_targets (OnSite::target_projection)
  Eigen::VectorXd b_targets;  // handle targets in the frame of r₀ (OnSite::rows)
  Eigen::VectorXd s_local;  // 9d: S in the frame of r₀
  // b and s_local in the last frame's r₀, while frame() weighs a refitted r₀.
  Eigen::VectorXd b_kept, s_kept;
  // The last good pose's x and r₀, put back when a frame's rounds fail
  // (NaN): the pose stays the last good one and the next frame starts there.
  Eigen::VectorXd x_before;
  Eigen::Matrix3d r0_before = Eigen::Matrix3d::Identity();
};

// The runtime options (DeformerOptions: iterations, float_rounds,
// round_threads, global_rotation).
struct Settings {
  AlternationSettings alternating;
  bool global_rotation = true;
  int cold_start_rounds = 500;        // DeformerOptions::cold_start_rounds
  double cold_start_tolerance = 1e-6;  // DeformerOptions::cold_start_tolerance
  bool soften_unreachable_handles = true;  // DeformerOptions::soften_unreachable_handles
};

// Sets the sizes of `model` in *summary (vertices, elements, proxies,
// patches, reduced size).
void describe(const Model& model, PrecomputeSummary* summary);

}  // namespace qpreduce::deform::detail

namespace qpreduce::deform {

struct Deformer::State {
  detail::Inputs inputs;
  detail::Model model;
  detail::Settings settings;
  detail::OnSite onsite;
  detail::Pose pose;
  detail::Workspace work;
  bool ready = false;

  // With float rounds, G_z·T (the largest product of a new handle set) in
  // float too (FusedPrecision); finish() sets settings.alternating.float_products.
  FusedPrecision fused_precision() const {
    return settings.alternating.float_products ? FusedPrecision::Float : FusedPrecision::Double;
  }
  // After model.solver, basis, MN and MU are set: finishes the model, sizes
  // the pose and the workspace, takes the runtime options, and prepares
  // Phase 1 and the fused rounds for any handle set; ready = true.
  void finish(const DeformerOptions& options);
};

}  // namespace qpreduce::deform
