// qpreduce — quotient equivalence and the error bound of Theorem 4.10
// (Ye & Yan, Section 4 and the appendix "Proof of Theorem 4.10").
//
// Dense analysis in double precision for small and medium problems (n up to a
// few hundred: one n×n eigendecomposition and one dense KKT solve). It checks
// the engine; it is not on any per-frame path.
//
// ---- The problem -----------------------------------------------------------
// Eq. 1:  min_X ½XᵀHX − qᵀX  s.t.  AᵀX = b,   H n×n symmetric PSD, A n×m, b m, q n,
// designed with C (n×d, A ≈ C·A_c) and D (n×k, q ≈ D·Y); the engine's reduced
// answer is X* ∈ Span(N) + Span(UD) (Eq. 5, subspace_solver.h).
//
// ---- Factor and distance (Section 4.1, Eq. 20–21) ---------------------------
// H = VΛVᵀ (eigendecomposition). Keep the r eigenvalues λ > rank_tolerance·λ_max:
//     L  = Λ_r^{1/2}·V_rᵀ      r × n   (H = LᵀL up to the dropped eigenvalues)
//     L⁺ = V_r·Λ_r^{−1/2}      n × r   (L·L⁺ = I_r, so Eq. 26's projection
//                                       (I − LL⁺)X̂ = 0 is void)
//     K  = V_{n−r}             n × ν   (ker H, ν = n − r; I − L⁺L = K·Kᵀ)
// X = X̃ + X̄ with X̃ = L⁺L·X (range of H) and X̄ = (I − L⁺L)·X = KKᵀX (ker H).
// The distance between quotient-equivalence classes (Def. 4.2) is
//     d_H(x, y) = ‖L(x − y)‖ = sqrt((x − y)ᵀH(x − y)).
// The paper prints d_H without the square root; Eq. 40 uses the norm, and so
// do we. d_H ignores any component in ker H.
//
// ---- Whitening (Eq. 25–29) ---------------------------------------------------
// With X̂ = L·X (r), the objective is ½‖X̂‖² − q̂ᵀX̂ − qᵀX̄ and the constraint
// ÂᵀX̂ = b − AᵀX̄. The consistent transposition for X̂ = LX is (L⁺)ᵀ on every
// data matrix (the paper writes L⁺ for q̂, Â and (L⁺)ᵀ for Ĉ, D̂; only (L⁺)ᵀ
// has the right shape, since X̃ᵀM = X̂ᵀ(L⁺)ᵀM):
//     Ĉ = (L⁺)ᵀC  r×d,   D̂ = (L⁺)ᵀD  r×k,   Â = (L⁺)ᵀA  r×m,   q̂ = (L⁺)ᵀq  r,
// and the companion right-hand side (Def. 4.2)
//     b̂ = b − AᵀX̄_min   m,   X̄_min = (I − L⁺L)·X_min,
// where X_min is the exact solution of Eq. 1. The companion problem
//     min_X̂ ½‖X̂‖² − q̂ᵀX̂  s.t.  ÂᵀX̂ = b̂                               (Eq. 27)
// has the solution X̂_min = L·X_min (Theorem 4.3, Prop. 4.4) and, when Â has
// full column rank,
//     X̂_min = (I − ÂÂ⁺)q̂ + (Â⁺)ᵀb̂.                                      (Eq. 30)
// Whitened subspace (Eq. 29, Prop. 4.7):  N̂ = (Ĉ⁺)ᵀ (r×d),  Û = I − ĈĈ⁺ (r×r),
// ÛD̂ = (I − ĈĈ⁺)D̂ (r×k). Prop. 4.5: for the engine's X* = N·Z + UD·Y,
//     L·X* = N̂·Ẑ + ÛD̂·Y,  Ẑ = Z − CᵀKKᵀX*,
// so L·N = N̂(I − CᵀKKᵀN) and L·UD = ÛD̂ − N̂·CᵀKKᵀUD (L·N = N̂, L·UD = ÛD̂ when
// H is PD). Î is the orthogonal projector onto Span(Ĉ) + Span(D̂) (r×r,
// Prop. 4.9; = ÛD̂(ÛD̂)⁺ + ĈĈ⁺), computed from an orthonormal basis. The
// companion problem restricted to that span has the solution
//     X̂*_min = (Î − Â_pÂ_p⁺)q̂ + (Â_p⁺)ᵀb̂,  Â_p = ÎÂ  (r×m).              (Eq. 35)
//
// ---- Theorem 4.10 (Eq. 39) -----------------------------------------------------
// With ρ = ‖I − Â⁺ÎÂ‖₂ < 1 and ω = cond(Â) = ‖Â‖₂‖Â⁺‖₂,
//     ‖X̂*_min − X̂_min‖ ≤ ‖Îq̂ − q̂‖ + Δ·‖ÎÂ − Â‖₂,
//     Δ = β₁‖b̂‖‖Â⁺‖² + β₂‖q̂‖‖Â⁺‖,  β₁ = (2 − ρ)/(1 − ρ),  β₂ = 1 + ω/(1 − ρ).
// ρ ≥ 1: the theorem makes no claim (TheoremStatus::DoesNotApply, bound = +inf).
// We also report an a-posteriori bound that needs only Â_p of full column
// rank (proof in docs/theorem.md; δ = ‖ÎÂ − Â‖₂):
//     ‖X̂*_min − X̂_min‖ ≤ ‖(I − Î)q̂‖ + min(1, δ·min(‖Â⁺‖, ‖Â_p⁺‖))·‖Îq̂‖ + δ‖Â_p⁺‖²‖b̂‖,
// which is ≤ the paper's bound whenever ρ < 1.
//
// ---- What is bounded ------------------------------------------------------------
// Eq. 40 turns the theorem into d_H(X*, X_min) ≤ bound for "the corresponding
// variational reduced solution". The theorem's reduced solution is Eq. 35:
// the companion problem with b̂ fixed, searched over all of Span(Ĉ) + Span(D̂).
// The engine's answer X* (SubspaceSolver) minimises Eq. 1 over Span([N UD]),
// null-space part included. For every feasible X (AᵀX = b),
//     f(X) − f(X_min) = ½·d_H(X, X_min)²,
// so X* is the d_H-best feasible point of Span([N UD]). The lift
// Y = L⁺X̂*_min + X̄_min of the theorem's solution is feasible with
// d_H(Y, X_min) = ‖X̂*_min − X̂_min‖, and Y ∈ Span([N UD]) whenever
// L·Span([N UD]) = Span(Ĉ) + Span(D̂), i.e. whenever
//     ker H ⊆ Span(C) + Span(D)        (always when H is PD)
// (ker H ⊆ Span(N) and dim L·Span([N UD]) = d + k − ν). Then
//     d_H(X*, X_min) ≤ ‖X̂*_min − X̂_min‖ ≤ bound,
// with equality in the first step when H is PD (L·X* = X̂*_min). When ker H
// is NOT inside the design spaces nothing bounds X*: a demand perturbed only
// along ker H leaves the bound at zero while d_H(X*, X_min) is O(ε)
// (docs/theorem.md, and the test "ker H outside the design"). TheoremCheck
// reports both errors, the flag WhitenedDesign::kernel_in_design(), and the
// gap ‖L·X* − X̂*_min‖.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/subspace_solver.h"

