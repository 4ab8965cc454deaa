// qpreduce::deform — the reduced ARAP deformer session (paper Section 3.2):
// precompute → set handles (on-site step, "OP") → frames.
//
// Unknowns: the control layer u = [V′_free; t_s, d_s per affine patch s]
// (n_u), V′ = P·u (Eq. 47); the engine's variational subspace (Eq. 14–15)
// gives u = N·X + UD·S with X the linear proxies (3 per proxy, 12 per patch)
// and S the rotational proxies (9 per cluster). Each frame runs k rounds of
// Phase 1 (Eq. 17) and Phase 2 (Eq. 19, the model's projection), then
// reconstructs V′ = r₀·(P·[N UD]·[X; S_local]) in float. The derivation, the
// global rotation adaptation and the source layout are in docs/deform.md
// ("Inside the deformer").
#pragma once

#include "qpreduce/deform/energy/arap_energy.h"
#include "qpreduce/deform/mesh/mesh.h"
#include "qpreduce/deform/energy/model.h"
#include "qpreduce/deform/proxies/proxies.h"
#include "qpreduce/deform/deformer/handles.h"

#include <qpreduce/alternation.h>
#include <qpreduce/subspace_solver.h>

#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace qpreduce::deform {

// The built-in models of model.h.
enum class ModelKind { Arap, Conformal };

