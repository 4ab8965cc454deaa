// qpreduce::deform — full-space references for the reduced deformer: what
// the reduced model (deformer.h) is measured against.
//
// Two energies, both on the rest pose V (n × 3) and the rotation elements of
// arap_energy.h (spokes-and-rims for surfaces, one per tet for solids):
//   * ClassicArap (paper Eq. 6): one rotation r_k per element,
//         E(V′, R) = ½ Σ_k Σ_{(i,j)∈G_k} c_ijk ‖e′_ij − r_k e_ij‖²,
//     what libigl and CGAL users run; the energy reported is arap_energy(V′).
//   * ModifiedArap (Eq. 8–10): one rotation s_i ∈ SO(3) per rotational cluster
//     (DeformableMesh::clusters, required) plus the linearised corrections
//     q_k, i.e. E′(V′, Q, S) = ½ uᵀLu − SᵀDᵀu + ½ Σ c ‖s e‖² with u = [V′; Q]
//     (arap_energy.h). The reduced model minimises E′ with V′ restricted to
//     the variational subspace, so the full-space minimiser isolates the
//     subspace error; the energy reported is modified_arap_energy.
//
// Constraints are hard and exactly those of Deformer::set_handles: Fixed
// patches stay at rest, prescribed patches (Handles::patches) follow their
// 3 × 4 transform, point handles put their (weighted) point on the target.
// Patches that are not prescribed move with a free affine map (Eq. 47).
//
// Two solvers:
//   * LocalGlobalArap — Sorkine–Alexa alternation in full space: the global
//     step minimises over V′ (Q eliminated for E′) with rotations fixed, by one
//     sparse Cholesky cached per handle set; the local step fits every
//     rotation (fit_rotation, det = +1). Monotone in the energy.
//   * solve_ceres_reference — Ceres Solver (Levenberg–Marquardt, sparse normal
//     Cholesky, automatic derivatives) on all unknowns at once, rotations as
//     unit quaternions on ceres::QuaternionManifold. Constrained vertices are
//     constant parameter blocks, so only Fixed patches, prescribed patches and
//     single-vertex point handles are supported (std::invalid_argument for
//     weighted point handles and free patches; use LocalGlobalArap there).
//
// Both start from the rest pose (or a given initial guess) and report the
// energy, iterations, time and whether they converged.
//
// The deformer's global rotation adaptation (appendix) minimises E′ in the
// frame rotated by r₀ᵀ. ReferenceOptions::frame = r₀ does the same here: the
// result minimises E′(frameᵀV′, Q, frameᵀS) (only meaningful for E′; the
// classic energy is rotation invariant and ignores it).
#pragma once

#include "qpreduce/deform/energy/arap_energy.h"
#include "qpreduce/deform/deformer/deformer.h"

#include <qpreduce/factorization.h>

#include <Eigen/Core>

#include <functional>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace qpreduce::deform {

// The energy a reference minimises (see above): classic ARAP (Eq. 6) or E′
// (Eq. 8–10).
enum class ReferenceEnergy { ClassicArap, ModifiedArap };
const char* to_string(ReferenceEnergy energy);

