// qpreduce — the reduced solver: precompute once, then any demand (A, b, q).
//
// With the variational subspace X = N·z + UD·y = B·w  (B = [N UD], n×p,
// p = d + k, w = [z; y]; Eq. 5), a demand of Eq. 1
//     min_X ½XᵀHX − qᵀX   s.t.  AᵀX = b          (A n×m, b m×1, q n×1)
// becomes, substituting X = B·w (A and q need NOT lie in Span(C), Span(D)),
//     min_w ½wᵀH_r w − q_rᵀw   s.t.  A_r w = b,
//     H_r = BᵀHB (p×p, precomputed),  A_r = AᵀB (m×p),  q_r = Bᵀq (p×1).
//
// Hard constraints (Eq. 17 form). Null-space method on a rank-revealing QR of
// A_rᵀ: w = A_r⁺b + Z·u with Z (p×(p−r)) a basis of ker(A_r) and
//     (ZᵀH_rZ)·u = Zᵀ(q_r − H_r A_r⁺ b).
// When rank(A_r) = r < m the constraints cannot all hold for every b: the
// answer satisfies them in the least-squares sense (min ‖A_r w − b‖, then the
// energy) and the summary says Status::ConstraintsLeastSquares.
//
// Soft constraints (Eq. 18 form), weight δ > 0:
//     min_w ½wᵀH_r w − q_rᵀw + δ‖A_r w − b‖²
//     ⇔ (H_r + 2δA_rᵀA_r)·w = q_r + 2δA_rᵀb.
//
// Either way the answer is linear in (b, q_r):  w = M_b·b + M_q·q_r, and with
// q = D·Y also w = M_b·b + M_Y·Y (M_Y = M_q·BᵀD, p×k). `set_constraints` (the
// paper's on-site preconditioning, "OP") forms these small dense matrices at a
// cost independent of n beyond AᵀB (nnz(A)·p for sparse A); `solve` is two
// matrix–vector products into caller-owned storage, with no heap allocation
// (M_q is symmetric and only its lower triangle is read).
//
// Scale invariance. N's and UD's columns can differ in scale by orders of
// magnitude (UD's grow with the mesh), so every rank and conditioning test is
// made in energy-normalised coordinates w = D_s·w̄, D_s = diag(H_r)^(−1/2),
// where each column of B has unit energy: H̄ = D_sH_rD_s, Ā = A_rD_s.
//
// Fast path (the default for full-rank hard and for soft constraints).
// `precompute` factors H̄ = VΛVᵀ once and lifts its near-null directions V_L
// (λ_i ≤ lift_tolerance·λ_max) to σ = λ_max: H̃ = H̄ + V_L(σ − Λ_L)V_Lᵀ is SPD
// and H̃⁻¹ is stored (p×p). A demand then only needs the small Schur
// complement of the bordered system with Ã = [Ā; V_Lᵀ] ((m+ν)×p):
//     Σ = ÃH̃⁻¹Ãᵀ + diag(c·I_m, −(σ − Λ_L)⁻¹),   c = 0 (hard) or 1/(2δ) (soft),
//     M̄_q = H̃⁻¹ − YΣ⁻¹Yᵀ,  M̄_b = YΣ⁻¹[I_m; 0],  Y = H̃⁻¹Ãᵀ,
// about 4·p²·(m+ν) flops instead of the O(p³) null-space method. The answer
// is accepted only when λ_max(H̄)·‖M̄_q‖_F < 1/rank_tolerance, a bound on the
// condition number the null-space method tests; anything else (and rank-
// deficient hard constraints) goes to the null-space method, which decides the
// status. Both give the same unique minimiser when it exists. (The same
// range-space code, src/range_space.h, serves Phase 1 in alternating.h.)
// The rank test (a column-pivoted QR of Āᵀ, p×m) runs on Ā's nonzero columns
// only: the other rows of Āᵀ are zero and change neither R nor the rank; for
// a scaled selection (one nonzero per row of Ā, in distinct columns) R is
// diagonal and rank and condition are read off Ā's nonzeros.
//
// Factored fast path (double, when A_r is sparse: constraints in design
// coordinates, A_r = [A_cᵀ 0], with A_c a selection or a few sums). Forming
// the p×p M̄_q above is then the only O(p²·(m+ν)) term; instead keep, in
// unscaled coordinates (q = m + ν; M0 = D_sH̃⁻¹D_s and P0 = M0·BᵀD (p×k)
// precomputed; L = D_sV_L/σ, p×ν),
//     Y  = [M0·A_rᵀ, L]                                          p×q,
//     Σ  = [[A_r·M0·A_rᵀ + c·I_m, A_r·L], [Lᵀ·A_rᵀ, −λ_L/(σ(σ − λ_L))]],
//     Σ⁻¹ from Cholesky factors of Σ's m×m block and of its negated ν×ν
//         Schur complement (Σ has m positive, ν negative eigenvalues), q×q,
//     Φ  = Σ⁻¹·YᵀBᵀD = Σ⁻¹·[A_r·P0; LᵀBᵀD]                       q×k,
// so that M_q = M0 − YΣ⁻¹Yᵀ, M_b = YΣ⁻¹[I_m; 0], M_Y = P0 − YΦ, applied as
//     solve:       w = M0·q_r + Y·(Σ⁻¹·([b; 0] − Yᵀq_r))   p² + 2pq + q² flops,
//     solve_in_D:  w = P0·Y_D + Y·(Σ⁻¹[I_m; 0]·b − Φ·Y_D)  p(k + q) + q(m + k).
// The acceptance test needs ‖M̄_q‖_F without M̄_q: with K_j = ÃH̃⁻ʲÃᵀ (q×q),
//     ‖M̄_q‖_F² = ‖H̃⁻¹‖_F² − 2·tr(Σ⁻¹K₃) + tr(Σ⁻¹K₂Σ⁻¹K₂),
//     K_j = [[A_r·T_j·A_rᵀ, σ^(1−j)·A_r·L], [·, σ^(−j)·I_ν]],  T_j = D_sH̃⁻ʲD_s,
// T₂, T₃ (p×p) precomputed next to M0: the same norm and the same bound.
// Every product with A_r touches only its nonzeros, so the on-site step costs
// O(nnz(A_r)·(p + m + k) + q³) — for a selection of m design coordinates
// O(p·m + m³) — instead of about 4·p²·q. Round-off: the explicit path forms
// M_q = M0 − YΣ⁻¹Yᵀ in double too, so both carry errors of order ε·‖M0‖; in
// float the factored form would carry ε_float·‖M0‖ where the explicit M_q
// (formed in double, then rounded) has ε_float·‖M_q‖, so the float solver
// always keeps explicit operators.
//
// Round-off in A_r = AᵀB (set_constraints only). For an in-design demand,
// A = C·A_c, A_r = [A_cᵀ 0] has as few nonzeros as A_c, but the computed
// B satisfies CᵀN = I, CᵀUD = 0 only to round-off, so AᵀB comes out dense
// (gmrf, n ≈ 10⁵: 17,830 of 18,360 entries nonzero for m nonzeros) and the
// factored path is never taken. With a_i the i-th column of A and B_j the
// j-th of B, measure an entry by its cosine
//     γ_ij = |A_r(i,j)| / (‖a_i‖₂‖B_j‖₂) ≤ 1   (A_r(i,j) = a_iᵀB_j);
// for a_i = C·c_i and an entry that is zero in [A_cᵀ 0] (A_c = [c_1 … c_m]),
//     γ_ij = |c_iᵀ(CᵀB_j − [I 0]_j)| / (‖C·c_i‖‖B_j‖)
//          ≤ (‖CᵀB_j − [I 0]_j‖/‖B_j‖)·(‖c_i‖/‖C·c_i‖),
// the column-wise relative KKT residual of the build (not the Frobenius-
// normalised SubspaceSummary::kkt_residual, which is smaller by the ratio of
// the global norms to the column's: 6·10⁻¹⁹ for gmrf at n ≈ 10⁵, whose
// round-off cosines reach 4·10⁻¹⁷). Entries with
//     |A_r(i,j)| ≤ τ·‖a_i‖₂·‖B_j‖₂,   τ = ConstraintOptions::drop_tolerance,
// are therefore set to exactly zero (ConstraintSummary::dropped counts them);
// ‖B_j‖ is kept per precompute/restore (p numbers), ‖a_i‖ costs nnz(A).
// For any A, in the design or not, this changes row i of A_r by at most
// τ·‖a_i‖·‖B‖_F, and a genuinely dense A_r loses only entries that small.
// Measured on the three families (families.h at the bench sizes n ≈ 10⁴ and
// 10⁵, 16 in-design demands each): round-off cosines ≤ 1.0·10⁻¹⁴
// (portfolio; gmrf ≤ 10⁻¹⁶, trajectory ≤ 10⁻¹⁵; the column bound above
// ≤ 2.3·10⁻¹², portfolio), genuine ones ≥ 0.06. The default τ = 10⁻¹⁰ (the
// default rank_tolerance too) sits 4 decades above the first and 8 below
// the second. The in-design A_r then has exactly the nonzeros of [A_cᵀ 0],
// and the factored path and its selection shortcut apply as with
// set_constraints_in_design. Off-design rows keep their large entries
// (largest cosine per row ≥ 4.6·10⁻³ on the families' off-design demands)
// and lose only the tails of decaying columns. A row
// that is dropped entirely (a constraint with no component in Span(B) above
// τ) makes the constraint set rank deficient: hard constraints then hold in
// the least-squares sense (Status::ConstraintsLeastSquares) and the message
// says how many rows were dropped; soft ones report the lower rank.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/subspace.h"