struct DeformerOptions {
  EnergyParameters energy;
  // The deformation model (plugin contract, model.h): ARAP (rotations) or
  // conformal-like (scaled rotations within [1/conformal_bound,
  // conformal_bound], Eq. 48–49), both over the energy E′ of `energy`.
  ModelKind model = ModelKind::Arap;
  // ψ_max of the conformal model (> 1). 2 lets a cluster shrink to half or
  // grow to twice its size: enough for the uniform scalings of the paper's
  // Fig. 10 setting, while keeping ψ from running away where few handles
  // leave a region unconstrained.
  double conformal_bound = 2.0;
  // A model of your own (docs/plugins.md); when set, it replaces `model` and
  // `energy`.
  std::shared_ptr<const DeformationModel> custom_model;
  // Automatic proxy counts, used when the model does not give them. The
  // paper's Table 1 uses 20–60 of each; 27 rotational clusters and 33 linear
  // proxies are its Cactus/Bumpy Plane setting.
  Index rotational_proxies = 27;
  Index linear_proxies = 33;
  ClusterOptions clustering;
  // The rotation step of Phase 2 (arap_energy.h): Exact fits each cluster
  // rotation to its exact covariance with the Q-corrections (block-coordinate
  // descent on E′: with an exact subspace the fixed point is the full-space
  // E′ minimiser); PaperPhase2 is Eq. 19 (Q dropped). Same cost per round.
  ClusterRotationFit rotation_fit = ClusterRotationFit::Exact;
  // A frame runs rounds of Phase 1/Phase 2 until its relative fixed-point
  // residual ‖ΔS‖/‖S‖ (FrameSummary::fixed_point_residual) is at most
  // `tolerance`, or the rounds have run `time_budget` seconds, or
  // `iterations` rounds ran, whichever comes first (FrameSummary::stop says
  // which; the budget is checked after each round). The defaults put each
  // frame at its fixed point where that takes under 4 ms of rounds and
  // continue from there in the next frame (docs/deform.md, "Rounds per
  // frame"). The paper's setting, 8 rounds whatever the pose: iterations 8,
  // tolerance 0, time_budget 0 (Deformer::set_rounds(8)). The cold start
  // (below) has no budget. iterations ≥ 1; tolerance and time_budget finite
  // and ≥ 0 (0: no test).
  int iterations = 1000;
  double tolerance = 1e-6;
  double time_budget = 0.004;
  // Anderson acceleration of the rounds (AlternationSettings::anderson_window,
  // Peng et al. 2018) with the energy safeguard: 0 off, else the window
  // (1–16). Needs rotation_fit Exact (the safeguard's energy is E′ at the
  // exact Phase 2 input). With rotation_fit Exact set_handles forms Phase 1's
  // energy terms whatever the window (O(m·d·k) per handle set): point
  // handles at vertices move with the cluster rotations, and the rounds then
  // step on E′ itself (docs/engine.md, "Constraints on y"). Handle sets that tie a free Rigid patch to its
  // cluster run plain rounds (FrameSummary::message says so). The default 5
  // (docs/quality.md, "Accelerated rounds"): with the exact step, plain rounds
  // converge more slowly than the paper's, and 8 accelerated rounds reach a
  // lower E′ than 8 plain rounds of either. Set 0 with PaperPhase2.
  int anderson_window = 5;
  // Stiff point-handle sets (docs/engine.md, "Constraints on y"):
  // Riemannian Newton steps on E′ over the cluster rotations instead of
  // rounds, `iterations` of them per frame (ARAP without γ; each costs about
  // a dozen rounds). false: rounds always (they then crawl on such sets:
  // docs/robustness.md, "Soak").
  bool second_order = true;
  // The first frame after set_handles is a cold start: new handles whose
  // targets may lie far from the pose. It runs until its fixed-point
  // residual is at most cold_start_tolerance (or `tolerance` when that is
  // smaller and > 0), for at most cold_start_rounds rounds; a second-order
  // step counts as kRoundsPerSecondOrderStep rounds. The frames after it run
  // as `iterations` and `tolerance` say. cold_start_rounds 0: the first
  // frame runs like the others.
  int cold_start_rounds = 500;
  double cold_start_tolerance = 1e-6;
  static constexpr int kRoundsPerSecondOrderStep = 10;
  // A hard handle set the subspace cannot meet reliably: its rows have lower
  // rank in the subspace than in the full space (more point handles than the
  // proxies can follow, e.g. every vertex of a region as its own handle), or
  // condition above 10⁵ there over the rank it has (the float basis's
  // round-off, 6·10⁻⁸, can then move the exact answer by more than 1 %). Its
  // exact (least-squares) answer is ill-posed: the singular values decay to
  // round-off without a gap, and fitting targets along them blows the pose
  // up (docs/robustness.md, "Soak", hostile sets). true: set_handles solves
  // such a set as soft constraints (Eq. 18, ConstraintOptions::delta),
  // bounded, and returns ConstraintsLeastSquares with the reason; a set with
  // more rows than the subspace has coordinates is compressed to as many
  // (the same soft minimiser), so the rounds step on E′. Sets that are merely
  // dependent (a vertex held twice, a group over held vertices) have the
  // same rank in both spaces and stay exact: their targets are projected
  // onto their independent rows (the least-squares answer), which hold
  // exactly; so do sets that tie a free Rigid patch. false: the exact
  // (least-squares) form always.
  bool soften_unreachable_handles = true;
  // Factor out a global rotation each frame (appendix "Global rotation
  // adaptation"), refitted from the cluster rotations; with accelerated
  // rounds or second-order steps a refit whose rounds end above the warm
  // start's E′ in the last one is not kept (FrameSummary::rotation_kept).
  bool global_rotation = true;
  // Phase 2 inputs from a float product relative to a double reference in
  // each round (AlternationSettings::float_products): the fixed points of
  // double rounds at about a float round's cost; the handles hold to double
  // precision. false: every round in double.
  bool float_rounds = true;
  // OpenMP threads for a frame's rounds (AlternationSettings::threads): they
  // split the clusters when the model's Phase 2 is cluster-separable (γ = 0)
  // and 9d ≥ 256; 0: omp_get_max_threads(). Serial by default: a round is
  // too short for a barrier to pay on most models (docs/deform.md,
  // "Defaults"). The reconstruction always uses all threads.
  int round_threads = 1;
  // Prepare Phase 1's per-solver part at precompute (H_zz's lifted inverse
  // and responses: a d × d eigendecomposition, d = 3 × linear proxies + 12 ×
  // patches), so that the first handle set costs what the later ones do.
  // false: at the first set_handles that needs it; sets whose every row holds
  // a linear proxy that is one vertex never do (Phase 1 eliminates them).
  // ArapSolver sets false: its one handle set is of that kind.
  bool prepare_onsite = true;
  // Keep the reconstruction basis P·[N UD] and the reduced coordinates in
  // double instead of float: twice the basis's memory, cache and bytes read
  // per frame, for poses that carry double round-off (a rigidly moved or
  // renumbered scene gives its pose moved to about 10⁻¹⁵ of the diagonal,
  // not a few float roundings, 10⁻⁷: docs/robustness.md, "Units").
  // reconstruction_basis_double() and reduced_coordinates_double() then hold
  // them; reconstruction_basis() is empty. Not with precompute_part on more
  // than one process (its rows travel in float).
  bool double_basis = false;
  SubspaceOptions subspace;