struct ReferenceOptions {
  ReferenceEnergy energy = ReferenceEnergy::ClassicArap;
  // α, β of E′ (ModifiedArap only; β is ignored for tets, as in the deformer).
  EnergyParameters parameters;
  // E′ is minimised in the frame rotated by frameᵀ (see above). Identity: plain E′.
  Eigen::Matrix3d frame = Eigen::Matrix3d::Identity();
  // Iteration limit (local-global rounds, or Ceres LM iterations).
  int max_iterations = 20000;
  // Local-global: converged when the largest vertex move of a round is below
  // step_tolerance × the bounding-box diagonal AND the energy dropped by less
  // than energy_tolerance (relative). 1e-10 / 1e-13: the alternation is only
  // linearly convergent, so the step must be far below the accuracy wanted
  // (an energy within ~1e-8 relative of the limit on meshes of 10²–10⁴ vertices).
  double step_tolerance = 1e-10;
  double energy_tolerance = 1e-13;
  // Ceres: function, gradient and parameter tolerances (Ceres' own meaning),
  // far tighter than Ceres' defaults so that it stops at the minimiser.
  double function_tolerance = 1e-15;
  double gradient_tolerance = 1e-14;
  double parameter_tolerance = 1e-13;
  // Local-global: also stop when the relative energy change of a round,
  // |E_k − E_{k+1}| / E_{k+1}, or the relative fixed-point residual
  // ‖G(z_k) − z_k‖ / ‖z_k‖ (z and G: see LocalGlobalArap) is ≤ tolerance.
  // 0 (the default) leaves only the step/energy test above, which is meant
  // for converged references; a refine uses e.g. 1e-6. Finite and ≥ 0.
  double tolerance = 0.0;
  // Local-global: also stop once the estimated distance of the pose to the
  // fixed point the rounds converge to, RMS over the vertices and divided by
  // the bounding-box diagonal (ReferenceSummary::estimated_distance), is ≤
  // distance_tolerance. 0 (the default): no such test. Finite and ≥ 0.
  double distance_tolerance = 0.0;
  // Local-global: Anderson acceleration (anderson.h) of the rounds with this
  // window, in [0, 16]; 0 = the plain alternation. An accelerated pose is
  // kept only when it does not raise the energy, otherwise the plain round
  // is taken (ReferenceSummary::rejected_steps), so the energy still never
  // rises.
  int anderson_window = 0;
  // Local-global, classic energy: after this many rounds, trust-region
  // Newton steps (Steihaug conjugate gradients on the classic energy's
  // Hessian, preconditioned by the global step's factor; docs/deform.md,
  // "The Newton finish") replace the rounds, and the contraction of their
  // steps gives estimated_distance; max_iterations then bounds the rounds
  // and the steps' Hessian products together. 0 (the default): rounds only.
  // Not taken with weighted point handles. ≥ 0.
  int newton_after = 0;
  // Local-global with ModifiedArap: which rotation step (see above).
  ClusterRotationFit cluster_fit = ClusterRotationFit::Exact;
  // Factorization of the global step (local-global). Auto: CHOLMOD's
  // supernodal LLᵀ, or for a per-axis factor (HandleSetSummary::
  // axis_separable) CHOLMOD's simplicial LDLᵀ, which solves the three axes
  // in one sweep of the factor (make_cholmod_simplicial_factorization).
  // Cholmod, SimplicialLDLT: that backend for either factor.
  Backend backend = Backend::Cholmod;
  // Threads for Ceres' Jacobian evaluation and linear algebra, and for the
  // local step and linear term of classic local-global (elements and
  // vertices in parallel; the result does not depend on the count).
  int threads = 1;

  bool is_valid(std::string* why) const;
};

struct ReferenceSummary : Outcome {
  ReferenceEnergy energy_kind = ReferenceEnergy::ClassicArap;
  bool converged = false;    // a convergence test held (not the iteration limit)
  int iterations = 0;
  double initial_energy = 0.0;  // of the starting pose (Ceres: constrained vertices already at their targets)
  double energy = 0.0;       // arap_energy (classic) or E′ (modified) of the result
  double handle_residual = 0.0;  // largest constraint violation (absolute distance)
  double last_step = 0.0;    // local-global: largest vertex move of the last round
  double fixed_point_residual = 0.0;  // local-global: ‖G(z) − z‖ / ‖z‖ of the last round
  // Local-global: how far the pose is estimated to be from the converged
  // one, RMS over the vertices / the bounding-box diagonal. Rounds: the
  // residual over σ, the least singular value of I − J estimated on the last
  // 16 steps (docs/deform.md, "The refine's stop rule"); infinite until two
  // rounds have run. Newton steps: |s_k|·ρ/(1 − ρ) over two contracting full
  // steps, ρ = |s_k|/|s_{k−1}| ("The Newton finish"); infinite until then.
  double estimated_distance = std::numeric_limits<double>::infinity();
  int rejected_steps = 0;             // local-global: accelerated poses refused by the energy safeguard
  int newton_steps = 0;               // local-global: Newton steps taken (ReferenceOptions::newton_after)
  int cg_iterations = 0;              // local-global: their Hessian products (one solve with K each)
  int newton_fallbacks = 0;           // local-global: Newton steps that did not lower the energy (a plain round instead)
  bool cancelled = false;             // local-global: the cancel hook stopped it (the pose is the last accepted one)
  // Local-global: after each round, the energy of the accepted pose and the
  // seconds since the rounds began (time-to-accuracy measurements).
  std::vector<double> round_energy, round_seconds;
  double setup_seconds = 0.0;    // elements, assembly, factorization (local-global: per handle set)
  double solve_seconds = 0.0;    // the iterations
  std::string solver_report;     // Ceres: Solver::Summary::FullReport(); local-global: a line

