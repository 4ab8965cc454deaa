// qpreduce — the alternating scheme of Section 3.1 as one solver:
// Phase 1, a reduced QP in the linear coordinates z with the other
// coordinates y held fixed (Eq. 16–17), and Phase 2, a plugin's projection
// of y onto its manifold, warm-started, in rounds until a fixed point.
//
// With X = N·z + UD·y (Eq. 5) and the linear term q = D·y of the deformation
// model, Phase 1 is
//     min_z ½zᵀH_zz z + zᵀH_zy y − (NᵀD·y)ᵀz   s.t.  A_z z = b + T·y − A_y y,
// (A_z = AᵀN m × d, A_y = AᵀUD m × k; T, m × k and usually empty, makes
// right-hand sides follow y, e.g. a patch tied to a cluster), so
// z = M_b·b + (M_Y + M_b·T)·y, and Phase 2 sees g = G_z·z + G_y·y. A round
// is then one q × k product and the projection (the fused form).
//
// Shaped as ProxSuite's solvers: AlternationSettings (per run),
// `setup` (the model, once per constraint set: Phase 1, the energy terms, the
// proximal weights for constraints on y and the fused form, in that order),
// `solve` (rounds into caller storage, no heap allocation) and
// AlternationResults. `prepare` (once per subspace) moves the part of every
// `setup` that does not depend on the constraints to precompute time; it is
// optional. The strategies (plain, parallel, Anderson, second-order), the
// fast paths and their derivations: docs/engine.md, "The alternation".
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/subspace_solver.h"

#include <limits>
#include <memory>
#include <type_traits>

namespace qpreduce {

// Why a run's rounds ended (AlternationResults::stop).
enum class RoundStop {
  RoundLimit,  // AlternationSettings::iterations rounds ran
  Tolerance,   // the last round's ‖Δy‖ met AlternationSettings::tolerance
  TimeBudget,  // AlternationSettings::time_budget was spent first
};
const char* to_string(RoundStop stop);  // "round limit", "tolerance", "time budget"

// How one run goes (they may change between runs of one setup).
struct AlternationSettings {
  // Rounds per run: the cap with `tolerance` or `time_budget`, the count
  // without them (the paper's fixed 8 per frame). ≥ 1.
  int iterations = 8;
  // Stop early when ‖Δy‖ ≤ tolerance·max(1, ‖y‖). 0: always run `iterations`.
  double tolerance = 0.0;
  // Stop once the rounds have run this many seconds (checked after each
  // round or second-order step: the first always runs, the last may end past
  // the budget by one). 0: no budget. Finite and ≥ 0.
  double time_budget = 0.0;
  // The clock the budget reads, in seconds from any origin; nullptr:
  // std::chrono::steady_clock. For tests and simulations.
  double (*clock)() = nullptr;
  // The round's product in float relative to a double reference y_r,
  // g = F_b·b + F_y·y_r + F_y·(y − y_r): the rounds reach the fixed points of
  // double rounds; Phase 1's final z stays in double. Required after a setup
  // with FusedPrecision::Float.
  bool float_products = false;
  // OpenMP threads for the rounds when the projection is block-separable
  // (InputProjection::block_size() > 0) and F_y has at least
  // parallel_min_entries entries (0 threads: omp_get_max_threads()). The
  // iterates are the serial ones up to the last bits of an entry of g.
  int threads = 1;
  Index parallel_min_entries = 256 * 256;
  // Anderson acceleration (anderson.h) of the fixed-point map with the
  // retraction and the energy safeguard (an extrapolation that raises E(y)
  // is replaced by the plain step). 0: plain rounds; else 1–16. Needs a
  // setup that formed the energy terms (Alternation::energy_terms()).
  int anderson_window = 0;
  // Stiff constraints on rotation blocks (Alternation::second_order): damped
  // Riemannian Newton steps on E(y) instead of rounds, `iterations` of them.
  bool second_order = true;

  // False with a reason, e.g. "iterations must be at least 1, got 0".
  bool is_valid(std::string* why) const;
};

struct AlternationResults : Outcome {  // Success after a run
  int iterations = 0;                   // rounds (or second-order steps) run
  RoundStop stop = RoundStop::RoundLimit;
  double last_change = 0.0;  // ‖Δy‖ of the last Phase 2
  // Accelerated rounds and second-order steps: E(y) of the last accepted y
  // (up to the float rounds' round-off), and the extrapolations refused.
  double energy = std::numeric_limits<double>::quiet_NaN();
  int rejected = 0;
  bool second_order = false;  // second-order steps ran
};

// A Phase 2 projection whose input is linear in (z, y): g = G_z·z + G_y·y
// (q entries), then y ← Π(g) (Section 3.1, Phase 2).
template <typename Scalar>
class InputProjection {
 public:
  virtual ~InputProjection() = default;
  // y ← Π(g); returns ‖y_new − y_old‖. Should not allocate.
  virtual double project(const Eigen::Ref<const Vector<Scalar>>& g, Eigen::Ref<Vector<Scalar>> y) = 0;

