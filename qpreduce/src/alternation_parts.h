// Private to the engine: the two parts of Alternation (alternation.h).
// FixedCoordinateSolver is Phase 1 for one constraint set, z = M_b·b + M_Y·y
// (Eq. 16–17 with y fixed); FusedAlternation folds it into Phase 2's input,
// g = F_b·b + F_y·y, and runs the rounds. Alternation::setup calls them in
// the order they need (set_reduced_constraints, form_energy_terms,
// set_proximal_block_size, set); the white-box tests drive them directly.
#pragma once

#include "qpreduce/alternation_settings.h"
#include "qpreduce/common.h"
#include "qpreduce/input_projection.h"
#include "qpreduce/subspace_solver.h"

#include <memory>
#include <type_traits>

namespace qpreduce {

namespace detail {
struct FixedCoordinatePrep;
class PhaseOneOperator;
struct PhaseOneEnergy;
struct FusedModel;
struct FusedWorkspace;
}  // namespace detail

// Phase 1 (Eq. 16–17 with y fixed): z = M_b·b + M_Y·y for one constraint set.
// Double only. Copies share their (immutable) operators.
// A_z = AᵀN (m × d) and A_y = AᵀUD (m × k) from full-space constraint
// columns A (n × m), for FixedCoordinateSolver::set_constraints and
// Alternation::setup. `who` names the caller in the messages. Throws
// std::invalid_argument when the solver is not ready or holds no basis, or
// A has the wrong rows or NaN.
namespace detail {
void full_space_rows(const char* who, const SubspaceSolver<double>& solver, const SparseMatrix<double>& A,
                     Matrix<double>* Az, Matrix<double>* Ay);
}  // namespace detail

template <typename Scalar>
class FixedCoordinateSolver {
  static_assert(std::is_same_v<Scalar, double>, "FixedCoordinateSolver is double only");

 public:
  using VectorS = Vector<Scalar>;
  using ConstRef = Eigen::Ref<const VectorS>;
  using Ref = Eigen::Ref<VectorS>;

  // Forms M_b, M_Y for the constraints AᵀX = b.
  // Inputs:
  //   solver  a ready SubspaceSolver (d = solver.d(), k = solver.k()); read
  //           here, not kept (the fast path keeps what it prepared from it and
  //           redoes that after the solver's next precompute or restore)
  //   A       n × m sparse constraint columns
  //   options hard/soft, tolerances, fast_path (the range-space form on
  //           H_zz: O(d·μ·(d + k)) per set, μ = m + ν; the null-space method,
  //           O(d³ + d²k), for rank-deficient or uncertified sets)
  // Returns the summary (status as SubspaceSolver::set_constraints; fast_path
  // says which method ran). Throws std::invalid_argument on bad sizes or NaN.
  ConstraintSummary set_constraints(const SubspaceSolver<Scalar>& solver, const SparseMatrix<Scalar>& A,
                                    const ConstraintOptions& options = {});
  // The same from A_z = AᵀN (m × d) and A_y = AᵀUD (m × k), for callers that
  // keep rows of B = [N UD] at hand (gathering m rows of a row-major copy is
  // O(m·p) contiguous reads; AᵀB on the column-major subspace is not).
  ConstraintSummary set_reduced_constraints(const SubspaceSolver<Scalar>& solver, const Matrix<double>& Az,
                                            const Matrix<double>& Ay, const ConstraintOptions& options = {});

  // The fast path's per-solver part (H_zz's lifted inverse M0, P0 = M0·G with
  // G = NᵀD − H_zy, and LᵀG; O(d³ + d²k)) now rather than in the first
  // set_constraints after the solver's precompute or restore; nothing when it
  // is current. Throws std::invalid_argument when `solver` is not ready.
  void prepare(const SubspaceSolver<Scalar>& solver);

  // z = M_b·b + M_Y·y. b: m, y: k, z: d. Precondition: ready(). No heap
  // allocation. Not for concurrent calls on one object (scratch vector).
  void solve(const ConstRef& b, const ConstRef& Y, Ref z) const;