#include <limits>
#include <string>

namespace qpreduce {

struct QuotientOptions {
  // Eigenvalues λ ≤ rank_tolerance·max|λ| of H count as zero (ker H), and
  // λ < −rank_tolerance·max|λ| makes H indefinite. 1e-10 sits far above the
  // round-off of a dense eigensolver (≈ n·1e-16) and far below the smallest
  // nonzero eigenvalue of the generated families (≥ 1e-6·λ_max).
  double rank_tolerance = 1e-10;
  // H is rejected (std::invalid_argument) when ‖H − Hᵀ‖_F > symmetry_tolerance·‖H‖_F.
  double symmetry_tolerance = 1e-10;
  // Column spaces of [Ĉ D̂], Ĉ, Â and Â_p: singular values below
  // basis_tolerance·σ_max count as zero (rank-revealing QR/SVD threshold).
  double basis_tolerance = 1e-10;
  // The exact solve factors the dense KKT matrix [[H, A], [Aᵀ, 0]]; an
  // estimated reciprocal condition number below this means A is rank
  // deficient or H is not PD on ker Aᵀ (TheoremStatus::SolveFailed).
  double kkt_rcond_tolerance = 1e-14;
  // A bound counts as violated only when error > bound + slack with
  // slack = roundoff_factor·n·ε_mach·(‖X̂_min‖ + √λ_max·‖X_min‖): the error of
  // two independent solves (dense KKT and the engine) at working precision.
  double roundoff_factor = 100.0;
  // OpenMP threads for this analysis (Eigen's dense products and the engine
  // calls it makes); 0 means omp_get_max_threads(). The matrices here are a
  // few hundred wide at most, where waking threads costs more than it saves:
  // on a loaded 2-core machine the 2,040-trial test took 17 s with the
  // default team and 0.9 s with one thread.
  int threads = 1;
  // Options of the engine's reduced solve (the "practical" answer X*).
  SubspaceOptions subspace;
  ConstraintOptions constraints;

