// qpreduce — quotient equivalence (Ye & Yan, Section 4): the factor H = LᵀL,
// the distance d_H (Eq. 20–21), the whitened design and demand (Eq. 25–29)
// and the closed forms of the companion problem (Eq. 30 and 35).
//
// Dense analysis in double precision for problems up to a few hundred
// unknowns (one n×n eigendecomposition); a check on the engine, not on any
// per-frame path. The error bound of Theorem 4.10 is in theorem.h.
// Notation and derivations: docs/theorem.md.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/subspace_solver.h"

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
  // few hundred wide at most, where waking threads costs more than it saves.
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

 protected:
  void add_details(Report* out) const override;
};

// Rank-revealing factor of a symmetric PSD H. Throws std::invalid_argument on
// an empty (0 × 0) or non-square H, NaN/Inf entries, asymmetry, or invalid options. An
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
  // bound (theorem.h, docs/theorem.md).
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

}  // namespace qpreduce
