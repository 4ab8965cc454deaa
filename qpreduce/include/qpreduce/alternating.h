// qpreduce — the alternating scheme of Section 3.1: Phase 1 (a reduced QP in
// the linear coordinates z with the other coordinates y held fixed) and
// Phase 2 (a plugin's projection of y onto its manifold), warm-started.
//
// In the deformation model the linear term of the energy is q = D·S and the
// subspace coordinates of U·D are the same S: X = N·z + UD·y with y = S.
// Phase 1 (Eq. 16–17) therefore minimises over z alone, y = Y given:
//
//     min_z ½zᵀH_zz z + zᵀH_zy Y − (NᵀD·Y)ᵀz   s.t.  A_z z = b − A_y Y
//
// with H_r = [[H_zz, H_zy], [H_yz, H_yy]] = BᵀHB (B = [N UD]), A_r = AᵀB =
// [A_z A_y] (m×d, m×k), NᵀD the first d rows of BᵀD. With G = NᵀD − H_zy (d×k)
// and c = b − A_y Y, the answer is z = M_c·c + M_g·G·Y, i.e.
//
//     z = M_b·b + M_Y·Y,   M_b = M_c (d×m),  M_Y = M_g·G − M_c·A_y (d×k).
//
// `FixedCoordinateSolver::set_constraints` forms M_b, M_Y (cost independent of
// n beyond AᵀB); `solve` is two GEMVs with no heap allocation. Soft
// constraints (Eq. 18 form) work the same way.
//
// Fast path (ConstraintOptions::fast_path, the default), the range-space
// form of subspace_solver.h applied to H_zz. Once per precomputed solver (at
// the first set_constraints after its precompute or restore): with
// D_s = diag(H_zz)^(−1/2), H_zz's lifted inverse M0 = D_s·H̃_zz⁻¹·D_s (d×d),
// its ν lifted directions V_L, and the unconstrained z-response to Y,
// P0 = M0·G (d×k) and LᵀG (ν×k, L = D_sV_L/σ). Per constraint set, with
// Y' = [M0·A_zᵀ, L] (d×μ, μ = m + ν), the bordered Schur complement Σ (μ×μ,
// inverted through its blocks: src/range_space.h) and T = Y'·Σ⁻¹ (d×μ):
//
//     M_b = T's first m columns,   M_Y = P0 − T·R,
//     R = Y'ᵀG + [A_y; 0] = [A_z·P0 + A_y; LᵀG]   (μ×k),
//
// O(d·μ·(d + k)) instead of the null-space method's O(d³ + d²k). In double
// M_Y is kept as (P0, T, R): `solve` applies P0·Y − T·(R·Y), μ·(d + k)
// multiply-adds more than one d×k GEMV, and the d×μ×k product is never
// formed (MY() forms it on request). It is taken
// for full-rank hard and for soft constraints when the problem is well
// conditioned (the test of subspace_solver.h); anything else (rank-deficient
// or least-squares constraint sets, an energy that is not convex on the
// constraint set) falls back to the null-space method, which decides the
// status. ConstraintSummary::fast_path says which ran.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/subspace_solver.h"

#include <limits>
#include <memory>

namespace qpreduce {

namespace detail {
struct FixedCoordinatePrep;  // alternating.cpp: the fast path's per-solver part
}  // namespace detail

template <typename Scalar>
class FusedAlternation;

template <typename Scalar>
class FixedCoordinateSolver {
 public:
  using VectorS = Vector<Scalar>;
  using ConstRef = Eigen::Ref<const VectorS>;
  using Ref = Eigen::Ref<VectorS>;

  // A: n×m sparse constraint columns (AᵀX = b). `solver` must be ready; it is
  // read here and not kept (the fast path keeps what it prepared from it, and
  // redoes that after the solver's next precompute or restore). Throws
  // std::invalid_argument on bad sizes/NaN.
  ConstraintSummary set_constraints(const SubspaceSolver<Scalar>& solver, const SparseMatrix<Scalar>& A,
                                    const ConstraintOptions& options = {});
  // The same from the reduced constraints A_z = AᵀN (m×d) and A_y = AᵀUD
  // (m×k), for a caller that keeps rows of B = [N UD] at hand (a row-major
  // copy gathers m rows at O(m·p) contiguous reads; AᵀB on the column-major
  // subspace touches m·p scattered cache lines, a millisecond at p ≈ 700).
  ConstraintSummary set_reduced_constraints(const SubspaceSolver<Scalar>& solver, const Matrix<double>& Az,
                                            const Matrix<double>& Ay, const ConstraintOptions& options = {});