  bool is_valid(std::string* why) const;
  // The model these options select: custom_model, or make_arap_model(energy),
  // or make_conformal_model(energy, conformal_bound).
  std::shared_ptr<const DeformationModel> resolve_model() const;
};

// Called during precompute with a stage name and the overall fraction done.
using ProgressFn = std::function<void(const std::string& stage, double fraction)>;

struct PrecomputeSummary : Outcome {
  Index vertices = 0, elements = 0, rotational_proxies = 0, linear_proxies = 0, patches = 0;
  Index reduced_size = 0;  // 3m + 12s + 9d
  // The rotation elements this process assembled: all of them, except in
  // Deformer::precompute_part with more than one process (its elements and
  // the neighbours its rows need).
  Index assembled_elements = 0;
  SubspaceSummary subspace;
  double clustering_seconds = 0.0, assembly_seconds = 0.0, subspace_seconds = 0.0, reduction_seconds = 0.0,
         total_seconds = 0.0;

 protected:
  void add_details(Report* out) const override;
};

struct FrameSummary : Outcome {  // Success after a frame
  int iterations = 0;
  double last_change = 0.0;        // ‖ΔS‖ of the last Phase 2
  // The relative fixed-point residual ‖ΔS‖/‖S‖ of the last round: how far
  // the pose is from the alternation's fixed point (0 at the fixed point).
  double fixed_point_residual = 0.0;
  // Accelerated rounds (DeformerOptions::anderson_window): E′ of the reduced
  // model at the pose's rotations, in the frame of the global rotation (NaN
  // for plain rounds), and how many extrapolations the safeguard rejected.
  // With second-order steps (second_order below) E′ too, and rejected_steps
  // counts the steps the energy test refused.
  double model_energy = std::numeric_limits<double>::quiet_NaN();
  int rejected_steps = 0;
  // This frame took second-order steps (DeformerOptions::second_order on a
  // stiff point-handle set) instead of rounds: `iterations` counts steps.
  bool second_order = false;
  // The first frame after set_handles (DeformerOptions::cold_start_rounds):
  // it ran to cold_start_tolerance instead of `iterations` rounds.
  bool cold_start = false;
  // In the refitted global rotation the rounds ended above the warm start's
  // E′ in the last one, so they ran again there in what was left of the
  // budget and the cap (at least one round): the frame kept the last r₀
  // (`iterations` and `rejected_steps` count both runs).
  bool rotation_kept = false;
  // What ended the rounds: the cap (`iterations`), the tolerance, or the
  // time budget (DeformerOptions::time_budget).
  RoundStop stop = RoundStop::RoundLimit;
  double solve_seconds = 0.0;      // the alternating rounds
  double reconstruct_seconds = 0.0;
  double total_seconds = 0.0;

 protected:
  void add_details(Report* out) const override;
};

class Deformer {
 public:
  Deformer();
  ~Deformer();
  Deformer(Deformer&&) noexcept;
  Deformer& operator=(Deformer&&) noexcept;

