// qpreduce — the linear variational subspace (Ye & Yan, Section 2, Eq. 4–5).
//
// Problem family (Eq. 1):  min_X ½ XᵀHX − qᵀX   s.t.  AᵀX = b,
// with H (n×n) sparse symmetric positive semi-definite and fixed, and demands
// (A n×m, b m×1, q n×1) that change on site. The designer picks
//   C (n×d): the space constraint columns are expected in, A ≈ C·A_c,
//   D (n×k): the space linear terms are expected in,     q ≈ D·Y.
// The first-stage problem  min ½XᵀHX − YᵀDᵀX  s.t. CᵀX = Z  has the KKT system
//
//     [ H   C ] [X]   [D·Y]
//     [ Cᵀ  0 ] [Λ] = [ Z ]                                         (Eq. 4)
//
// whose solution is affine in the on-site parameters:
//
//     X*(Z, Y) = N·Z + UD·Y,   N: n×d,  UD: n×k.                     (Eq. 5)
//
// The KKT matrix is nonsingular iff C has full column rank and H is positive
// definite on ker(Cᵀ). Then, for any ρ > 0 and any column selection P (d×p)
// such that H_ρ = H + ρ·(CP)(CP)ᵀ is positive definite, adding
// ρ·CP·((CP)ᵀX − PᵀZ) = 0 to the first row gives, with μ = ρPPᵀZ − Λ,
//     X = F·Y + G·μ,  G = H_ρ⁻¹C (n×d),  F = H_ρ⁻¹D (n×k),  S = CᵀG (d×d, SPD),
//     N  = G·S⁻¹,
//     UD = F − G·S⁻¹·(CᵀF).
// So ONE sparse Cholesky of H_ρ and d + k solves give the subspace. When the
// augmentation would fill in too much (C with long columns) or the caller asks
// for it, the KKT matrix itself is factored with SparseLU instead.
//
// Checks reported in the summary:
//   * S is SPD iff C has full column rank            → Status::RankDeficientC;
//   * (UD)ᵀH(UD) = Dᵀ·UD is SPD iff no combination of D's columns lies in
//     Span(C)                                        → Status::DependentCD;
//   * H_ρ not positive definite                      → Status::SingularKKT;
//   * optional PSD check of H (a certificate from S, or LDLᵀ inertia of H + τI)
//                                                    → Status::IndefiniteH;
//   * the relative KKT residual of the result.
#pragma once

#include "qpreduce/common.h"
#include "qpreduce/factorization.h"

#include <string>
#include <vector>