  bool is_valid(std::string* why) const;
};

// ---- H = LᵀL -------------------------------------------------------------------

struct PsdFactor {
  Matrix<double> L;            // r × n,  Λ_r^{1/2}·V_rᵀ
  Matrix<double> L_pinv;       // n × r,  V_r·Λ_r^{−1/2}
  Matrix<double> kernel;       // n × ν,  orthonormal basis K of ker H
  Vector<double> eigenvalues;  // n, ascending (all of them, before truncation)

  Index n() const { return L.cols(); }
  Index rank() const { return L.rows(); }
  Index nullity() const { return kernel.cols(); }
  // (L⁺)ᵀ·M: r × M.cols(). M must have n rows (asserted).
  Matrix<double> whiten(const Matrix<double>& M) const;
  // X̄ = (I − L⁺L)·X = K·KᵀX, the component of X in ker H.
  Vector<double> null_part(const Vector<double>& X) const;
  // d_H(x, y) = ‖L(x − y)‖.
  double distance(const Vector<double>& x, const Vector<double>& y) const;
};

struct FactorSummary : Outcome {  // status: Success or IndefiniteH
  Index n = 0, rank = 0, nullity = 0;
  double lambda_max = 0.0;       // largest eigenvalue
  double lambda_min = 0.0;       // smallest eigenvalue (may be a tiny negative)
  double lambda_min_kept = 0.0;  // smallest eigenvalue kept in L (0 when r = 0)
  double residual = -1.0;        // ‖H − LᵀL‖_F / ‖H‖_F
  double seconds = 0.0;
};

// Rank-revealing factor of a symmetric PSD H. Throws std::invalid_argument on
// a non-square H, NaN/Inf entries, asymmetry, or invalid options. An
// indefinite H comes back as Status::IndefiniteH (message names the most
// negative eigenvalue) and `out` is left empty.
FactorSummary factor_psd(const Matrix<double>& H, const QuotientOptions& options, PsdFactor* out);
FactorSummary factor_psd(const SparseMatrix<double>& H, const QuotientOptions& options, PsdFactor* out);

// d_H(x, y) = sqrt(max(0, (x − y)ᵀH(x − y))) without a factor. Throws on size mismatch.
double h_distance(const SparseMatrix<double>& H, const Vector<double>& x, const Vector<double>& y);

// ---- Whitened design and demand ----------------------------------------------

struct WhitenedDesign {
  Matrix<double> C_hat;   // r × d,  Ĉ = (L⁺)ᵀC
  Matrix<double> D_hat;   // r × k,  D̂ = (L⁺)ᵀD
  Matrix<double> basis;   // r × s,  orthonormal basis of Span(Ĉ) + Span(D̂)
  Matrix<double> I_hat;   // r × r,  Î = basis·basisᵀ
  Matrix<double> U_hat;   // r × r,  Û = I − ĈĈ⁺
  Matrix<double> N_hat;   // r × d,  N̂ = (Ĉ⁺)ᵀ (Prop. 4.7; pseudo-inverse if Ĉ is rank deficient)
  Matrix<double> UD_hat;  // r × k,  ÛD̂
  Index rank_C_hat = 0;   // rank of Ĉ (< d iff Span(C) meets ker H)
  Index rank = 0;         // s = dim(Span(Ĉ) + Span(D̂))
  // ‖(I − P)K‖₂, P the orthogonal projector onto Span(C) + Span(D), K a basis
  // of ker H: the sine of the largest angle between ker H and the design
  // spaces (0 when H is PD).
  double kernel_angle = 0.0;
  // ker H ⊆ Span(C) + Span(D): the engine's answer is then covered by the
  // bound ("What is bounded" above).
  bool kernel_in_design(double tolerance = 1e-8) const { return kernel_angle <= tolerance; }
  // The paper's assumption "columns of Ĉ and D̂ linearly independent".
  bool independent() const { return rank == C_hat.cols() + D_hat.cols(); }
};

// Throws std::invalid_argument when C or D does not have n rows or holds NaN.
WhitenedDesign whiten_design(const PsdFactor& factor, const Matrix<double>& C, const Matrix<double>& D,
                             const QuotientOptions& options = {});

struct CompanionDemand {
  Matrix<double> A_hat;  // r × m,  Â = (L⁺)ᵀA
  Vector<double> q_hat;  // r,      q̂ = (L⁺)ᵀq
  Vector<double> b_hat;  // m,      b̂ = b − AᵀX̄_min
  Vector<double> X_bar;  // n,      X̄_min = (I − L⁺L)·X_min
};

// X_min: the exact solution of Eq. 1 for (A, b, q). Throws on size mismatch or NaN.
CompanionDemand companion_demand(const PsdFactor& factor, const Matrix<double>& A, const Vector<double>& b,
                                 const Vector<double>& q, const Vector<double>& X_min);

// Eq. 30. Returns false (X_hat untouched) when Â lacks full column rank.
bool companion_solution(const CompanionDemand& demand, Vector<double>* X_hat,
                        const QuotientOptions& options = {});
// Eq. 35. Returns false (X_hat untouched) when Â_p = ÎÂ lacks full column rank.
bool subspace_companion_solution(const WhitenedDesign& design, const CompanionDemand& demand,
                                 Vector<double>* X_hat, const QuotientOptions& options = {});

// ---- Theorem 4.10 ----------------------------------------------------------------

enum class TheoremStatus {
  NotRun,
  Applies,         // ρ < 1 and Â has full column rank: `bound` is finite
  DoesNotApply,    // ρ = ‖I − Â⁺ÎÂ‖₂ ≥ 1: the theorem makes no claim, bound = +inf
  RankDeficientA,  // Â = (L⁺)ᵀA lacks full column rank: Eq. 30 is not defined
  IndefiniteH,     // H is not PSD
  SolveFailed,     // the exact KKT solve or the engine's reduced solve failed
};
const char* to_string(TheoremStatus status);

struct TheoremBound {
  TheoremStatus status = TheoremStatus::NotRun;
  std::string message;
  Index r = 0, m = 0;
  double q_residual = 0.0;      // ‖Îq̂ − q̂‖
  double A_residual = 0.0;      // δ = ‖ÎÂ − Â‖₂
  double rho = 0.0;             // ρ = ‖I − Â⁺ÎÂ‖₂
  double omega = 0.0;           // ω = cond(Â) = ‖Â‖₂‖Â⁺‖₂
  double beta1 = 0.0, beta2 = 0.0;  // (2 − ρ)/(1 − ρ), 1 + ω/(1 − ρ); +inf when ρ ≥ 1
  double Delta = 0.0;           // Δ = β₁‖b̂‖‖Â⁺‖² + β₂‖q̂‖‖Â⁺‖
  double norm_q_hat = 0.0, norm_b_hat = 0.0;
  double norm_A_hat = 0.0;      // ‖Â‖₂
  double norm_A_pinv = 0.0;     // ‖Â⁺‖₂ = 1/σ_min(Â)
  double norm_Ap_pinv = std::numeric_limits<double>::infinity();  // ‖Â_p⁺‖₂
  double bound = std::numeric_limits<double>::infinity();          // Eq. 39
  double refined_bound = std::numeric_limits<double>::infinity();  // a posteriori (above)