  // Throws std::invalid_argument on an invalid model or options (sizes,
  // labels out of range, degenerate elements, a component without a linear
  // proxy or patch). Numerical failures come back in the summary.
  PrecomputeSummary precompute(const DeformableMesh& model, const DeformerOptions& options = {},
                               const ProgressFn& progress = {});

  // A precompute whose subspace is built across processes (`qpr precompute`
  // under mpirun: qpreduce::distributed's MUMPS build), no process holding
  // the whole n_u × n_u H_u nor the whole n_u × p double basis B = [N UD].
  // Every process calls it together with the same model and options and its
  // place in the partition: process r of K owns the control rows
  // [⌊r·n_u/K⌋, ⌊(r+1)·n_u/K⌋) (qpreduce::distributed::owned_rows). Then:
  //   assembly — each process assembles the energy only on the rotation
  //     elements its rows need (those with a vertex whose control rows it
  //     owns; the rows of a patch's 12 unknowns are summed over the
  //     processes from each one's own elements), and gets its rows of H_u
  //     (rows × n_u) and of D_u (rows × 9d); C (n_u × nx, one entry per
  //     proxy vertex) is whole everywhere. A model whose L_QQ is not block
  //     diagonal (γ > 0: Q stays in u) is assembled whole and sliced.
  //     Elements follow the vertex order, so a mesh whose vertex numbering
  //     has no locality (a random permutation) leaves each process nearly
  //     every element: PrecomputeSummary::assembled_elements says how many;
  //   `build` gets these rows, fills this process's SubspacePart — its rows
  //     of N and UD (first_row must be its first owned row), and the whole
  //     H_r = BᵀH_uB (p × p) and BᵀD_u (p × 9d) as SubspaceSolver::precompute
  //     would make them — and returns a summary; one that is not ok() ends
  //     precompute with its status (it must be the same on every process);
  //   `sum` replaces a matrix by its sum over the processes, on every
  //     process (an all-reduce; the same shape everywhere).
  // The reduced operators are sums over the rows of B (M_N = D_uᵀ·N etc.,
  // the rows of the patch unknowns, ‖B_j‖), so every process ends with all
  // of them, and with the rows basis_rows() of the float reconstruction
  // basis P·B: the vertex rows whose control unknowns it owns (contiguous;
  // rows of patch vertices go with the free row before them). With K > 1 it
  // keeps its rows of B in double and makes the float rows when asked
  // (basis_block), so that the two are never held together;
  // reconstruction_basis() is then empty. Such a deformer can only be saved,
  // with the other processes' rows, by save(path, blocks) on one process;
  // set_handles refuses it. With K = 1 it is an ordinary deformer.
  struct SubspacePart {
    Index first_row = 0;             // N_rows, UD_rows are rows [first_row, first_row + rows) of N, UD
    Matrix<double> N_rows, UD_rows;  // rows × nx, rows × 9d
    Matrix<double> Hr, BtD;          // p × p, p × 9d: whole, the same on every process
  };
  struct Partition {
    int process = 0, processes = 1;  // this process r and the count K (the MPI rank and size)
  };
  // H: this process's rows of H_u (rows × n_u); C whole (n_u × nx); D: its
  // rows of D_u (rows × 9d).
  using PartBuilder = std::function<SubspaceSummary(const SparseMatrix<double>& H, const SparseMatrix<double>& C,
                                                    const SparseMatrix<double>& D, const SubspaceOptions& options,
                                                    SubspacePart* part)>;
  using SumOverProcesses = std::function<void(Matrix<double>* M)>;
  PrecomputeSummary precompute_part(const DeformableMesh& model, const DeformerOptions& options,
                                    const ProgressFn& progress, Partition partition, const PartBuilder& build,
                                    const SumOverProcesses& sum);
  // Rows [first, first + count) of the reconstruction basis (3n rows in all)
  // that this deformer has (basis_block): all of them, except after
  // precompute_part with more than one process.
  struct RowBlock {
    Index first = 0, count = 0;
  };
  RowBlock basis_rows() const;
  using BasisRows = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  // Rows [first, first + count) of the float reconstruction basis (count × p),
  // within basis_rows(): a copy of reconstruction_basis()'s, or after
  // precompute_part with K > 1 made from this process's double rows of B
  // (the same floats make_basis would store). Throws std::invalid_argument
  // outside basis_rows() or before precompute.
  void basis_block(Index first, Index count, BasisRows* rows) const;