#include <cstdint>
#include <memory>
#include <string>

namespace qpreduce {

namespace detail {
// Private to the engine (src/range_space.h, src/factored_operators.h).
struct RangeSpace;
struct FactoredOperators;
}  // namespace detail

struct ConstraintOptions {
  // false: hard constraints (Eq. 17); true: soft constraints (Eq. 18).
  bool soft = false;
  // Soft-constraint weight δ (Eq. 18). Relative to H_r's scale: the system
  // solved is H_r + 2·δ·A_rᵀA_r, so δ ≫ ‖H_r‖/‖A_r‖² approaches hard constraints.
  double delta = 1e3;
  // Singular values of Ā (and eigenvalues of the reduced Hessian on the
  // constraint set) below rank_tolerance × the largest count as zero.
  double rank_tolerance = 1e-10;
  // set_constraints(A) only: entries of A_r = AᵀB with |A_r(i,j)| ≤
  // drop_tolerance·‖a_i‖₂·‖B_j‖₂ (a_i: column i of A, B_j: column j of B)
  // are round-off and set to exactly zero (see "Round-off in A_r"): in-design
  // demands given as a sparse A then get the sparse A_r = [A_cᵀ 0] and the
  // factored path. Round-off measured ≤ 10⁻¹⁴, genuine entries of in-design
  // demands ≥ 0.06 on the three families; 0 keeps every entry. In [0, 1).
  double drop_tolerance = 1e-10;
  // Use the precomputed range-space fast path when it applies (see above;
  // likewise FixedCoordinateSolver and FusedAlternation, alternating.h);
  // false forces the O(p³) null-space method (for comparison and tests).
  bool fast_path = true;
  // OpenMP threads for the dense algebra of this step. At p ≈ 300 a step is
  // about a millisecond of GEMMs, where waking a second thread on a shared
  // machine costs more than it saves; 0 means omp_get_max_threads().
  int threads = 1;
  // false: the fast path keeps M_q factored (see "Factored fast path") when
  // Scalar is double, m + ν ≤ SubspaceSolver::kMaxFactoredRank and it is
  // cheaper: factored_cost_ratio × its sparse products' multiply-adds,
  // p·nnz + 3·min(nnz², nnz·(p + m)) (nnz = nnz(A_r): Y, then A_r·T·A_rᵀ for
  // T = M0, T₂, T₃), at most the explicit form's p²·(m + (m + ν)/2) (Y and
  // the rank-(m + ν) update of M0); otherwise it forms M_b, M_q, M_Y.
  // true: always form them (the explicit path, for comparison and tests).
  bool explicit_operators = false;
  // Cost of one multiply-add in the factored form's sparse loops relative to
  // one in the explicit form's BLAS GEMMs; only the automatic choice uses it.
  // Streaming column axpys measured about 10 (trajectory family, n = 10⁵,
  // a sparse A with nnz(A_r) = 5,384 of 16,320: 8.6 ms factored, 2.7 ms
  // explicit); the in-cache gathers of a selection less (portfolio, p = 70:
  // factored 14% faster although it counts 1.3 times the explicit work).
  // 5 takes the faster form on both and on every family's A_c demands.
  double factored_cost_ratio = 5.0;

