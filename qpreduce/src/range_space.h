// Private to the engine: the range-space ("fast path") operators of the small
// equality-constrained QP
//
//     min_w ½wᵀH w − gᵀw   s.t.  A w = c          (hard, Eq. 17 form)
//     min_w ½wᵀH w − gᵀw + δ‖A w − c‖²            (soft, Eq. 18 form)
//     H: p×p symmetric PSD, A: m×p,   w = M_c·c + M_g·g,
//
// shared by SubspaceSolver (H = H_r, w = [z; y]) and FixedCoordinateSolver
// (H = H_zz, w = z). src/qp_operators.h is the null-space method for the
// same operators; this is the O(p²·(m+ν)) alternative once H̃⁻¹ is known.
//
// Once per H (`prepare_range_space`, O(p³)): in energy-normalised
// coordinates w = D_s·w̄, D_s = diag(H)^(−1/2), H̄ = D_sHD_s = VΛVᵀ; the
// near-null directions V_L (λ_i ≤ lift_tolerance·λ_max, ν of them) are lifted
// to σ = λ_max: H̃ = H̄ + V_L(σ − Λ_L)V_Lᵀ is SPD, and
//     M0 = D_s·H̃⁻¹·D_s                   (p × p)
//     L  = D_s·V_L/σ                     (p × ν)
//     β  = −λ_L/(σ(σ − λ_L))             (ν;  = 1/σ − 1/(σ − λ_L))
// are kept.
//
// Per demand (`range_space_operators`): with Y' = [M0·Aᵀ, L] (p × q,
// q = m + ν) the bordered Schur complement is
//     Σ = [[A·M0·Aᵀ + c·I_m, A·L], [Lᵀ·Aᵀ, diag(β)]]   (q × q),
//     c = 0 (hard) or 1/(2δ) (soft),
// and, with T = Y'·Σ⁻¹ (p × q),
//     M_g = M0 − T·Y'ᵀ,      M_c = T's first m columns,
// so M_g·G = M0·G − T·(Y'ᵀG) for any G (p × k). The same solve gives the
// constraints' multipliers λ (H·w + Aᵀλ = g; soft: λ = 2δ·(A·w − c)):
//     w = M0·g − Y'·s,   s = Σ⁻¹·(Y'ᵀg − [c; 0]),   λ = s's first m entries,
// i.e. λ = K·(Y'ᵀg − [c; 0]) with K the first m rows of Σ⁻¹ (m × q). The answer is accepted only
// when λ_max(H̄)·‖D_s⁻¹M_gD_s⁻¹‖_F < 1/rank_tolerance (the condition bound
// the null-space method tests) and, for hard constraints, when Ā = A·D_s has
// full row rank m; anything else goes to the null-space method, which decides
// the status. Both give the same unique minimiser when it exists.
//
// Σ is inverted through its blocks (bordered_inverse), not an
// eigendecomposition (a q × q eigensolver was most of a demand's cost at
// q ≈ 30): Σ₁₁ = A·M0·Aᵀ + c·I = L₁L₁ᵀ is positive definite whenever the
// fast path applies (full-rank hard or soft constraints), and
// N = Σ₁₂ᵀΣ₁₁⁻¹Σ₁₂ − diag(β) (ν × ν), the negated Schur complement of Σ₁₁, is
// positive semidefinite (β ≤ 0), definite exactly when A pins every lifted
// direction; N = L₂L₂ᵀ, and with E = Σ₁₁⁻¹Σ₁₂
//     Σ⁻¹ = [[Σ₁₁⁻¹ − E·N⁻¹·Eᵀ, E·N⁻¹], [N⁻¹·Eᵀ, −N⁻¹]].
// A failed Cholesky factor sends the demand to the null-space method.
//
// The rank test (a column-pivoted QR of Āᵀ, p×m) runs on Ā's nonzero columns
// only: the other rows of Āᵀ are zero and change neither R nor the rank; for
// a scaled selection (one nonzero per row of Ā, in distinct columns) R is
// diagonal and rank and condition are read off Ā's nonzeros, without a QR.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/constraints.h"

namespace qpreduce::detail {

struct RangeSpace {
  Eigen::VectorXd scale;       // diagonal of D_s (p)
  Eigen::VectorXd inv_scale;   // its inverse (p)
  double hbar_max = 0.0;       // λ_max(H̄) = σ
  Matrix<double> Minv0;        // M0 = D_s·H̃⁻¹·D_s (p × p, symmetric)
  Matrix<double> lift_cols;    // L = D_s·V_L/σ (p × ν)
  Eigen::VectorXd lift_block;  // β (ν)
  // Only with factored_terms (SubspaceSolver's factored fast path,
  // src/factored_operators.h); empty and 0 otherwise.
  Matrix<double> T2;           // D_s·H̃⁻²·D_s (p × p, symmetric)
  Matrix<double> T3;           // D_s·H̃⁻³·D_s (p × p, symmetric)
  double inv_fro2 = 0.0;       // ‖H̃⁻¹‖_F²
  Index p() const { return Minv0.rows(); }
};

// H: p×p symmetric (PSD up to round-off), finite. O(p³); factored_terms adds
// T₂, T₃ and ‖H̃⁻¹‖_F² (two more p³ products).
RangeSpace prepare_range_space(const Matrix<double>& H, double lift_tolerance, bool factored_terms = false);

// The fast path's rank test for the constraints A (m × p, unscaled, finite):
// sets summary->m, rank and (hard) condition, status Success and message.
// false: hard constraints without full row rank (the fast path is not taken).
bool range_space_rank(const RangeSpace& rs, const Matrix<double>& A, const ConstraintOptions& options,
                      ConstraintSummary* summary);

// rank(Ā) with Eigen's default threshold for an m × p matrix (soft
// constraints' summary), from Ā's nonzero columns only.
Index default_rank(const Matrix<double>& Abar);

// Σ⁻¹ (q × q, symmetric) from Σ₁₁ (m × m, with c·I added), Σ₁₂ = A·L (m × ν)
// and β = lift_block (ν), by the block elimination above. false when Σ₁₁ or
// N is not positive definite or an entry is not finite.
bool bordered_inverse(const Matrix<double>& S11, const Matrix<double>& S12, const Eigen::VectorXd& lift_block,
                      Matrix<double>* Sinv);

struct RangeSpaceOperators {
  Matrix<double> Y;     // Y' = [M0·Aᵀ, L] (p × q)
  Matrix<double> Sinv;  // Σ⁻¹ (q × q, symmetric)
  Matrix<double> T;     // Y'·Σ⁻¹ (p × q); its first m columns are M_c
  Matrix<double> Mg;  // lower triangle of M_g (p × p); the strict upper triangle is M0's
};

// The fast path for the constraints A (m × p, unscaled, finite) under
// `options` (soft, delta, rank_tolerance; the BLAS threads are the caller's):
// range_space_rank, then the bordered operators (not taken for soft
// constraints with more rows than columns, m > p: the null-space method is
// then cheaper). true: *out holds the operators and *summary its status (Success), message,
// rank and condition (summary->m is set either way). false: not taken; the
// caller runs the null-space method (and overwrites the summary).
bool range_space_operators(const RangeSpace& rs, const Matrix<double>& A, const ConstraintOptions& options,
                           ConstraintSummary* summary, RangeSpaceOperators* out);

}  // namespace qpreduce::detail