namespace qpreduce {

struct SubspaceOptions {
  // Factorization backend. Auto: CHOLMOD on H_ρ, or SparseLU on the KKT matrix
  // when the augmentation fill exceeds max_augmentation_fill.
  Backend backend = Backend::Auto;
  // ρ = rho_scale · mean(diag H) / mean(‖c_j‖²) over the augmenting columns:
  // the augmentation then has the scale of H, so H_ρ is no worse conditioned
  // than the KKT matrix.
  double rho_scale = 1.0;
  // Columns of C used for the augmentation (indices into 0..d−1). Empty: all
  // of them. One column per connected component of H's null space suffices;
  // pick short columns to limit fill.
  std::vector<Index> augment_columns;
  // false: no augmentation, factor H itself (ρ = 0; G = H⁻¹C, F = H⁻¹D).
  // Requires H positive definite (else Status::SingularKKT); avoids the fill
  // of long columns of C (group sums, factor loadings) without the SparseLU
  // route. augment_columns and max_augmentation_fill are then ignored.
  bool augment = true;
  // Auto backend: when Σ_j nnz(c_j)² over the augmenting columns exceeds this
  // multiple of nnz(H), factor the KKT matrix with SparseLU instead.
  double max_augmentation_fill = 4.0;
  // Optional: a group id in [0, g) for each of the n unknowns, e.g. the
  // vertex of each coordinate of a mesh. CHOLMOD then computes its
  // fill-reducing ordering on the g-node quotient graph, with each group's
  // unknowns kept together (SparseFactorization::setOrderingGroups), several
  // times faster on mesh Hessians (docs/engine.md). Empty: order the
  // unknowns themselves.
  std::vector<Index> ordering_groups;
  // Right-hand sides solved per block. Blocks are solved concurrently, one per
  // OpenMP thread (omp_get_max_threads(); set OMP_NUM_THREADS to change it),
  // each a BLAS-3 supernodal solve for CHOLMOD.
  Index block_size = 64;
  // H is rejected as asymmetric when ‖H − Hᵀ‖_F > symmetry_tolerance·‖H‖_F.
  double symmetry_tolerance = 1e-10;
  // Check that H is PSD, i.e. that H + τI with τ = psd_shift·max|H_ii| is
  // positive definite. On the augmented route this comes almost free: with
  // T = ρ·CᵀH_ρ⁻¹C over the augmenting columns (a block of ρS), H ⪰ 0 iff
  // λ_max(T) ≤ 1, and λ_max(T) ≤ 1 + τ/λ̄ (λ̄ a Gershgorin bound on λ_max(H_ρ))
  // certifies H + τI ⪰ 0. Only when that certificate fails, on the KKT route,
  // or when a factorization of H_ρ fails, is H + τI factored (LDLᵀ inertia or
  // CHOLMOD LLᵀ), which costs about one more factorization of H.
  bool check_psd = true;
  double psd_shift = 1e-8;
  // Always run the factorization check instead of the certificate (the
  // behaviour before the certificate; kept for comparison and benchmarks).
  bool psd_check_by_factorization = false;
  // S and Dᵀ·UD count as singular when λ_min < rank_tolerance·λ_max.
  double rank_tolerance = 1e-12;
  // After factoring, one solve with a known answer checks the factor: a
  // relative error above this means the KKT matrix is singular to working
  // precision (Status::SingularKKT).
  double max_probe_error = 1e-6;
  // Set to false to skip the KKT residual (saves one product with H).
  bool compute_residual = true;
  // SubspaceSolver::precompute: eigen-directions of the scaled reduced Hessian
  // H̄ with λ ≤ reduced_lift_tolerance·λ_max are lifted to λ_max for the
  // set_constraints fast path (subspace_solver.h). Exact for any value; it
  // bounds cond(H̃) by 1/reduced_lift_tolerance, which is what the fast path's
  // rounding error grows with, while each lifted direction adds one row to the
  // per-demand Schur complement.
  double reduced_lift_tolerance = 1e-8;
  // SubspaceSolver: prepare set_constraints' fast path (the eigen-
  // decomposition of the scaled H_r, O(p³)) at precompute and restore. false
  // leaves it to the first set_constraints, for a caller that only reads the
  // reduced operators (the deformer, whose Phase 1 has its own fast path).
  bool prepare_constraint_path = true;
  // Report Status::DependentCD when a combination of D's columns lies in
  // Span(C). Off for callers that use D as a plain right-hand side (the
  // full-space solve, where q ∈ Span(A) is legitimate).
  bool check_dependent_cd = true;

  bool is_valid(std::string* why) const;
};

struct SubspaceSummary : Outcome {
  Backend backend_used = Backend::Auto;
  Index n = 0, d = 0, k = 0;
  double rho = 0.0;                // augmentation weight (0 on the KKT route)
  Index factor_nonzeros = 0;
  // max of ‖(I − P_C)(H·[N UD] − [0 D])‖_F / (‖H‖_F‖[N UD]‖_F + ‖D‖_F) and
  // ‖Cᵀ[N UD] − [I 0]‖_F / √d, where P_C is the orthogonal projector onto Span(C).
  double kkt_residual = -1.0;
  double probe_error = -1.0;       // relative error of the known-answer solve
  double s_condition = 0.0;        // λ_max/λ_min of S (or of CᵀN⁻¹ on the KKT route)
  double ud_condition = 0.0;       // λ_max/λ_min of Dᵀ·UD (0 when k = 0)
  double check_psd_seconds = 0.0, factorize_seconds = 0.0, solve_seconds = 0.0,
         total_seconds = 0.0;
  std::string brief_report() const override;  // one-line human summary

 protected:
  void add_details(Report* out) const override;
};

// The subspace X = N·Z + UD·Y. Columns are in the order of C's and D's columns.
template <typename Scalar>
struct VariationalSubspace {
  Matrix<Scalar> N;   // n × d
  Matrix<Scalar> UD;  // n × k
};

// Builds N and UD from one factorization. Throws std::invalid_argument on
// wrong sizes, NaN/Inf entries, an asymmetric H, d = 0, or invalid options.
// Numerical failures come back as a status with a message; `out` is then
// left empty (never NaN).
template <typename Scalar>
SubspaceSummary build_subspace(const SparseMatrix<Scalar>& H, const SparseMatrix<Scalar>& C,
                               const SparseMatrix<Scalar>& D, const SubspaceOptions& options,
                               VariationalSubspace<Scalar>* out);

}  // namespace qpreduce