  bool is_valid(std::string* why) const;
};

struct ConstraintSummary : Outcome {
  Index m = 0;            // number of constraints
  Index rank = 0;         // numerical rank of Ā = AᵀB·D_s (= rank of A_r)
  double condition = 0.0; // σ_max/σ_min(Ā) over its rank
  bool fast_path = false; // the answer came from the precomputed fast path
  bool factored = false;  // ... with M_q kept factored (no p×p operator formed)
  Index dropped = 0;      // entries of A_r zeroed by drop_tolerance (set_constraints)
  double seconds = 0.0;
};

template <typename Scalar>
class SubspaceSolver {
 public:
  using VectorS = Vector<Scalar>;
  using MatrixS = Matrix<Scalar>;
  using ConstRef = Eigen::Ref<const VectorS>;
  using Ref = Eigen::Ref<VectorS>;
  // Largest m + ν for which the fast path keeps M_q factored: `solve` keeps
  // two vectors of that length on the stack (8 KiB) to stay allocation-free.
  static constexpr Index kMaxFactoredRank = 512;

  // Builds the subspace from one factorization (build_subspace) and the
  // reduced matrices H_r = BᵀHB and BᵀD. Throws std::invalid_argument on bad
  // input (see build_subspace); numerical failures come back in the summary
  // and leave the solver unusable (ready() == false).
  SubspaceSummary precompute(const SparseMatrix<Scalar>& H, const SparseMatrix<Scalar>& C,
                             const SparseMatrix<Scalar>& D, const SubspaceOptions& options = {});

