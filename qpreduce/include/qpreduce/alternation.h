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
// Shaped as ProxSuite's solvers: AlternationSettings (per run;
// alternation_settings.h, with AlternationSetup and AlternationResults),
// `setup` (the model, once per constraint set: Phase 1, the energy terms, the
// proximal weights for constraints on y and the fused form, in that order),
// `solve` (rounds into caller storage, no heap allocation) and
// AlternationResults; the plugin's Phase 2 is an InputProjection
// (input_projection.h). `prepare` (once per subspace) moves the part of every
// `setup` that does not depend on the constraints to precompute time; it is
// optional. The strategies (plain, parallel, Anderson, second-order), the
// fast paths and their derivations: docs/engine.md, "The alternation".
#pragma once

#include "qpreduce/alternation_settings.h"
#include "qpreduce/common.h"
#include "qpreduce/input_projection.h"
#include "qpreduce/subspace_solver.h"

#include <limits>
#include <memory>
#include <type_traits>

namespace qpreduce {

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

  // The energy E(y) the accelerated rounds and the second-order steps judge
  // by (docs/engine.md, "The energy of the alternation", (*)) at this b (m)
  // and y (k), in double: one product with F_y. NaN when the setup formed
  // no energy terms (energy_terms() false) or the projection has no
  // quadratic_term. *slack (optional): the round-off bound a comparison of
  // energies from `solve` with this one should allow (10⁻⁹ of its terms'
  // magnitudes, that of float rounds). No heap allocation after the first
  // solve or energy of a setup. Throws std::invalid_argument before a setup
  // and on other sizes.
  double energy(InputProjection<Scalar>& projection, const Eigen::Ref<const Vector<Scalar>>& b,
                const Eigen::Ref<const Vector<Scalar>>& y, double* slack = nullptr);

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
  // Whether `solve` with this projection and these settings evaluates E(y)
  // (second-order steps or Anderson rounds: AlternationResults' energy is
  // finite); plain rounds do not (NaN).
  bool reports_energy(const InputProjection<Scalar>& projection, const AlternationSettings& settings) const;
  // Phase 1's operators (d × m; d × k formed on each call).
  const Matrix<Scalar>& Mb() const;
  Matrix<Scalar> MY() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace qpreduce