  bool applies() const { return status == TheoremStatus::Applies; }
};

// All terms of Eq. 39 for one demand. Never NaN: a failed hypothesis gives a
// status, +inf bounds and a message.
TheoremBound theorem_bound(const WhitenedDesign& design, const CompanionDemand& demand,
                           const QuotientOptions& options = {});

// ---- One demand, end to end -----------------------------------------------------

struct TheoremCheck {
  TheoremStatus status = TheoremStatus::NotRun;
  std::string message;
  TheoremBound bound;
  double exact_norm = 0.0;          // ‖X̂_min‖ = ‖L·X_min‖
  double exact_kkt_residual = -1.0; // ‖K·[X; Λ] − rhs‖ / (‖K‖_F‖[X; Λ]‖ + ‖rhs‖), dense KKT
  double practical_error = -1.0;    // d_H(X*, X_min), X* from the engine (SubspaceSolver)
  double practical_rel_error = -1.0;// ‖X* − X_min‖ / ‖X_min‖ (the full vectors, ker H included)
  double theorem_error = -1.0;      // ‖X̂*_min − X̂_min‖ (Eq. 35 vs Eq. 30); −1 if Eq. 35 undefined
  double practical_gap = -1.0;      // ‖L·X* − X̂*_min‖ (round-off when H is PD)
  double closed_form_gap = -1.0;    // ‖X̂_min(Eq. 30) − L·X_min‖ (Theorem 4.3 consistency)
  bool practical_covered = false;   // ker H ⊆ Span(C) + Span(D): d_H(X*, X_min) ≤ theorem_error
  double slack = 0.0;               // round-off allowance (QuotientOptions::roundoff_factor)
  double seconds = 0.0;