  // The fast path's per-solver part (H_zz's lifted inverse M0, P0 = M0·G
  // and LᵀG; O(d³ + d²k)) now, instead of in the first set_constraints after
  // the solver's precompute or restore; nothing when it is current. For
  // callers that count it as precompute, so that the first handle set costs
  // what the later ones do (the deformer). Throws std::invalid_argument when
  // `solver` is not ready.
  void prepare(const SubspaceSolver<Scalar>& solver);

  // z = M_b·b + M_Y·Y. b: m, Y: k, z: d. No heap allocation. Not for
  // concurrent calls on one object (the factored M_Y uses a scratch vector).
  void solve(const ConstRef& b, const ConstRef& Y, Ref z) const;

  bool ready() const { return ready_; }
  const Matrix<Scalar>& Mb() const { return Mb_; }  // d × m
  // d × k. Formed on each call when the fast path keeps it factored (double).
  Matrix<Scalar> MY() const;
  Index d() const { return Mb_.rows(); }
  Index k() const { return k_; }
  Index m() const { return Mb_.cols(); }

 private:
  friend class FusedAlternation<Scalar>;
  void prepare_impl(const SubspaceSolver<Scalar>& solver);
  Matrix<Scalar> Mb_;  // d × m
  Matrix<Scalar> MY_;  // d × k; empty when factored (fast path, double)
  Index k_ = 0;
  mutable Vector<double> ry_;  // μ: R·Y in the factored solve
  // Fast path (see above), in double: the per-solver part, and M_Y = P0 − T·R.
  std::shared_ptr<const detail::FixedCoordinatePrep> prep_;
  Matrix<double> T_;   // d × μ; M_b is its first m columns
  Matrix<double> R_;   // μ × k
  bool fast_ = false;  // the current M_b, M_Y came from the fast path
  bool ready_ = false;
};

struct AlternatingOptions {
  // Phase 1/Phase 2 rounds per call (the paper uses a fixed 8 per frame, so a
  // frame's cost does not depend on the pose).
  int iterations = 8;
  // Stop early when ‖Δy‖ ≤ tolerance·max(1, ‖y‖). 0: always run `iterations`.
  double tolerance = 0.0;
  // FusedAlternation<double>: form the round's product F_y·y in float
  // (g = F_b·b + F_y·y keeps F_b·b and the sum in double). About 2.5× faster
  // at k ≈ 250 on baseline x86-64; the Phase 2 input then carries a relative
  // error of ~1e-7·‖F_y‖‖y‖/‖g‖, which a projection onto rotations absorbs.
  // Phase 1's final z = M_b·b + M_Y·y stays in double, so hard constraints
  // hold to double precision either way.
  bool float_products = false;
  // FusedAlternation: OpenMP threads for the rounds when the projection is
  // block-separable (InputProjection::block_size() > 0) and F_y has at least
  // parallel_min_entries entries (0 means omp_get_max_threads()). Each thread
  // owns a contiguous range of blocks: its rows of F_y·y, then Phase 2 on its
  // own blocks, then one barrier per round. The rows of F_y a thread reads
  // stay in its core's cache from round to round: at q = k = 468 (52
  // clusters) the float F_y is 876 KiB, more than one core's L2, half of it
  // less. The rounds are those of the serial ones; an entry of g can differ
  // in its last bits where the row split moves it between the SIMD kernel's
  // vector body and its scalar tail.
  int threads = 1;
  Index parallel_min_entries = 256 * 256;