 protected:
  void add_details(Report* out) const override;
};

// The result: deformed positions V′ (n × 3) and the rotations.
struct ReferenceSolution {
  Vertices V;
  // ClassicArap: one 3 × 3 rotation per element, 9r (column-major per element).
  // ModifiedArap: S, 9d (as Deformer::rotations), and Q, 4r (arap_energy.h).
  Eigen::VectorXd rotations;
  Eigen::VectorXd Q;
};

// The outcome of LocalGlobalArap::set_handles.
struct HandleSetSummary : Outcome {
  Index free_coordinates = 0, pinned_coordinates = 0;
  Index point_rows = 0;  // weighted-point constraint rows
  // Classic ARAP with whole vertices and patches pinned: K = K_s ⊗ I₃, and
  // K_s (a third of the size) was factored instead of K.
  bool axis_separable = false;
  double seconds = 0.0;

 protected:
  void add_details(Report* out) const override;
};

// Sorkine–Alexa local-global ARAP in full space, one cached factorization per
// handle set:
//   precompute(model, options)  elements, energy matrices (both energies);
//   set_handles(handles)        eliminates the pinned coordinates, factors
//                               K (free coordinates, with the remaining
//                               weighted-point rows as ρAᵀA) and the small
//                               Schur complement of the point rows;
//   solve(targets, …)           rounds of global (one back-substitution) and
//                               local steps until converged.
// Only the targets may change between solves: new targets reuse the
// factorization, a new handle set needs set_handles again.
// Global step: the control layer of deformer.h, u = [V′_free; t_s, d_s per
// patch] (n_u), V′ = P u; minimise ½uᵀ(PᵀHP)u − uᵀPᵀq(R) subject to the
// constraints, with H = the cotangent ARAP matrix Σ c (ξ_i − ξ_j)(ξ_i − ξ_j)ᵀ ⊗ I₃
// (classic) or the Q-eliminated H of arap_energy.h (E′, q = D_s S).
//
// Anderson acceleration (ReferenceOptions::anderson_window > 0). One round
// is the fixed-point map z ↦ G(z) = global(local(z)) on the stacked pose
// z = [vec V′] (3n; classic) or z = [vec V′; Q] (3n + 4r; E′), not on the
// rotations: 3n numbers against 9r (r = n for spokes-and-rims, r ≈ 5n–6n
// for tets), so each Anderson step streams 3–18 times fewer numbers, and the
// energy of a pose z is min_R E(z, R), which the local step computes anyway
// (the safeguard costs nothing extra when the step is accepted). Each
// accelerated z_{k+1} is an affine combination of global-step outputs, so
// it meets the (affine) handle constraints and stays in the control layer.
// Safeguard (Peng et al. 2018): if E(z_{k+1}) > E(z_k)·(1 + 10⁻¹³) (more
// than round-off above) or it is not finite, take the plain G(z_k) instead
// (monotone to round-off) and restart the history.
class LocalGlobalArap {
 public:
  LocalGlobalArap();
  ~LocalGlobalArap();
  LocalGlobalArap(LocalGlobalArap&&) noexcept;
  LocalGlobalArap& operator=(LocalGlobalArap&&) noexcept;

  // Builds the rotation elements and the energy matrices of both energies,
  // on the rest pose in its units-free frame (Normalization, handles.h):
  // solve maps targets and the initial pose in, and returns poses, energies,
  // residuals and elements() in the given units.
  //   model    rest pose V (n × 3), its elements, patches and, for
  //            ModifiedArap, the rotational clusters
  //   options  the energy, its parameters and the solver settings
  // Throws std::invalid_argument on a bad model (as Deformer::precompute), on
  // ModifiedArap without clusters, or on invalid options.
  void precompute(const DeformableMesh& model, const ReferenceOptions& options = {});