  // Writes the precomputed model to `path` (binary, versioned, CRC-32
  // checked; layout in docs/formats.md: the float reconstruction basis in row
  // blocks and the reduced operators, not the double basis), through a
  // temporary file renamed at the end so an existing cache is never left
  // half-written. Throws IoError when the file cannot be written,
  // std::invalid_argument before precompute or when this deformer holds only
  // part of the basis (after precompute_part: use the form below).
  void save(const std::string& path) const;
  // The same with the reconstruction basis supplied in row blocks: `next` is
  // called until it returns false, each time filling the next block's first
  // row and its rows (p columns; each block starts where the last ended and
  // together they cover the 3n rows). Throws std::invalid_argument (and
  // leaves no file) when the blocks do not tile the 3n rows, have another
  // width, or hold NaN/Inf.
  using BasisBlocks = std::function<bool(Index* first_row, BasisRows* rows)>;
  void save(const std::string& path, const BasisBlocks& next) const;

  // Reads a model written by save() instead of precomputing it. `model` and
  // `options` must be what precompute was given: the file keeps them and
  // load compares (rest positions, elements, patches, given proxies, energy
  // and proxy options); the runtime options (iterations, global_rotation)
  // are taken from `options`. Throws IoError naming the file and the problem
  // for a missing, truncated or corrupted file, another format version, or a
  // cache made from other inputs; the session is then left as it was.
  PrecomputeSummary load(const std::string& path, const DeformableMesh& model, const DeformerOptions& options = {});

  // The on-site step: forms the reduced constraint operators for this handle
  // set. Fixed patches are always included. Cost independent of n (a few rows
  // of the subspace per handle; with point handles also O(k²·m) for the
  // rounds' correction and its proximal weights, k = 9·rotational proxies).
  ConstraintSummary set_handles(const Handles& handles, const ConstraintOptions& options = {});

  // One frame: alternation warm-started from the previous frame, then
  // reconstruction into *out (n × 3, resized once). With out == nullptr the
  // reconstruction is left to the caller (e.g. a GPU, paper Fig. 5 step 5):
  // V′ = c + σ·r₀·(B·w) with B = reconstruction_basis(), w =
  // reduced_coordinates(), r₀ = global_rotation(), (c, σ) = normalization().
  // When the rounds produce NaN or infinities the summary says
  // Status::NumericalFailure and the pose stays the last good one: *out is
  // not written, rotations(), reduced_coordinates() and global_rotation()
  // are as after the last good frame, and the next frame starts from there.
  // Throws std::invalid_argument before any work on targets that do not fit
  // the handle set, are not finite, or reach beyond kMaxCoordinate
  // (mesh_check.h; they would overflow in the energy).
  FrameSummary frame(const HandleTargets& targets, Vertices* out);
  // The same, reconstructing into the caller's n × 3 buffer (a NumPy array,
  // a mapped GPU buffer) in place: no copy, no allocation. Throws
  // std::invalid_argument when `out` does not have n rows.
  FrameSummary frame(const HandleTargets& targets, Eigen::Map<Vertices> out);

  // Back to the rest rotations (S = identity, r₀ = identity); the next frame
  // is a cold start (DeformerOptions::cold_start_rounds).
  void reset_pose();
  // Changes DeformerOptions::round_threads for the following frames (≥ 0).
  void set_round_threads(int threads);
  // Replaces DeformerOptions::iterations (≥ 1, the cap), tolerance and
  // time_budget (seconds; finite, ≥ 0) for the following frames:
  // set_rounds(8) runs the paper's fixed 8 rounds. Throws
  // std::invalid_argument.
  void set_rounds(int iterations, double tolerance = 0.0, double time_budget = 0.0);
  // Changes DeformerOptions::anderson_window (0–16) for the following frames
  // (set_handles forms the energy terms both kinds of rounds read). Throws
  // std::invalid_argument on a window out of range, or a window > 0 with
  // rotation_fit PaperPhase2.
  void set_anderson_window(int window);