  // Restores a precomputed solver from its parts (e.g. read back from a cache
  // file): the subspace B = [N UD] (n×p), H_r = BᵀHB (p×p, symmetric) and
  // BᵀD (p×k), as `precompute` would have made them from the same options.
  // Redoes only the p×p fast-path preparation (O(p³), no factorization)
  // and the column norms ‖B_j‖ (O(n·p)).
  // Throws std::invalid_argument on inconsistent sizes, NaN/Inf, or an
  // asymmetric H_r.
  void restore(VariationalSubspace<Scalar> subspace, Matrix<double> Hr, Matrix<double> BtD,
               const SubspaceOptions& options = {});

  // The on-site step for a new constraint set A (n×m, sparse). m may be 0.
  // Throws std::invalid_argument on a wrong row count, NaN, or when called
  // before a successful precompute.
  ConstraintSummary set_constraints(const SparseMatrix<Scalar>& A, const ConstraintOptions& options = {});
  // The same for constraints given in the design space, A = C·A_c (A_c d×m,
  // dense): A_r = A_cᵀ·Cᵀ[N UD] = [A_cᵀ 0], because CᵀN = I and CᵀUD = 0
  // (Eq. 4, second row) — exact up to the precompute's kkt_residual. Costs
  // O(m·p) to form A_r plus the dense algebra of set_constraints: no term in
  // n, even when A itself is dense in n (group sums, factor loadings). Throws
  // std::invalid_argument when A_c does not have d rows, holds NaN, or
  // before a successful precompute.
  ConstraintSummary set_constraints_in_design(const MatrixS& A_c, const ConstraintOptions& options = {});

  // q_r = Bᵀq for a general linear term q (n). Cost O(n·p).
  void reduce_linear_term(const ConstRef& q, Ref q_r) const;
  // q_r = BᵀD·Y for q = D·Y (Y: k). Cost O(p·k).
  void reduce_linear_term_in_D(const ConstRef& Y, Ref q_r) const;

