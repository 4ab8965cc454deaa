#include "qpreduce/problems/schur_baseline.h"

#include "qpreduce/checks.h"
#include "qpreduce/util/timer.h"

#include <Eigen/QR>
#include <fmt/format.h>

#include <cmath>

namespace qpreduce {

bool SchurBaselineOptions::is_valid(std::string* why) const {
  auto fail = [&](const std::string& s) {
    if (why) *why = s;
    return false;
  };
  if (backend != Backend::Cholmod && backend != Backend::SimplicialLDLT) {
    return fail(fmt::format("backend must be Cholmod or SimplicialLDLT, got {}", to_string(backend)));
  }
  if (block_size < 1) return fail(fmt::format("block_size must be ≥ 1, got {}", block_size));
  if (!(rank_tolerance > 0.0) || !(rank_tolerance < 1.0)) {
    return fail(fmt::format("rank_tolerance must lie in (0, 1), got {}", rank_tolerance));
  }
  return true;
}

SchurBaselineSummary CachedCholeskySchur::precompute(const SparseMatrix<double>& H, const SparseMatrix<double>& W,
                                                     const SchurBaselineOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("SchurBaselineOptions: " + why);
  check_size("CachedCholeskySchur: H columns", H.rows(), H.cols());
  check_size("CachedCholeskySchur: W rows", H.rows(), W.rows());
  check_finite("CachedCholeskySchur: H", H);
  check_finite("CachedCholeskySchur: W", W);
  const Timer timer;
  factor_.reset();
  options_ = options;
  n_ = H.rows();
  SchurBaselineSummary summary;
  SparseMatrix<double> K = H;
  if (W.cols() > 0) K += SparseMatrix<double>(W * W.transpose());
  auto factor = make_factorization(options.backend);
  factor->compute(K);
  if (factor->info() != Eigen::Success) {
    summary.status = Status::SingularKKT;
    summary.message = "H + W·Wᵀ is not positive definite: " + factor->message();
    return summary;
  }
  W_ = W;
  GW_ = Matrix<double>(W);
  factor->solveInPlace(GW_, options.block_size);
  WtGW_ = W.transpose() * GW_ - Matrix<double>::Identity(W.cols(), W.cols());
  factor_ = std::move(factor);
  summary.factor_nonzeros = factor_->factorNonZeros();
  summary.status = Status::Success;
  summary.message = fmt::format("factored H + W·Wᵀ (n = {}, r = {}, {} factor nonzeros)", n_, W.cols(),
                                summary.factor_nonzeros);
  summary.seconds = timer.seconds();
  return summary;
}

SchurBaselineSummary CachedCholeskySchur::solve(const SparseMatrix<double>& A, const Vector<double>& b,
                                                const Vector<double>& q, Vector<double>* X) const {
  if (!ready()) throw std::invalid_argument("CachedCholeskySchur::solve: call precompute first");
  check_size("CachedCholeskySchur::solve: A rows", n_, A.rows());
  check_size("CachedCholeskySchur::solve: b size", A.cols(), b.size());
  check_size("CachedCholeskySchur::solve: q size", n_, q.size());
  check_finite("CachedCholeskySchur::solve: A", A);
  check_finite("CachedCholeskySchur::solve: b", b);
  check_finite("CachedCholeskySchur::solve: q", q);
  const Timer timer;
  X->resize(0);
  SchurBaselineSummary summary;
  const Index m = A.cols(), r = W_.cols();
  // [G_A, x₀] = K⁻¹[A, q]: m + 1 solves with the cached factor.
  Matrix<double> G(n_, m + 1);
  G.leftCols(m) = Matrix<double>(A);
  G.col(m) = q;
  factor_->solveInPlace(G, options_.block_size);
  const auto GA = G.leftCols(m);
  const auto x0 = G.col(m);
  Matrix<double> S(r + m, r + m);
  Vector<double> rhs(r + m);
  S.topLeftCorner(r, r) = WtGW_;
  S.topRightCorner(r, m) = -(W_.transpose() * GA);
  S.bottomLeftCorner(m, r) = A.transpose() * GW_;
  S.bottomRightCorner(m, m) = -(A.transpose() * GA);
  rhs.head(r) = -(W_.transpose() * x0);
  rhs.tail(m) = b - A.transpose() * x0;
  Eigen::ColPivHouseholderQR<Matrix<double>> qr(S);
  qr.setThreshold(options_.rank_tolerance);
  if (qr.rank() < r + m) {
    summary.status = Status::SingularKKT;
    summary.message = fmt::format("Schur complement has rank {} < {}: A is rank deficient or H is not PD on ker Aᵀ",
                                  qr.rank(), r + m);
    summary.seconds = timer.seconds();
    return summary;
  }
  const Vector<double> sl = qr.solve(rhs);
  *X = x0 + GW_ * sl.head(r) - GA * sl.tail(m);
  summary.status = Status::Success;
  summary.message = fmt::format("{} constraints, {} solves", m, m + 1);
  summary.seconds = timer.seconds();
  return summary;
}

void SchurBaselineSummary::add_details(Report* out) const {
  out->add("factor_nonzeros", factor_nonzeros)
      .add("seconds", seconds);
}

}  // namespace qpreduce
