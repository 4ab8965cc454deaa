#include "factored_operators.h"

#include "range_space.h"

#include <Eigen/Cholesky>

#include <algorithm>
#include <cmath>

namespace qpreduce::detail {

namespace {

using MatD = Matrix<double>;
using SpMatD = Eigen::SparseMatrix<double>;

// M·A_rᵀ (rows × m) for dense M (rows × p) and At = A_rᵀ (p × m): one column
// axpy per nonzero of A_r.
MatD times_sparse(const MatD& M, const SpMatD& At) {
  MatD out = MatD::Zero(M.rows(), At.cols());
  for (Index j = 0; j < At.outerSize(); ++j)
    for (SpMatD::InnerIterator it(At, j); it; ++it) out.col(j).noalias() += it.value() * M.col(it.index());
  return out;
}

MatD symmetric_part(const MatD& S) { return 0.5 * (S + S.transpose()); }

// A_r·T·A_rᵀ (m × m) for symmetric T (p × p). From T's entries at pairs of
// A_r's nonzeros (nnz² terms; m² for a selection) when that is fewer than the
// nnz·(p + m) of T·A_rᵀ and A_r·(T·A_rᵀ), otherwise through those.
MatD sandwich(const MatD& T, const SpMatD& At) {
  const Index m = At.cols(), nnz = At.nonZeros();
  if (nnz > T.rows() + m) return symmetric_part(At.transpose() * times_sparse(T, At));
  MatD K(m, m);
  for (Index b = 0; b < m; ++b)
    for (Index a = b; a < m; ++a) {
      double sum = 0.0;
      for (SpMatD::InnerIterator ib(At, b); ib; ++ib)
        for (SpMatD::InnerIterator ia(At, a); ia; ++ia) sum += ia.value() * T(ia.index(), ib.index()) * ib.value();
      K(a, b) = K(b, a) = sum;
    }
  return K;
}

}  // namespace

bool factored_operators(const RangeSpace& rs, const MatD& P0, const MatD& lift_btd, const SpMatD& At, bool soft,
                        double delta, double rank_tolerance, double abar_squared_norm, FactoredOperators* out) {
  const Index p = At.rows(), m = At.cols(), nu = rs.lift_cols.cols(), q = m + nu, k = P0.cols();
  const double sigma = rs.hbar_max;
  MatD& Y = out->Y;
  Y.resize(p, q);
  Y.leftCols(m) = times_sparse(rs.Minv0, At);
  Y.rightCols(nu) = rs.lift_cols;

  // Σ's blocks: Σ₁₁ = A_r·M0·A_rᵀ + c·I (m × m; positive definite for hard
  // constraints of full row rank and for soft ones), Σ₁₂ = A_r·L (m × ν),
  // Σ₂₂ = diag(β) (β ≤ 0); Σ⁻¹ by block elimination (bordered_inverse).
  MatD S11 = sandwich(rs.Minv0, At);
  if (soft) S11.diagonal().array() += 1.0 / (2.0 * delta);
  const MatD S12 = At.transpose() * rs.lift_cols;
  MatD& Sinv = out->Sinv;
  if (!bordered_inverse(S11, S12, rs.lift_block, &Sinv)) return false;

  // The acceptance test of the explicit path on ‖M̄_q‖_F, from
  //     ‖M̄_q‖_F² = ‖H̃⁻¹‖_F² − 2·tr(Σ⁻¹K₃) + tr(Σ⁻¹K₂Σ⁻¹K₂),
  //     K_j = [[A_r·T_j·A_rᵀ, σ^(1−j)·Σ₁₂], [·, σ^(−j)·I_ν]].
  MatD K2(q, q), K3(q, q);
  K2.topLeftCorner(m, m) = sandwich(rs.T2, At);
  K3.topLeftCorner(m, m) = sandwich(rs.T3, At);
  if (nu > 0) {
    K2.topRightCorner(m, nu) = S12 / sigma;
    K3.topRightCorner(m, nu) = S12 / (sigma * sigma);
    K2.bottomLeftCorner(nu, m) = K2.topRightCorner(m, nu).transpose();
    K3.bottomLeftCorner(nu, m) = K3.topRightCorner(m, nu).transpose();
    K2.bottomRightCorner(nu, nu) = MatD::Identity(nu, nu) / (sigma * sigma);
    K3.bottomRightCorner(nu, nu) = MatD::Identity(nu, nu) / (sigma * sigma * sigma);
  }
  const double tr3 = Sinv.cwiseProduct(K3).sum();  // tr(Σ⁻¹K₃): both symmetric
  const MatD X = Sinv * K2;
  const double tr22 = X.cwiseProduct(X.transpose()).sum();  // tr((Σ⁻¹K₂)²)
  const double norm2 = rs.inv_fro2 - 2.0 * tr3 + tr22;
  if (!std::isfinite(norm2)) return false;
  // Round-off can take a tiny norm below zero; the test is about large ones.
  const double lambda_up = sigma + (soft ? 2.0 * delta * abar_squared_norm : 0.0);
  const double cond_bound = lambda_up * std::sqrt(std::max(norm2, 0.0));
  if (!std::isfinite(cond_bound) || !(cond_bound * rank_tolerance < 1.0)) return false;

  // Φ = Σ⁻¹·YᵀBᵀD with YᵀBᵀD = [A_r·P0; LᵀBᵀD] (M0 symmetric).
  MatD Psi(q, k);
  if (k > 0) {  // no blocks of an empty matrix: its data pointer is null
    Psi.topRows(m) = At.transpose() * P0;
    Psi.bottomRows(nu) = lift_btd;
  }
  out->PhiNeg.resize(q, k);
  out->PhiNeg.noalias() = -(Sinv * Psi);
  return Y.allFinite() && out->PhiNeg.allFinite();
}

}  // namespace qpreduce::detail