  bool ready() const { return op_ != nullptr; }
  const Matrix<Scalar>& Mb() const;  // d × m (empty before the first set)
  Matrix<Scalar> MY() const;         // d × k, formed on each call in the fast path's factored form
  Index d() const { return Mb().rows(); }
  Index k() const { return k_; }
  Index m() const { return Mb().cols(); }

  // The terms of the reduced energy for this constraint set, which
  // accelerated rounds (AlternationSettings::anderson_window) need: A_y and
  // the multipliers of Phase 1's constraints, λ = Λ_b·b + Λ_y·y, so that
  //     E(y) = ½yᵀN_S y − ½gᵀy − ½(b − A_y·y)ᵀλ                (*)
  // is E′ at the Phase 1 minimiser for this y (docs/engine.md, "The energy
  // of the alternation"; N_S is the plugin's ½yᵀN_S y, g its Phase 2 input).
  // On the fast path λ = K·(R·y − [b; 0]) with K the first m rows of its
  // bordered Σ⁻¹ (src/phase_one.h), O(m·μ·k); otherwise, hard constraints:
  // λ = W·(G·y − H_zz·z) with W = (A_zᵀ)⁺ (m × d), soft: λ = 2δ·(A_z·z +
  // A_y·y − b), O(m·d·k). Per constraint set; dropped by the next
  // set_constraints. Precondition: ready(), and `solver` the one the
  // constraints were set for. Throws std::invalid_argument otherwise.
  //
  // FusedAlternation::set reads them too: with them, and A_y ≠ 0, its rounds
  // step on E(y) itself (see "Constraints on y" at FusedAlternation), so
  // form them before that `set`.
  void form_energy_terms(const SubspaceSolver<Scalar>& solver);
  bool has_energy_terms() const { return energy_ != nullptr; }

  // The engine's view of the current operators and of the fast path's
  // per-solver part (opaque outside the engine; FusedAlternation reads them).
  const detail::PhaseOneOperator* phase_one_operator() const { return op_.get(); }
  const std::shared_ptr<const detail::FixedCoordinatePrep>& preparation() const { return prep_; }
  const detail::PhaseOneEnergy* energy_terms() const { return energy_.get(); }
  const std::shared_ptr<const detail::PhaseOneEnergy>& shared_energy_terms() const { return energy_; }

 private:
  void prepare_impl(const SubspaceSolver<Scalar>& solver);