  // Optional block structure, for parallel rounds (AlternationSettings::
  // threads). block_size() = s > 0 promises that Π acts block by block on
  // g and y of equal length (q = k): block j of y (entries [s·j, s·(j + 1)))
  // depends only on block j of g and of the old y. project_blocks then
  // updates blocks [first, last) of y only, reads no other entry of y, and
  // returns Σ‖Δy_j‖² over them; it is called concurrently on disjoint ranges.
  // Override both or neither; 0 (the default) keeps the rounds serial.
  virtual Index block_size() const { return 0; }

  // For accelerated rounds and the correction for constraints on y:
  // ½yᵀN_S y, the quadratic term in y of the energy whose Phase 2 this is
  // (for y on the manifold), and the retraction y ← the nearest point of the
  // manifold. NaN (the default): no energy terms (plain rounds only).
  virtual double quadratic_term(const Eigen::Ref<const Vector<Scalar>>& y) const {
    (void)y;
    return std::numeric_limits<double>::quiet_NaN();
  }
  virtual void retract(Eigen::Ref<Vector<Scalar>> y) const { (void)y; }

  // Proximal Phase 2, for constraints that involve y: `project` must (at
  // least) decrease its Phase 2 energy plus ½·Σ_j w_j‖y_j‖², y_j the blocks
  // of proximal_block_size() entries (one block, the whole y, when that is
  // 0), for the input it is given, which the engine forms as g + w∘y_old.
  // Projections onto a set on which each block's norm is constant
  // (rotations, unit blocks) need do nothing, which is the default; one
  // whose output's norm varies (scaled rotations) must add w_j to block j's
  // curvature. Weights ≥ 0; all 0 (or empty) restores the plain Phase 2.
  virtual Index proximal_block_size() const { return 0; }
  // Whether y is d blocks of 3 × 3 matrices (column-major, 9 entries each) on
  // SO(3) on which quadratic_term is constant, so that stiff constraints on
  // y may take second-order steps (AlternationSettings::second_order).
  virtual bool rotation_blocks() const { return false; }
  virtual void set_proximal_weights(const Eigen::Ref<const Vector<Scalar>>& weights) { (void)weights; }
  virtual double project_blocks(const Eigen::Ref<const Vector<Scalar>>& g, Eigen::Ref<Vector<Scalar>> y,
                                Index first, Index last) {
    (void)g, (void)y, (void)first, (void)last;
    return std::numeric_limits<double>::quiet_NaN();  // never called when block_size() == 0
  }
};

// How the model keeps F_y = G_z·(M_Y + M_b·T) + G_y when Phase 1 came from
// its fast path: Explicit forms the q × k matrix per constraint set;
// Factored keeps the part common to every set and applies a rank-(m + ν)
// correction each round (O(q·μ·d) per set instead of O(q·μ·k)). Automatic:
// Factored for q·k > Alternation::kExplicitMaxEntries.
enum class FusedForm { Automatic, Explicit, Factored };

// The precision of the factored form's per-set product (most of a set's
// cost): Float runs it at about twice the BLAS rate, for runs with
// AlternationSettings::float_products (a Float set's fixed point is that of
// the rounded operator; Phase 1's z stays in double).
enum class FusedPrecision { Double, Float };

// What `setup` builds for one constraint set.
struct AlternationSetup {
  // Hard or soft constraints, tolerances, the fast path, and the BLAS
  // threads of the setup's products (ConstraintOptions::threads).
  ConstraintOptions constraints;
  // T (m × k): the constraints' right-hand side is b + T·y (empty: b). With
  // T, E(y) is not formed (plain rounds only).
  SparseMatrix<double> follow_y;
  // Form Phase 1's energy terms E(y) where they apply (hard or soft
  // constraints solved without a least-squares fallback, no T, a projection
  // with quadratic_term): accelerated rounds need them, and constraints on y
  // (A_y ≠ 0) step on E(y) with them. false: plain rounds.
  bool energy_terms = true;
  FusedForm form = FusedForm::Automatic;
  FusedPrecision precision = FusedPrecision::Double;
};

// Phase 1 folded into Phase 2's input, run in rounds to a fixed point.
// Double only. Not for concurrent calls on one object; copies are
// independent (they share immutable operators).
template <typename Scalar>
class Alternation {
  static_assert(std::is_same_v<Scalar, double>, "Alternation is double only");

 public:
  // Sets with q·k above this many entries take the factored form (Automatic).
  static constexpr Index kExplicitMaxEntries = 256 * 256;

  Alternation();
  ~Alternation();
  Alternation(const Alternation& other);
  Alternation& operator=(const Alternation& other);
  Alternation(Alternation&&) noexcept;
  Alternation& operator=(Alternation&&) noexcept;