  bool ready() const;
  Index vertex_count() const;
  Index rotational_proxies() const;
  Index linear_proxies() const;
  Index patch_count() const;
  Index handle_rows() const;  // constraint rows of the current handle set
  const std::vector<int>& clusters() const;          // per rotation element
  const std::vector<int>& patch_of_vertex() const;
  const RotationElements& elements() const;
  const Eigen::VectorXd& rotations() const;  // S, 9d (world frame)
  // The transform [t_s | d_s] (world frame) of patch p after the last frame:
  // its vertices are at t_s·v + d_s (up to the float reconstruction). Rigid
  // patches have t_s ∈ SO(3), Fixed ones the identity.
  Eigen::Matrix<double, 3, 4> patch_transform(Index p) const;
  // ψ_a = det(s_a)^(1/3) per cluster (1 for rotations; the conformal scale).
  Eigen::VectorXd cluster_scales() const;
  // The model in use (name(), parameters()); null before precompute.
  const std::shared_ptr<const DeformationModel>& model() const;
  const Eigen::Matrix3d& global_rotation() const;
  // The frame the deformer computes in: the rest pose minus the centre c of
  // its bounding box, divided by σ, the box's diagonal. Every length, energy
  // and condition inside (and the automatic proxies) is then free of the
  // mesh's units, and a model in millimetres or light-years gets the same
  // pose (docs/robustness.md, "Units"). Targets
  // are mapped in and the pose out (frame, patch_transform); what stays in
  // this frame: reconstruction_basis(), reduced_coordinates() (V′ = c +
  // σ·r₀·(B·w)) and the rows of a saved cache.
  using Normalization = deform::Normalization;  // handles.h
  const Normalization& normalization() const;
  // The reconstruction basis B = P·[N UD] in float, 3n × p row-major with
  // p = 3m + 12s + 9d: row 3v + a gives coordinate a (x, y, z) of vertex v
  // in the normalised frame (normalization()).
  // Empty before precompute, and after precompute_part with more than one
  // process (its rows basis_rows() come from basis_block).
  // Empty with DeformerOptions::double_basis (below).
  const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>& reconstruction_basis() const;
  // w = [X; S_local] (p entries, float) of the last frame: the linear proxies
  // (normalised, normalization()) and the cluster rotations in the frame of r₀ (S_local = r₀ᵀ·S per
  // cluster, each 3 × 3 column-major). Valid after the first frame().
  const Eigen::VectorXf& reduced_coordinates() const;
  // With DeformerOptions::double_basis: the same basis and w in double (the
  // frames reconstruct from these); empty otherwise.
  bool double_basis() const;
  const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>& reconstruction_basis_double() const;
  const Eigen::VectorXd& reduced_coordinates_double() const;

 private:
  struct State;
  // precompute (build empty: the engine's single-process build) and precompute_part.
  PrecomputeSummary run_precompute(const DeformableMesh& model, const DeformerOptions& options,
                                   const ProgressFn& progress, Partition partition, const PartBuilder& build,
                                   const SumOverProcesses& sum);
  std::unique_ptr<State> state_;
};

// Builds the model, handles and targets of a Botsch–Sorkine scenario: `sel`
// (0 fixed, 1 free, 2 handle) gives a Fixed patch and an Affine handle patch
// whose transform is `def` (4 × 4, column vectors).
struct SelDefScenario {
  Handles handles;
  HandleTargets targets;
};
SelDefScenario apply_sel_def(const std::vector<int>& sel, const Eigen::Matrix4d& def, DeformableMesh* model);

}  // namespace qpreduce::deform