  std::shared_ptr<const detail::FixedCoordinatePrep> prep_;  // per solver generation
  std::shared_ptr<const detail::PhaseOneOperator> op_;       // per constraint set
  std::shared_ptr<const detail::PhaseOneEnergy> energy_;     // per constraint set, on request
  Matrix<double> Az_, Ay_;                                   // this set's A_z (m × d), A_y (m × k)
  ConstraintOptions options_;                                // this set's options
  Index k_ = 0;
  mutable Vector<double> scratch_;  // μ: R·y in the factored solve
};

// Phase 1 folded into Phase 2's input: with z = M_b·b + M_Y·y,
//     g = G_z·z + G_y·y = F_b·b + F_y·y,   F_b = G_z·M_b (q × m),
//                                          F_y = G_z·M_Y + G_y (q × k),
// so a round is one q × k product and Π; z is formed once after the last
// round. Without constraints on y (A_y = 0) the iterates are those of the
// plain alternation. Double only.
//
// Constraints on y (A_y ≠ 0: e.g. a point handle at a vertex that the
// cluster rotations move). A plain round fits y to g at fixed z, but a new y
// breaks A_z z + A_y y = b and Phase 1 then moves z: the rounds are not
// descent on the reduced energy E(y) (FixedCoordinateSolver::
// form_energy_terms, (*)) and converge to a stationary point of another
// problem, far from E's minimiser when the constraints are stiff
// (docs/robustness.md, "Soak"). E's gradient is N_S·y − (g − A_yᵀλ(y)),
// λ = Λ_b·b + Λ_y·y Phase 1's multipliers, and its Hessian is N_S + Q with
// Q = −(F_y − A_yᵀΛ_y) (symmetric), whose positive part is the stiff,
// rank ≤ m term of the constraints. So when `set` finds Phase 1's energy
// terms, A_y ≠ 0 and q = k, it forms the rounds of the majorise–minimise step
//     y ← Π(g − A_yᵀλ + D·y),   D = diag(w_j·I) ⪰ Q  (0 when Q ⪯ 0),
//     i.e.  F_b ← F_b − A_yᵀΛ_b,   F_y ← F_y − A_yᵀΛ_y + D,
// with the projection told w (InputProjection::set_proximal_weights), so
// that E(y) = ½yᵀN_S y − ½g′ᵀy + ½yᵀDy − ½bᵀλ never rises over a plain
// round and the fixed points are E's stationary points on the manifold. D is
// 0 when Q ⪯ 0; else λ_max(Q)·I (a Lanczos run, Spectra) or, per block of
// the projection's proximal_block_size() in the explicit form, the block
// Gershgorin bound of Q, whichever is smaller in total (it leaves the blocks
// far from the constraints free). On Phase 1's fast path Q = −F₀ + U·R with
// F₀ = C0 + G_y the same for every set and U·R of rank μ, and whether
// λ_max(Q) ≤ ε (ε = 10⁻¹⁰‖F₀‖_F, round-off; such a set gets D = 0) is
// decided exactly from a Cholesky factor of F₀ + εI formed once (`prepare`)
// with one triangular solve of μ columns, O(k²·μ/2); Lanczos runs only when
// that test fails or does not apply (src/fused_rounds.h, CurvatureTest).
// The correction itself is folded into that factor, U = G_z·T + A_yᵀ·K:
// O(q·d·μ) per set, as without it. Nothing changes when A_y = 0.
template <typename Scalar>
class FusedAlternation {
  static_assert(std::is_same_v<Scalar, double>, "FusedAlternation is double only");

 public:
  static constexpr Index kExplicitMaxEntries = 256 * 256;
  // Automatic sets beyond kExplicitMaxEntries are factored, but a stiff one
  // (proximal weights > 0, blocks of 3 × 3) with at most this many blocks is
  // set explicitly after all, so that it can take second-order steps; larger
  // ones run the damped rounds (a step factors a 3d × 3d matrix).
  static constexpr Index kSecondOrderMaxBlocks = 64;

  FusedAlternation();
  ~FusedAlternation();
  FusedAlternation(const FusedAlternation& other);
  FusedAlternation& operator=(const FusedAlternation& other);
  FusedAlternation(FusedAlternation&&) noexcept;
  FusedAlternation& operator=(FusedAlternation&&) noexcept;

  // Forms F_b and F_y for the current constraint set of `phase1` (call again
  // after each of its set_constraints).
  // Inputs:
  //   phase1    a ready FixedCoordinateSolver (d, k, m from it)
  //   Gz, Gy    q × d and q × k; kept, and compared bitwise with the last
  //             ones (what was formed from unchanged inputs is reused)
  //   threads   BLAS threads for these products (0: the BLAS's own setting)
  //   form, precision  see FusedForm, FusedPrecision
  // Throws std::invalid_argument on mismatched sizes, NaN or an unready phase1.
  void set(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz, const Matrix<Scalar>& Gy,
           int threads = 1, FusedForm form = FusedForm::Automatic,
           FusedPrecision precision = FusedPrecision::Double);
  // The same with the G_z, G_y of the last call, without comparing them.
  // Throws std::invalid_argument before any G_z, G_y were given.
  void set(const FixedCoordinateSolver<Scalar>& phase1, int threads = 1, FusedForm form = FusedForm::Automatic,
           FusedPrecision precision = FusedPrecision::Double);