  // Violations beyond round-off; false when the theorem does not apply.
  bool practical_violation() const;
  bool theorem_violation() const;
  // η = bound / practical_error (+inf when the error is 0).
  double eta() const;
};

// Optional outputs of TheoremChecker::check.
struct TheoremSolutions {
  Vector<double> X_min;       // n, exact (dense KKT)
  Vector<double> X_star;      // n, engine's reduced answer
  Vector<double> X_hat_min;   // r, Eq. 30
  Vector<double> X_hat_star;  // r, Eq. 35 (empty when undefined)
  CompanionDemand demand;
};

struct TheoremSetupSummary : Outcome {
  FactorSummary factor;
  SubspaceSummary subspace;
  Index design_rank = 0;  // dim(Span(Ĉ) + Span(D̂))
  double seconds = 0.0;
};

// Precompute once per (H, C, D), then check many demands.
class TheoremChecker {
 public:
  // Factors H = LᵀL, whitens the design (Ĉ, D̂, Î) and precomputes the
  // engine's SubspaceSolver on (H, C, D). Throws std::invalid_argument on bad
  // sizes/NaN/asymmetry/invalid options; numerical failures come back in the
  // summary and leave the checker unusable.
  TheoremSetupSummary precompute(const SparseMatrix<double>& H, const SparseMatrix<double>& C,
                                 const SparseMatrix<double>& D, const QuotientOptions& options = {});

  // Exact solve, engine solve, companion problem, Theorem 4.10 terms and the
  // errors for one demand (A n×m, b m, q n). Throws std::invalid_argument on
  // bad sizes/NaN, or before a successful precompute.
  TheoremCheck check(const SparseMatrix<double>& A, const Vector<double>& b, const Vector<double>& q,
                     TheoremSolutions* solutions = nullptr);

  bool ready() const { return ready_; }
  const PsdFactor& factor() const { return factor_; }
  const WhitenedDesign& design() const { return design_; }
  const SubspaceSolver<double>& solver() const { return solver_; }
  const QuotientOptions& options() const { return options_; }

 private:
  QuotientOptions options_;
  Matrix<double> H_;  // dense copy of H (n×n) for the KKT solve
  PsdFactor factor_;
  WhitenedDesign design_;
  SubspaceSolver<double> solver_;
  bool ready_ = false;
};

// One-off: precompute + check. Setup failures come back as IndefiniteH or
// SolveFailed with the setup's message.
TheoremCheck check_theorem(const SparseMatrix<double>& H, const SparseMatrix<double>& C,
                           const SparseMatrix<double>& D, const SparseMatrix<double>& A,
                           const Vector<double>& b, const Vector<double>& q,
                           const QuotientOptions& options = {}, TheoremSolutions* solutions = nullptr);

}  // namespace qpreduce