  // What every setup for this subspace shares (H_zz's lifted inverse on the
  // fast path, its product with G_z, the curvature test of constraints on
  // y; O(d³ + d²k + q·d·k)), now rather than in the first setup; keeps
  // G_z, G_y as the inputs of setup(solver, Az, Ay, projection, ...).
  // Inputs:
  //   solver     a ready SubspaceSolver (d = solver.d(), k = solver.k())
  //   Gz, Gy     q × d and q × k
  //   projection the Phase 2 (its proximal_block_size)
  //   precision  as the setups that follow will ask
  //   shared_parts  false: only keep G_z, G_y; the first setup that needs
  //              the shared parts forms them (a set that Phase 1 eliminates,
  //              every row one linear proxy, never does)
  // Clears the current constraint set. Throws std::invalid_argument on
  // mismatched sizes, NaN or an unready solver.
  void prepare(const SubspaceSolver<Scalar>& solver, const Matrix<Scalar>& Gz, const Matrix<Scalar>& Gy,
               const InputProjection<Scalar>& projection, FusedPrecision precision = FusedPrecision::Double,
               bool shared_parts = true);

  // The model for the constraints A_z z + A_y y = b + T·y: Phase 1's
  // operators, the energy terms (AlternationSetup::energy_terms), the
  // proximal weights when the constraints involve y, and F_b, F_y.
  // Inputs:
  //   solver     a ready SubspaceSolver; read here, not kept
  //   Az, Ay     m × d and m × k (rows of AᵀN and AᵀUD)
  //   Gz, Gy     q × d and q × k; compared bitwise with the last ones, so
  //              what was formed from unchanged inputs is reused. Without
  //              them: those of the last prepare or setup.
  //   projection the Phase 2 the runs will use
  // Returns the constraint summary (status as SubspaceSolver::
  // set_constraints: a rank-deficient set gets its least-squares answer,
  // ConstraintsLeastSquares, and plain rounds). Throws std::invalid_argument
  // on bad sizes or NaN, or without G's given yet, and then changes nothing.
  ConstraintSummary setup(const SubspaceSolver<Scalar>& solver, const Matrix<double>& Az, const Matrix<double>& Ay,
                          const Matrix<Scalar>& Gz, const Matrix<Scalar>& Gy,
                          const InputProjection<Scalar>& projection, const AlternationSetup& options = {});
  ConstraintSummary setup(const SubspaceSolver<Scalar>& solver, const Matrix<double>& Az, const Matrix<double>& Ay,
                          const InputProjection<Scalar>& projection, const AlternationSetup& options = {});
  // The same from full-space constraint columns A (n × m): A_z = AᵀN,
  // A_y = AᵀUD (the solver must hold its basis).
  ConstraintSummary setup(const SubspaceSolver<Scalar>& solver, const SparseMatrix<Scalar>& A,
                          const Matrix<Scalar>& Gz, const Matrix<Scalar>& Gy,
                          const InputProjection<Scalar>& projection, const AlternationSetup& options = {});

  // settings.iterations rounds (fewer at settings.tolerance or
  // settings.time_budget) from the given y (k, warm start), then
  // z = M_b·b + (M_Y + M_b·T)·y (d). b: m. No heap allocation after the
  // first run of a setup.
  // Throws std::invalid_argument before a setup, on other sizes, on invalid
  // settings, for accelerated runs without energy terms, and for double
  // products after a FusedPrecision::Float setup.
  AlternationResults solve(InputProjection<Scalar>& projection, const Eigen::Ref<const Vector<Scalar>>& b,
                           const AlternationSettings& settings, Eigen::Ref<Vector<Scalar>> z,
                           Eigen::Ref<Vector<Scalar>> y);

  // Phase 1 alone: z = M_b·b + (M_Y + M_b·T)·y for this y (no rounds).
  // Precondition: ready(). No heap allocation.
  void phase_one(const Eigen::Ref<const Vector<Scalar>>& b, const Eigen::Ref<const Vector<Scalar>>& y,
                 Eigen::Ref<Vector<Scalar>> z) const;

  bool ready() const;  // a setup succeeded and nothing cleared it since
  Index d() const;
  Index k() const;
  Index m() const;
  const ConstraintSummary& constraint_summary() const;  // of the last setup
  // The last setup formed E(y) (accelerated runs possible).
  bool energy_terms() const;
  // The rounds step on E(y) for constraints on y, with proximal weights
  // (one per block of the projection's proximal_block_size(); empty when
  // none were needed).
  bool constrained_y() const;
  const Vector<double>& proximal_weights() const;
  bool factored() const;   // the rounds use the factored form
  bool float_set() const;  // the factored form was formed in float
  // Whether `solve` takes second-order steps for this projection and these
  // settings: stiff constraints on y, rotation blocks, settings.second_order.
  bool second_order(const InputProjection<Scalar>& projection, const AlternationSettings& settings) const;
  // Phase 1's operators (d × m; d × k formed on each call).
  const Matrix<Scalar>& Mb() const;
  Matrix<Scalar> MY() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace qpreduce