  // w = M_b·b + M_q·q_r. b: m, q_r: p, w: p (not aliasing q_r). No heap
  // allocation. Cost p² + p·m (explicit), p² + 2p·(m + ν) (factored).
  void solve(const ConstRef& b, const ConstRef& q_r, Ref w) const;
  // Same with q = D·Y (Y: k). No heap allocation. Cost p·(m + k) (explicit),
  // p·(k + m + ν) + (m + ν)·(m + k) (factored).
  void solve_in_D(const ConstRef& b, const ConstRef& Y, Ref w) const;
  // X = N·z + UD·y for w = [z; y]. X: n. Cost O(n·p).
  void reconstruct(const ConstRef& w, Ref X) const;

  bool ready() const { return ready_; }
  bool constrained() const { return constrained_; }
  Index n() const { return n_; }
  Index d() const { return subspace_.N.cols(); }
  Index k() const { return subspace_.UD.cols(); }
  Index p() const { return d() + k(); }
  Index m() const { return m_; }
  const VariationalSubspace<Scalar>& subspace() const { return subspace_; }
  const MatrixS& reduced_hessian() const { return Hr_; }  // H_r = BᵀHB, p×p
  const MatrixS& reduced_constraints() const { return Ar_; }  // A_r = AᵀB, m×p
  const MatrixS& reduced_linear_map() const { return BtD_; }   // BᵀD, p×k (q_r = BᵀD·Y)
  // Changes with every precompute and restore (a process-wide counter), so
  // that state derived from this solver (FixedCoordinateSolver's fast path)
  // knows when to redo it.
  std::uint64_t generation() const { return generation_; }
  // SubspaceOptions::reduced_lift_tolerance of the last precompute or restore.
  double lift_tolerance() const { return lift_tolerance_; }

 private:
  using MatD = Matrix<double>;
  void require_ready(const char* what) const;
  void require_constrained(const char* what) const;
  // The fast path's p×p preparation, ‖B_j‖ and a new generation (precompute, restore).
  void prepare_fast_path(double lift_tolerance);
  // Everything of set_constraints after A_r (m × p) is formed; sets all but `seconds`.
  ConstraintSummary apply_constraints(MatD Ar, const ConstraintOptions& options);
  void reference_operators(const MatD& Abar, const ConstraintOptions& options, ConstraintSummary* summary, MatD* Mb,
                           MatD* Mq, MatD* MY) const;

  VariationalSubspace<Scalar> subspace_;
  MatrixS Hr_;   // p × p
  MatrixS BtD_;  // p × k
  MatrixS Ar_;   // m × p
  Vector<double> basis_norms_;  // ‖B_j‖₂ (p), for ConstraintOptions::drop_tolerance
  MatrixS Mb_;   // p × m
  MatrixS Mq_;   // p × p, symmetric: only its lower triangle is kept current (solve reads that)
  MatrixS MY_;   // p × k
  // Precomputed, in double (see "Fast path" above), in unscaled coordinates.
  MatD Hr_d_;   // H_r
  MatD BtD_d_;  // BᵀD
  // D_s, λ_max(H̄), D_s·H̃⁻¹·D_s and the lifted directions (range_space.h);
  // immutable once made, so copies of the solver share it.
  std::shared_ptr<const detail::RangeSpace> range_;
  MatD P0_;  // D_s·H̃⁻¹·D_s·BᵀD (p × k)
  double lift_tolerance_ = 0.0;  // SubspaceOptions::reduced_lift_tolerance of the precompute
  std::uint64_t generation_ = 0;  // see generation()
  // For the factored fast path (double only; range_ then has T₂, T₃, ‖H̃⁻¹‖_F²).
  MatD lift_btd_;  // LᵀBᵀD (ν × k)
  // The factored operators of the current constraint set (when factored_);
  // copies of the solver share them until one of them sets new constraints.
  std::shared_ptr<detail::FactoredOperators> factored_ops_;
  Index n_ = 0, m_ = 0;
  bool ready_ = false, constrained_ = false, factored_ = false;
};

}  // namespace qpreduce
