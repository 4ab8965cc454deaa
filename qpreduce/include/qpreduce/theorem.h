// qpreduce — the error bound of Theorem 4.10 (Ye & Yan, Eq. 39) and a checker
// that compares it with the engine's reduced answer.
//
// With ρ = ‖I − Â⁺ÎÂ‖₂ < 1, ω = cond(Â) and δ = ‖ÎÂ − Â‖₂ (whitened data of
// quotient.h):
//     ‖X̂*_min − X̂_min‖ ≤ ‖Îq̂ − q̂‖ + Δ·δ,
//     Δ = β₁‖b̂‖‖Â⁺‖² + β₂‖q̂‖‖Â⁺‖,  β₁ = (2 − ρ)/(1 − ρ),  β₂ = 1 + ω/(1 − ρ).
// An a-posteriori bound that needs only Â_p = ÎÂ of full column rank is
// reported too (refined_bound). The engine's answer X* is covered by the
// bound (d_H(X*, X_min) ≤ ‖X̂*_min − X̂_min‖, Eq. 40) when ker H ⊆
// Span(C) + Span(D). Proofs and the precise scope: docs/theorem.md.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/quotient.h"
#include "qpreduce/subspace_solver.h"

#include <limits>
#include <string>

namespace qpreduce {

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

 protected:
  void add_details(Report* out) const override;
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
  // Steps of check(); each returns an empty string or the failure message.
  std::string exact_solve(const Matrix<double>& A, const Vector<double>& b, const Vector<double>& q,
                          Vector<double>* X_min, double* kkt_residual) const;
  std::string engine_solve(const SparseMatrix<double>& A, const Vector<double>& b, const Vector<double>& q,
                           Vector<double>* X_star);

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