  // Splits the control layer into pinned and free coordinates for this handle
  // set and factors the global step. Precondition: precompute was called.
  //   handles  point handles (vertex indices in [0, n), optional weights) and
  //            prescribed patches (indices into the model's patches)
  // Returns the coordinate counts and the factorization's status.
  // Throws std::invalid_argument on handles out of range, on a connected
  // component that nothing anchors (no Fixed/prescribed patch, no handle: its
  // position would be undetermined), or on linearly dependent weighted
  // handles. Factorization failures come back in the summary.
  HandleSetSummary set_handles(const Handles& handles);

  // Runs the alternation from `initial` (n × 3; empty: the rest pose) to the
  // targets. Precondition: set_handles was called.
  //   targets  one row of `points` per point handle (m × 3), one 3 × 4 [A | t]
  //            per prescribed patch
  //   out      V (n × 3), the rotations and, for E′, Q (ReferenceSolution)
  //   cancel   optional; called once per round before the round: true stops
  //            the solve with the last accepted pose (finite, meeting the
  //            constraints as well as any round's pose) and
  //            summary.cancelled = true
  // Returns the energy, iterations, residual and whether it converged. Throws std::invalid_argument on target sizes,
  // NaN, or conflicting targets (one vertex held at two different places by two constraints).
  ReferenceSummary solve(const HandleTargets& targets, ReferenceSolution* out, const Vertices& initial = {},
                         const std::function<bool()>& cancel = {});

  // Replaces the iteration settings (max_iterations, step_tolerance,
  // energy_tolerance, tolerance, anderson_window, threads) and keeps the
  // factorization. Throws std::invalid_argument on invalid options or
  // before precompute.
  void set_iteration_options(const ReferenceOptions& options);
  const ReferenceOptions& options() const;

  const RotationElements& elements() const;

 private:
  struct State;
  std::unique_ptr<State> state_;
};

// One-off local-global solve: LocalGlobalArap's precompute(model, options),
// set_handles(handles) and solve(targets, out, initial), with their inputs,
// outputs and errors. A failed set_handles comes back as the summary's status.
// It runs on the rest pose centred and scaled to a unit bounding-box
// diagonal (normalization_of, handles.h) and reports the pose, energies,
// handle residual and last step in the given units: a scene scaled by any
// power of ten gives the same answer scaled.
ReferenceSummary solve_local_global(const DeformableMesh& model, const Handles& handles,
                                    const HandleTargets& targets, const ReferenceOptions& options,
                                    ReferenceSolution* out, const Vertices& initial = {});

// Ceres full-space minimiser of the chosen energy, as a sum of squared
// residuals that equals it exactly (docs/deform.md, "The Ceres residuals").
// Constrained vertices are constant parameter blocks. Like
// solve_local_global it runs in the units-free frame (so Ceres' absolute
// gradient tolerance is relative to the mesh) and reports in the given units.
//   model, handles, targets, options, initial  as for solve_local_global
//   out  V (n × 3), the rotations and, for E′, Q (ReferenceSolution)
// Throws std::invalid_argument on the unsupported constraints named above
// (weighted point handles, free patches), bad input, or conflicting targets.
// Throws std::runtime_error when qpreduce was built without Ceres
// (QPREDUCE_NO_CERES; has_ceres_reference() tells).
ReferenceSummary solve_ceres_reference(const DeformableMesh& model, const Handles& handles,
                                       const HandleTargets& targets, const ReferenceOptions& options,
                                       ReferenceSolution* out, const Vertices& initial = {});

// Whether solve_ceres_reference is available (qpreduce was built with Ceres).
bool has_ceres_reference();

// Where the constraints put each vertex, when they put it somewhere.
struct VertexTargets {
  std::vector<char> pinned;  // n entries, true where a target is set
  Vertices position;         // n × 3, meaningful where pinned
};

// The per-vertex targets of the Fixed patches, the prescribed patches and
// the single-vertex point handles (weighted handles and free patches are not
// per-vertex).
//   model      rest pose V (n × 3) and its patches
//   handles, targets  as for LocalGlobalArap::set_handles and solve
//   tolerance  how far apart two targets of one vertex may be (absolute)
// Throws std::invalid_argument on conflicting targets (a vertex held at two
// places more than `tolerance` apart), naming the vertex and both constraints.
VertexTargets vertex_targets(const DeformableMesh& model, const Handles& handles, const HandleTargets& targets,
                             double tolerance);

}  // namespace qpreduce::deform