  bool is_valid(std::string* why) const;
};

struct AlternatingSummary : Outcome {  // Success after a run
  int iterations = 0;
  double last_change = 0.0;  // ‖Δy‖ of the last Phase 2
};

// Phase 2 projections whose input is linear in (z, y): g = G_z·z + G_y·y
// (g: q entries), then y ← Π(g). Substituting Phase 1, z = M_b·b + M_Y·y,
//     g = (G_z·M_b)·b + (G_z·M_Y + G_y)·y = g_b + F_y·y,
// so a round costs one q×k GEMV plus Π, g_b is formed once per call, and z
// once after the last round. The iterates are those of the plain alternation
// (Phase 1 solve, then Phase 2 on (z, y)) exactly.
//
// When Phase 1 came from its fast path (M_Y = P0 − T·R, M_b = T's first m
// columns, above),
// `set` splits F_y into a part that depends on G_z and Phase 1's solver only
// and a rank-μ correction:
//
//     F_y = C0 + G_y − (G_z·T)·R,   C0 = G_z·P0   (q×k),
//     F_b = G_z·M_b = the first m columns of G_z·T.
//
// C0 is formed once and kept for as long as Phase 1's precomputed solver and
// the contents of G_z stay the same (compared bitwise on each `set`; G_y may
// change freely), so a new constraint set costs O(q·μ·(d + k)) instead of
// O(q·d·k).
//
// Factored form (FusedForm; automatic for q·k > kExplicitMaxEntries). The
// rank-μ update of the q×k F_y is still q·μ·k multiply-adds and three passes
// over q×k arrays per constraint set: 1.4 ms at q = k = 540. The factored
// form keeps F₀ = C0 + G_y (formed once per (Phase 1 preparation, G_z,
// G_y), both compared bitwise) and applies the correction in each round:
//     g = g_b + F₀·y − (G_z·T)·(R·y),
// so a constraint set costs O(q·μ·d) (G_z·T) and a round μ·(q + k) more
// multiply-adds (10–20% of the q·k product at μ = 27; in float with
// float_products, like the product itself). For F_y within
// kExplicitMaxEntries (256² entries: 256 KiB in float, in L2) the explicit
// form's rounds are cheaper and its set-up is small, so it is kept there.
template <typename Scalar>
class InputProjection {
 public:
  virtual ~InputProjection() = default;
  // y ← Π(g); returns ‖y_new − y_old‖. Should not allocate.
  virtual double project(const Eigen::Ref<const Vector<Scalar>>& g, Eigen::Ref<Vector<Scalar>> y) = 0;

  // Optional block structure, for parallel rounds (AlternatingOptions::
  // threads). block_size() = s > 0 promises that Π acts block by block on
  // g and y of equal length (q = k): block j of y (entries [s·j, s·(j + 1)))
  // depends only on block j of g and of the old y. project_blocks then
  // updates blocks [first, last) of y only, reads no other entry of y, and
  // returns Σ‖Δy_j‖² over them; it is called concurrently on disjoint ranges.
  // Override both or neither; 0 (the default) keeps the rounds serial.
  virtual Index block_size() const { return 0; }
  virtual double project_blocks(const Eigen::Ref<const Vector<Scalar>>& g, Eigen::Ref<Vector<Scalar>> y,
                                Index first, Index last) {
    (void)g, (void)y, (void)first, (void)last;
    return std::numeric_limits<double>::quiet_NaN();  // never called when block_size() == 0
  }
};

enum class FusedForm { Automatic, Explicit, Factored };

// What `set` forms per constraint set in the factored form, in double or in
// float. Float: G_z·T (q×μ×d multiply-adds, most of a new constraint set's
// cost) by the BLAS in single precision, at about twice the double rate; for
// rounds with AlternatingOptions::float_products, where G_z·T is a float
// operand anyway. F_b = G_z·M_b, its first m columns, then carries float
// round-off as well (g_b = F_b·b to ~1e-7 relative, the order of the float
// rounds' own error); Phase 1's final z = M_b·b + M_Y·y stays in double, so
// hard constraints still hold to double precision. `run` with double rounds
// after a Float set throws. The explicit form is formed in double either way.
enum class FusedPrecision { Double, Float };

template <typename Scalar>
class FusedAlternation {
 public:
  static constexpr Index kExplicitMaxEntries = 256 * 256;

  // Forms F_b = G_z·M_b (q×m) and F_y = G_z·M_Y + G_y (q×k) for the current
  // constraint set of `phase1` (call again after each set_constraints).
  // Throws std::invalid_argument on mismatched sizes or an unready phase1.
  // `threads`: BLAS threads for these products (as ConstraintOptions::threads;
  // 0 leaves the BLAS's own setting).
  // `form`: see "Factored form" above (Factored applies only when Phase 1
  // came from its fast path and Scalar is double; otherwise explicit).
  // `precision`: see FusedPrecision.
  void set(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz, const Matrix<Scalar>& Gy,
           int threads = 1, FusedForm form = FusedForm::Automatic,
           FusedPrecision precision = FusedPrecision::Double);
  // The same with the G_z, G_y of the last call above, without comparing them
  // (2 passes over q × (d + k) saved; the caller knows they did not change).
  // Throws std::invalid_argument before any G_z, G_y were given.
  void set(const FixedCoordinateSolver<Scalar>& phase1, int threads = 1, FusedForm form = FusedForm::Automatic,
           FusedPrecision precision = FusedPrecision::Double);

