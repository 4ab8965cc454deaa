#include "qp_operators.h"

#include "blas.h"

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <fmt/format.h>

#include <cmath>

namespace qpreduce::detail {

namespace {

using MatD = Matrix<double>;

// Inverse of a symmetric PSD matrix K (pseudo-inverse on its numerical range
// when singular); flags a singular K and estimates λ_max/λ_min. The common
// case, K clearly positive definite, costs one Cholesky (p³/3); only when the
// Cholesky pivots say K is near singular does it fall back to an
// eigendecomposition (≈ 9p³), whose spectrum decides.
MatD symmetric_pinv(const MatD& K, double tolerance, bool* singular, double* condition) {
  *singular = false;
  *condition = 1.0;
  if (K.rows() == 0) return MatD(0, 0);
  const MatD Ks = 0.5 * (K + K.transpose());
  const Eigen::LLT<MatD> llt(Ks);
  if (llt.info() == Eigen::Success) {
    const Eigen::VectorXd piv = llt.matrixLLT().diagonal().cwiseAbs2();
    const double est = piv.maxCoeff() / piv.minCoeff();  // a lower bound of cond(K), cheap
    if (std::isfinite(est) && est * tolerance < 1e-2) {
      *condition = est;
      return llt.solve(MatD::Identity(K.rows(), K.cols()));
    }
  }
  const Eigen::SelfAdjointEigenSolver<MatD> es(Ks);
  const Eigen::VectorXd& lambda = es.eigenvalues();
  const double top = lambda.cwiseAbs().maxCoeff();
  Eigen::VectorXd inv(lambda.size());
  for (Index i = 0; i < lambda.size(); ++i) {
    const bool keep = top > 0 && lambda(i) > tolerance * top;
    inv(i) = keep ? 1.0 / lambda(i) : 0.0;
    *singular = *singular || !keep;
  }
  *condition = lambda.minCoeff() > 0 ? top / lambda.minCoeff() : INFINITY;
  return es.eigenvectors() * inv.asDiagonal() * es.eigenvectors().transpose();
}

}  // namespace

QpOperators qp_operators(const MatD& H, const MatD& A, const ConstraintOptions& options,
                         ConstraintSummary* summary) {
  const Index p = H.rows(), m = A.rows();
  QpOperators ops;
  summary->m = m;
  bool singular = false;
  double cond = 0.0;
  if (!options.soft) {
    // Rank-revealing QR of Aᵀ (p×m): its first r Householder vectors span the
    // row space of A; the remaining columns of Q span ker(A).
    Index r = 0;
    MatD Z = MatD::Identity(p, p);
    MatD P = MatD::Zero(p, m);
    if (m > 0 && A.norm() > 0) {
      Eigen::ColPivHouseholderQR<MatD> qr(A.transpose());
      qr.setThreshold(options.rank_tolerance);
      r = qr.rank();
      const MatD Q = qr.householderQ();
      Z = Q.rightCols(p - r);
      Eigen::CompleteOrthogonalDecomposition<MatD> cod(A);
      cod.setThreshold(options.rank_tolerance);
      P = cod.pseudoInverse();
      // Condition estimate from the rank-revealing R (|R_11| / |R_rr|).
      const auto diag = qr.matrixR().diagonal().cwiseAbs();
      summary->condition = r > 0 ? diag(0) / diag(r - 1) : 0.0;
    }
    summary->rank = r;
    // The p×p products go through the BLAS (blas.h): M_g = Z·K⁺·Zᵀ with
    // K = ZᵀHZ, and M_c = P − M_g·H·P.
    const Index q = Z.cols();
    MatD HZ(p, q), K(q, q);
    blas_gemm(false, false, 1.0, H, Z, 0.0, HZ);
    blas_gemm(true, false, 1.0, Z, HZ, 0.0, K);
    const MatD Kinv = symmetric_pinv(K, options.rank_tolerance, &singular, &cond);
    MatD ZK(p, q), HP(p, m);
    blas_gemm(false, false, 1.0, Z, Kinv, 0.0, ZK);
    ops.Mg.resize(p, p);
    blas_gemm(false, true, 1.0, ZK, Z, 0.0, ops.Mg);
    blas_gemm(false, false, 1.0, H, P, 0.0, HP);
    ops.Mc = P;
    blas_gemm(false, false, -1.0, ops.Mg, HP, 1.0, ops.Mc);
    if (singular) {
      summary->status = Status::Unbounded;
      summary->message = fmt::format(
          "the reduced energy is not strictly convex on the constraint set (condition {:.2e}): the minimiser is "
          "not unique or does not exist; the minimum-norm stationary point is returned",
          cond);
    } else if (r < m) {
      summary->status = Status::ConstraintsLeastSquares;
      summary->message = fmt::format(
          "{} hard constraints have rank {} in the subspace (over-determined or dependent): they hold in the "
          "least-squares sense",
          m, r);
    } else {
      summary->status = Status::Success;
      summary->message = fmt::format("{} hard constraints, rank {}", m, r);
    }
  } else {
    const double two_delta = 2.0 * options.delta;
    ops.Mg = symmetric_pinv(H + two_delta * (A.transpose() * A), options.rank_tolerance, &singular, &cond);
    ops.Mc = two_delta * (ops.Mg * A.transpose());
    summary->rank = m > 0 ? Eigen::ColPivHouseholderQR<MatD>(A).rank() : 0;
    if (singular) {
      summary->status = Status::Unbounded;
      summary->message = fmt::format(
          "H + 2δAᵀA is singular (condition {:.2e}): the soft-constrained minimiser is not unique; the "
          "minimum-norm stationary point is returned",
          cond);
    } else {
      summary->status = Status::Success;
      summary->message = fmt::format("{} soft constraints, δ = {:.3g}", m, options.delta);
    }
  }
  return ops;
}

}  // namespace qpreduce::detail