  // C0 = G_z·P0 (and G_z's float copy for `precision` Float), F₀ = C0 + G_y
  // when `set` will take the factored form (q·k > kExplicitMaxEntries), and
  // for q = k the Cholesky factor of F₀ + εI that decides whether a set's
  // rounds need proximal weights ("Constraints on y"; O(k³)) now, for the
  // preparation of `phase1` (FixedCoordinateSolver::prepare or a fast-path
  // set_constraints), rather than in the first `set`; keeps G_z, G_y as the
  // inputs of set(phase1). Resets ready(): call `set` before `run`.
  // Throws std::invalid_argument on mismatched sizes or NaN.
  void prepare(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz, const Matrix<Scalar>& Gy,
               FusedPrecision precision = FusedPrecision::Double);

  // options.iterations rounds (fewer with options.tolerance or
  // options.time_budget; AlternationResults::stop says which ended them) from
  // the given y (k, warm start), then z = M_b·b + M_Y·y (d). b: m. No heap
  // allocation.
  // Throws std::invalid_argument before a `set`, on sizes other than phase1's,
  // and for double rounds after a FusedPrecision::Float set.
  AlternationResults run(const FixedCoordinateSolver<Scalar>& phase1, InputProjection<Scalar>& projection,
                         const Eigen::Ref<const Vector<Scalar>>& b, const AlternationSettings& options,
                         Eigen::Ref<Vector<Scalar>> z, Eigen::Ref<Vector<Scalar>> y);

  // E(y) of (*) (docs/engine.md, "The energy of the alternation") at this
  // b (m) and y (k), in double: the energy `run`'s safeguard and second-order
  // steps judge by. NaN when phase1 has no energy terms or the projection no
  // quadratic_term. *slack (optional): reduced_energy's for float rounds.
  // Overwrites the workspace's product (the next `run` starts afresh).
  // Throws std::invalid_argument before a `set` and on sizes other than
  // phase1's.
  double energy(const FixedCoordinateSolver<Scalar>& phase1, InputProjection<Scalar>& projection,
                const Eigen::Ref<const Vector<Scalar>>& b, const Eigen::Ref<const Vector<Scalar>>& y,
                double* slack = nullptr);

  bool ready() const;
  bool factored() const;   // the rounds use the factored form
  // The rounds step on E(y) for constraints on y ("Constraints on y"), and
  // their proximal weights D, one per block of the projection's
  // proximal_block_size() (empty otherwise).
  bool constrained_y() const;
  // Whether `run` takes second-order steps for this projection and these
  // options: stiff constraints on y, a projection whose rotation_blocks() is
  // true, and AlternationSettings::second_order.
  bool second_order(const InputProjection<Scalar>& projection, const AlternationSettings& options) const;
  // The rounds `run` takes for this projection and these options: second
  // order, Anderson-accelerated, or plain (parallel or serial). The first
  // two evaluate E(y) and report it; plain rounds do not.
  enum class Path { SecondOrder, Accelerated, Plain };
  Path path(const InputProjection<Scalar>& projection, const AlternationSettings& options) const;
  const Vector<double>& proximal_weights() const;
  // The projection's InputProjection::proximal_block_size(), which the
  // weights D are formed for (0, the default: one scalar weight). Resets
  // ready(): call before `set`. Throws std::invalid_argument when < 0.
  void set_proximal_block_size(Index block);
  bool float_set() const;  // the factored form's G_z·T (and F_b) were formed in float
  // The G_z, G_y kept by the last set or prepare (empty before any).
  const Matrix<Scalar>& Gz() const;
  const Matrix<Scalar>& Gy() const;

 private:
  void set_impl(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>* Gz, const Matrix<Scalar>* Gy,
                int threads, FusedForm form, FusedPrecision precision);

  std::unique_ptr<detail::FusedModel> model_;          // what `set` and `prepare` form
  std::unique_ptr<detail::FusedWorkspace> workspace_;  // the rounds' vectors
};

}  // namespace qpreduce