  // C0 = G_z·P0 (and G_z's float copy for `precision` Float) now, for the
  // solver `phase1` was prepared for (FixedCoordinateSolver::prepare or a
  // fast-path set_constraints), instead of in the first `set`; keeps G_z, G_y
  // as the inputs of set(phase1). Without a prepared fast path (or for
  // Scalar = float) it only keeps the inputs. Call `set` before `run`.
  // Throws std::invalid_argument on mismatched sizes or NaN.
  void prepare(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz, const Matrix<Scalar>& Gy,
               FusedPrecision precision = FusedPrecision::Double);

  // `options.iterations` rounds from the given y (warm start), then
  // z = M_b·b + M_Y·y. No heap allocation. Throws std::invalid_argument
  // before a `set` (a `prepare` resets it), on sizes other than phase1's, and
  // for double rounds (float_products false) after a FusedPrecision::Float set.
  AlternatingSummary run(const FixedCoordinateSolver<Scalar>& phase1, InputProjection<Scalar>& projection,
                         const Eigen::Ref<const Vector<Scalar>>& b, const AlternatingOptions& options,
                         Eigen::Ref<Vector<Scalar>> z, Eigen::Ref<Vector<Scalar>> y);

  bool ready() const { return ready_; }
  bool factored() const { return factored_; }
  // The factored form's G_z·T (and F_b) were formed in float.
  bool float_set() const { return float_set_; }

 private:
  // Both `set`s; same_inputs: Gz, Gy are Gz_, Gy_ (no comparison, no copy).
  void set_impl(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz, const Matrix<Scalar>& Gy,
                int threads, FusedForm form, FusedPrecision precision, bool same_inputs);
  // Keep copies of the inputs (for set(phase1, ...) and the bitwise tests);
  // a changed input invalidates what was formed from it.
  void keep_inputs(const Matrix<Scalar>& Gz, const Matrix<Scalar>& Gy);
  // C0 = G_z·P0 unless it is current for phase1's preparation (double).
  void form_c0(const FixedCoordinateSolver<Scalar>& phase1, const Matrix<Scalar>& Gz);
  // G_z's float copy (FusedPrecision::Float) unless it is current.
  void form_gz_float(const Matrix<Scalar>& Gz);
  // Rows [r0, r1) of g = g_b + F_y·y into g_, from y, or from its float copy
  // yf when not null. ry, ryf: μ scratch for R·y (factored form).
  void round_product(const Scalar* y, const float* yf, Index r0, Index r1, double* ry, float* ryf);
  // The rounds of `run` on `threads` threads over block ranges (see
  // AlternatingOptions::threads); leaves z to the caller.
  AlternatingSummary run_parallel(InputProjection<Scalar>& projection, const AlternatingOptions& options,
                                  Index threads, Index block, Eigen::Ref<Vector<Scalar>> y);

  Matrix<Scalar> Fb_, Fy_;
  // Fast path: C0 = G_z·P0 (q×k, double), with the Phase 1 preparation and
  // a copy of the G_z it was formed from.
  std::shared_ptr<const detail::FixedCoordinatePrep> prep_;
  Matrix<Scalar> Gz_;
  Matrix<double> C0_;
  Matrix<float> Gz_f_;  // G_z in float, formed with C0 at the first Float set
  Matrix<float> Fy_f_;  // F_y in float (AlternatingOptions::float_products)
  // Factored form: F₀ = C0 + G_y in Fy_ / Fy_f_ (base_ready_), G_z·T (q×μ)
  // and R (μ×k); ry_ = R·y per round. Gz_ and Gy_ are the last inputs.
  Matrix<Scalar> Gy_;
  Matrix<double> GzT_, R_;
  Matrix<float> GzT_f_, R_f_;  // (AlternatingOptions::float_products)
  Vector<double> ry_;
  Vector<float> ryf_;
  Matrix<double> ry_threads_;  // μ × threads, for run_parallel
  Matrix<float> ryf_threads_;
  bool base_ready_ = false, factored_ = false, inputs_ready_ = false, float_set_ = false;
  Vector<Scalar> gb_, g_;
  Vector<float> gf_, yf_;
  // Parallel rounds: y as read by the next round's product, double-buffered
  // (round r reads buffer r mod 2 and its Phase 2 writes the other).
  Matrix<float> yf2_;
  Matrix<Scalar> y2_;
  bool ready_ = false;
};

}  // namespace qpreduce
