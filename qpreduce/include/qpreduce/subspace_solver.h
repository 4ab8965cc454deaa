// qpreduce — the reduced solver: precompute once, then any demand (A, b, q).
//
// With the variational subspace X = N·z + UD·y = B·w (B = [N UD], n × p,
// p = d + k, w = [z; y]; Eq. 5), a demand of Eq. 1
//     min_X ½XᵀHX − qᵀX   s.t.  AᵀX = b          (A n × m, b m × 1, q n × 1)
// becomes, substituting X = B·w (A and q need NOT lie in Span(C), Span(D)),
//     min_w ½wᵀH_r w − q_rᵀw   s.t.  A_r w = b,
//     H_r = BᵀHB (p × p, precomputed),  A_r = AᵀB (m × p),  q_r = Bᵀq (p × 1),
// with hard constraints (Eq. 17 form) or soft ones of weight δ (Eq. 18 form,
// (H_r + 2δA_rᵀA_r)·w = q_r + 2δA_rᵀb). Either way the answer is linear,
//     w = M_b·b + M_q·q_r,   and with q = D·Y also   w = M_b·b + M_Y·Y,
// so `set_constraints` (the paper's on-site step) forms these small operators
// at a cost independent of n beyond AᵀB, and `solve` is a few matrix–vector
// products into caller-owned storage, with no heap allocation.
//
// How (docs/engine.md, "Demands"): rank and conditioning tests in energy-
// normalised coordinates (B's columns scaled to unit energy); a range-space
// fast path from H_r's lifted inverse, precomputed once, for full-rank hard
// and for soft constraints, kept factored (no p × p operator) when A_r is
// sparse; the null-space method on a rank-revealing QR of A_rᵀ otherwise,
// which gives the least-squares answer (Status::ConstraintsLeastSquares) for
// rank-deficient hard constraints and the minimum-norm stationary point
// (Status::Unbounded) when the energy is not convex on the constraint set.
// Entries of AᵀB that are round-off (cosine ≤ drop_tolerance) are zeroed, so
// in-design demands keep their sparsity ("Round-off in A_r = AᵀB").
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/constraints.h"
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
  // Redoes only the p×p fast-path preparation (O(p³), no factorization;
  // SubspaceOptions::prepare_constraint_path) and the column norms ‖B_j‖
  // (O(n·p)).
  // Throws std::invalid_argument on inconsistent sizes, NaN/Inf, or an
  // asymmetric H_r.
  void restore(VariationalSubspace<Scalar> subspace, Matrix<double> Hr, Matrix<double> BtD,
               const SubspaceOptions& options = {});
  // Restores the reduced solver without the basis: n (rows of B), d (N's
  // columns), the column norms ‖B_j‖₂ (p; ConstraintOptions::drop_tolerance
  // uses them), H_r (p×p, symmetric) and BᵀD (p×k, k = p − d). For callers
  // that keep their own (e.g. float) copy of the basis and form A_r = AᵀB
  // themselves: solve, solve_in_D, reduce_linear_term_in_D,
  // set_constraints_in_design and the reduced accessors work; set_constraints,
  // reduce_linear_term and reconstruct need B and throw std::invalid_argument
  // saying so. Throws on inconsistent sizes, NaN/Inf, a negative norm or an
  // asymmetric H_r. has_basis() is false afterwards.
  void restore_without_basis(Index n, Index d, Vector<double> basis_norms, Matrix<double> Hr, Matrix<double> BtD,
                             const SubspaceOptions& options = {});
  // Frees B = [N UD] (n×p) and keeps everything else (the reduced operators,
  // the constraint set, ‖B_j‖): afterwards as after restore_without_basis.
  // For a caller that has taken from B what it needs (the deformer's float
  // reconstruction basis): n·p·sizeof(Scalar) bytes less resident.
  void release_basis();

  // The on-site step for a new constraint set A (n×m, sparse). m may be 0.
  // With SubspaceOptions::prepare_constraint_path false, the first call
  // after precompute or restore also prepares the fast path (O(p³) once).
  // Throws std::invalid_argument on a wrong row count, NaN, or when called
  // before a successful precompute.
  ConstraintSummary set_constraints(const SparseMatrix<Scalar>& A, const ConstraintOptions& options = {});
  // The same with A_r = AᵀB (m × p) formed by the caller — e.g. summed over
  // the processes that each hold rows of B (qpreduce::distributed), for a
  // solver restored without its basis. A (n × m) gives the checks and the
  // rows' norms of ConstraintOptions::drop_tolerance. Throws
  // std::invalid_argument on wrong sizes or NaN.
  ConstraintSummary set_constraints_reduced(const SparseMatrix<Scalar>& A, Matrix<double> Ar,
                                            const ConstraintOptions& options = {});
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
  // B = [N UD] is held (false after restore_without_basis or release_basis).
  bool has_basis() const { return ready_ && has_basis_; }
  bool constrained() const { return constrained_; }
  Index n() const { return n_; }
  Index d() const { return d_; }
  Index k() const { return k_; }
  Index p() const { return d() + k(); }
  Index m() const { return m_; }
  // B = [N UD]; empty (0 × 0 blocks) when !has_basis().
  const VariationalSubspace<Scalar>& subspace() const { return subspace_; }
  const Vector<double>& basis_norms() const { return basis_norms_; }  // ‖B_j‖₂, p
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
  void require_basis(const char* what) const;
  // Checks and stores H_r and BᵀD (sizes p × p, p × k; finite; H_r symmetric).
  void set_reduced(const char* what, Index p, Index k, Matrix<double> Hr, Matrix<double> BtD);
  // ‖B_j‖ from the held basis (precompute, restore).
  void compute_basis_norms();
  // A new generation and lift tolerance (precompute, restore); the range
  // space now or, with SubspaceOptions::prepare_constraint_path false, at
  // the first set_constraints.
  void prepare_fast_path(const SubspaceOptions& options);
  // The fast path's p×p preparation (O(p³)): range_, P0_, lift_btd_.
  void prepare_range_space();
  // Everything of set_constraints after A_r (m × p) is formed; sets all but `seconds`.
  ConstraintSummary apply_constraints(MatD Ar, const ConstraintOptions& options);
  bool fast_operators(const MatD& Ar, const ConstraintOptions& options, bool factored, ConstraintSummary* summary,
                      MatD* Mb, MatD* Mq, MatD* MY);
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
  // Precomputed, in double (docs/engine.md, "Fast path"), in unscaled coordinates.
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
  Index n_ = 0, m_ = 0, d_ = 0, k_ = 0;
  bool ready_ = false, constrained_ = false, factored_ = false, has_basis_ = false;
};

}  // namespace qpreduce
